"""The merged cloud P*: every submap's voxels placed in the world by its pose, re-voxelized.

Each submap's voxel centres are transformed to the world and re-keyed at `voxel_m`; a world
voxel keeps the colour and robot of its earliest observation (smallest first tick, then robot
id), so the result does not depend on the order submaps are stored in. Updates are incremental
while no pose changes: only voxels appended since the last update are transformed and merged
(they arrived later, so they never displace an existing voxel's first observer). A pose change
rebuilds that submap's world keys and the merged set.

Each robot's own map (`robot_cloud`, the live evaluator's overlap asks for it every few sim
seconds, under the edge's lock) is kept the same way: per robot, the voxels of the parts it was
built from, extended by what those parts appended since and rebuilt only when one of that
robot's submaps moved.
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


@dataclass
class _RobotMap:
    """One robot's own map (sorted unique world keys, colours) and, per part it was built
    from, (pose_version, voxels taken)."""

    taken: dict[SubmapKey, tuple[int, int]]
    keys: np.ndarray
    colors: np.ndarray
    points: np.ndarray | None = None


def _insert_new(
    keys: np.ndarray, values: list[np.ndarray], new_keys: np.ndarray, new_values: list[np.ndarray]
) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Sorted `keys` (with per-key `values`) plus the sorted unique `new_keys` they lack; a
    known key keeps its values (its first observation is older). Also the keys inserted."""
    pos = np.searchsorted(keys, new_keys)
    known = np.zeros(new_keys.size, bool)
    inside = pos < keys.size
    known[inside] = keys[pos[inside]] == new_keys[inside]
    new, pos = ~known, pos[~known]
    merged = [np.insert(v, pos, nv[new], axis=0) for v, nv in zip(values, new_values, strict=True)]
    return np.insert(keys, pos, new_keys[new]), merged, new_keys[new]


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
        self._robot_maps: dict[int, _RobotMap] = {}

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
        self.keys, (self.colors, self.robot_ids), self.added_keys = _insert_new(
            self.keys, [self.colors, self.robot_ids], keys, [colors[idx], robots[idx]])

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
        """One robot's own map: (N, 3) world voxel centres and (N, 3) colours of its submaps,
        each voxel once with the colour of its earliest observation; as of the last update."""
        parts = {k: p for k, p in self._parts.items() if k[0] == robot_id}
        cached = self._robot_maps.get(robot_id)
        if cached is None or any(k in cached.taken and cached.taken[k][0] != p.pose_version
                                 for k, p in parts.items()):
            cached = _robot_map(parts)  # first time, or a submap moved: from scratch
        else:
            _extend(cached, parts)
        self._robot_maps[robot_id] = cached
        if cached.points is None:
            cached.points = centres(unpack(cached.keys), self.voxel_m)
        return cached.points, cached.colors


def _robot_map(parts: dict[SubmapKey, _WorldPart]) -> _RobotMap:
    """A robot's own map from all of its parts."""
    ordered = [parts[k] for k in sorted(parts)]
    taken = {k: (p.pose_version, p.keys_world.size) for k, p in parts.items()}
    if not ordered:
        return _RobotMap(taken, np.zeros(0, np.int64), np.zeros((0, 3), np.uint8))
    keys = np.concatenate([p.keys_world for p in ordered])
    ticks = np.concatenate([p.first_tick for p in ordered])
    uniq, idx = _first_observed(keys, ticks, np.zeros(keys.size, np.uint8))
    return _RobotMap(taken, uniq, np.concatenate([p.colors for p in ordered])[idx])


def _extend(cached: _RobotMap, parts: dict[SubmapKey, _WorldPart]) -> None:
    """Add the voxels the robot's unmoved parts appended since `cached` was built. They
    arrived in later plans, so later ticks: a voxel already held keeps its first observer."""
    new: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for k in sorted(parts):
        p = parts[k]
        start = cached.taken.get(k, (p.pose_version, 0))[1]
        if p.keys_world.size > start:
            new.append((p.keys_world[start:], p.first_tick[start:], p.colors[start:]))
        cached.taken[k] = (p.pose_version, p.keys_world.size)
    if not new:
        return
    keys, ticks, colors = (np.concatenate(arrays) for arrays in zip(*new, strict=True))
    keys, idx = _first_observed(keys, ticks, np.zeros(keys.size, np.uint8))
    cached.keys, (cached.colors,), _ = _insert_new(cached.keys, [cached.colors], keys,
                                                   [colors[idx]])
    cached.points = None
