"""Inventories of submaps: what each agent produced against what the edge merged."""

from __future__ import annotations

import logging
from typing import Any

from schemas import DecodeError
from schemas.messages import Inventory, SubmapInfo
from services.common.access import identity
from services.common.bus import Bus, BusConfig, connect

log = logging.getLogger(__name__)


def as_json(inventory: Inventory | None) -> dict[str, Any] | None:
    if inventory is None:
        return None
    return {
        str(robot): {f"{s.epoch}/{s.submap_id}": s.voxels for s in infos}
        for robot, infos in inventory.submaps.items()
    }


def query_inventory(bus: Bus, key: str, timeout_s: float) -> Inventory | None:
    try:
        reply = bus.query(key, None, Inventory, timeout_s)
    except (TimeoutError, DecodeError) as exc:
        log.warning("no inventory from %s: %s", key, exc)
        return None
    assert isinstance(reply, Inventory)
    return reply


def collect_inventories(config: BusConfig, robots: int, timeout_s: float) -> dict[str, Any]:
    """{"edge": {robot: {"epoch/submap": voxels}}, "agents": {robot: {"epoch/submap": voxels}}}
    (None where a process did not answer)."""
    with connect(config, identity("monitor")) as bus:
        edge = as_json(query_inventory(bus, bus.keys.map_inventory(), timeout_s))
        agents = {}
        for r in range(robots):
            own = as_json(query_inventory(bus, bus.keys.inventory(r), timeout_s))
            agents[str(r)] = None if own is None else own.get(str(r), {})
    return {"edge": edge, "agents": agents}


def missing_submaps(
    produced: dict[str, int], merged: dict[str, int]
) -> dict[str, tuple[int, int]]:
    """Submaps ("epoch/id" → voxels) an agent produced that the edge lacks or holds fewer
    voxels of: {submap: (produced voxels, merged voxels)}."""
    return {
        name: (voxels, merged.get(name, 0))
        for name, voxels in produced.items()
        if merged.get(name, 0) < voxels
    }


def inventory_of(submaps: dict[int, list[tuple[int, int, int]]], tick: int) -> Inventory:
    """An Inventory from {robot: [(epoch, submap_id, voxels), ...]}."""
    return Inventory(
        tick=tick,
        submaps={
            robot: [SubmapInfo(epoch=e, submap_id=i, voxels=v) for e, i, v in items]
            for robot, items in submaps.items()
        },
    )
