"""The merged cloud P*: every submap's voxels placed in the world by its pose, re-voxelized.

Each submap's voxel centres are transformed to the world and re-keyed at `voxel_m`; a world
voxel keeps the colour and robot of its earliest observation (smallest first tick, then robot
id), so the result does not depend on the order submaps are stored in. Updates are incremental
while no pose changes: only voxels appended since the last update are transformed and merged
(they arrived later, so they never displace an existing voxel's first observer). A pose change
rebuilds that submap's world keys and the merged set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.geometry import transform_points
from services.common.voxels import centres, pack, unpack, voxel_indices
from services.edge_server.submap_store import StoredSubmap, SubmapKey, SubmapStore


@dataclass
class _WorldPart:
    """One submap's voxels in world keys, valid for `pose_version` and its first `n` voxels."""

    pose_version: int
    n: int
    keys_world: np.ndarray
    colors: np.ndarray
    first_tick: np.ndarray


def _to_world_keys(sm: StoredSubmap, start: int, voxel_m: float) -> np.ndarray:
    centres_submap = centres(unpack(sm.keys[start:]), voxel_m)
    return pack(voxel_indices(transform_points(sm.T_world_submap, centres_submap), voxel_m))


def _first_observed(
    keys: np.ndarray, ticks: np.ndarray, robots: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique keys and, per key, the index of its earliest (tick, robot) entry."""
    order = np.lexsort((robots, ticks, keys))
    sorted_keys = keys[order]
    first = np.ones(sorted_keys.size, bool)
    first[1:] = sorted_keys[1:] != sorted_keys[:-1]
    return sorted_keys[first], order[first]


class MergedMap:
    """P* in the world frame as sorted voxel keys with colour and first-observer robot."""

    def __init__(self, voxel_m: float) -> None:
        self.voxel_m = voxel_m
        self._parts: dict[SubmapKey, _WorldPart] = {}
        self.keys = np.zeros(0, np.int64)
        self.colors = np.zeros((0, 3), np.uint8)
        self.robot_ids = np.zeros(0, np.uint8)
        self._points: np.ndarray | None = None
        self._store_version = -1
        self.version = 0  # bumps whenever the merged set changes
        # keys the last update inserted; None after a rebuild (voxels may have been removed)
        self.added_keys: np.ndarray | None = np.zeros(0, np.int64)

    # -- update ----------------------------------------------------------------------------
    def update(self, store: SubmapStore) -> bool:
        """Bring P* up to date with the store; True when it changed."""
        if store.version == self._store_version:
            return False
        self._store_version = store.version
        rebuild = False
        deltas: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        for sm in store.ordered():
            part = self._parts.get(sm.key)
            if part is None or part.pose_version != sm.pose_version:
                rebuild |= part is not None
                part = _WorldPart(sm.pose_version, 0, np.zeros(0, np.int64),
                                  np.zeros((0, 3), np.uint8), np.zeros(0, np.int64))
                self._parts[sm.key] = part
            if sm.keys.size > part.n:
                new_keys = _to_world_keys(sm, part.n, self.voxel_m)
                new_colors, new_ticks = sm.colors[part.n :], sm.first_tick[part.n :]
                robots = np.full(new_keys.size, sm.robot_id, np.uint8)
                deltas.append((new_keys, new_colors, new_ticks, robots))
                part.keys_world = np.concatenate([part.keys_world, new_keys])
                part.colors = np.concatenate([part.colors, new_colors])
                part.first_tick = np.concatenate([part.first_tick, new_ticks])
                part.n = sm.keys.size
        if rebuild:
            self._rebuild(store)
            self.added_keys = None
        elif deltas:
            self._merge_delta(*(np.concatenate(parts) for parts in zip(*deltas, strict=True)))
        else:
            return False
        self._points = None
        self.version += 1
        return True

    def _rebuild(self, store: SubmapStore) -> None:
        sms = store.ordered()
        parts = [self._parts[sm.key] for sm in sms]
        keys = np.concatenate([p.keys_world for p in parts])
        ticks = np.concatenate([p.first_tick for p in parts])
        colors = np.concatenate([p.colors for p in parts])
        robots = np.concatenate([
            np.full(p.keys_world.size, sm.robot_id, np.uint8)
            for sm, p in zip(sms, parts, strict=True)
        ])
        self.keys, idx = _first_observed(keys, ticks, robots)
        self.colors, self.robot_ids = colors[idx], robots[idx]

    def _merge_delta(
        self, keys: np.ndarray, colors: np.ndarray, ticks: np.ndarray, robots: np.ndarray
    ) -> None:
        keys, idx = _first_observed(keys, ticks, robots)
        colors, robots = colors[idx], robots[idx]
        pos = np.searchsorted(self.keys, keys)
        known = np.zeros(keys.size, bool)
        inside = pos < self.keys.size
        known[inside] = self.keys[pos[inside]] == keys[inside]
        new, pos = ~known, pos[~known]
        self.added_keys = keys[new]
        self.keys = np.insert(self.keys, pos, keys[new])
        self.colors = np.insert(self.colors, pos, colors[new], axis=0)
        self.robot_ids = np.insert(self.robot_ids, pos, robots[new])

    # -- read ------------------------------------------------------------------------------
    @property
    def points_world(self) -> np.ndarray:
        """(N, 3) float64 voxel centres of P* in the world frame."""
        if self._points is None:
            self._points = centres(unpack(self.keys), self.voxel_m)
        return self._points

    def __len__(self) -> int:
        return int(self.keys.size)

    def robot_cloud(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]:
        """One robot's own map: (N, 3) world voxel centres and (N, 3) colours of its submaps."""
        parts = [p for (r, _), p in sorted(self._parts.items()) if r == robot_id]
        if not parts:
            return np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
        keys = np.concatenate([p.keys_world for p in parts])
        ticks = np.concatenate([p.first_tick for p in parts])
        uniq, idx = _first_observed(keys, ticks, np.zeros(keys.size, np.uint8))
        colors = np.concatenate([p.colors for p in parts])[idx]
        return centres(unpack(uniq), self.voxel_m), colors
