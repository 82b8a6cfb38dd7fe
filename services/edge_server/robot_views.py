"""One robot's own 2D grid (map/robot_grid), for the evaluator's 2D overlap.

The merged-grid builder runs over a view of the store holding only that robot's submaps and a
view of P* holding only its voxels, on the merged grid's current bounds so cells line up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from schemas.messages import OccupancyGrid
from services.edge_server.merged_grid import MergedGrid
from services.edge_server.merged_map import MergedMap
from services.edge_server.submap_store import StoredSubmap, SubmapStore


@dataclass(frozen=True)
class _StoreView:
    submaps: list[StoredSubmap]

    def ordered(self) -> list[StoredSubmap]:
        return self.submaps


@dataclass(frozen=True)
class _CloudView:
    centres_world: np.ndarray
    version: int


def robot_grid(
    store: SubmapStore, merged: MergedMap, grid: MergedGrid, robot_id: int, tick: int
) -> OccupancyGrid | None:
    """The robot's own grid, or None before the merged grid exists."""
    if grid.bounds is None:
        return None
    config = grid.config.model_copy(update={"grid_bounds_m": grid.bounds})
    view = _StoreView([sm for sm in store.ordered() if sm.robot_id == robot_id])
    snap = MergedGrid(config).update(view, _CloudView(merged.robot_centres(robot_id), 0))  # type: ignore[arg-type]
    if snap is None:
        return None
    s = snap.spec
    return OccupancyGrid(tick=tick, resolution_m=s.resolution_m, origin_x=s.origin_x,
                         origin_y=s.origin_y, cells=snap.cells)
