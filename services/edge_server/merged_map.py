"""The merged cloud P*: every submap's voxels placed in the world by its pose, re-voxelized.

Each submap's voxel centres are transformed to the world and re-keyed at `voxel_m`; a world
voxel keeps the colour, robot and point of its earliest observation (smallest first tick, then
robot id), so the result does not depend on the order submaps are stored in. Its point is that
observation's mean point (the agent's latest, moved with its submap's pose): on the surface,
where the world voxel's centre would stair-step it by up to half a voxel; the keys, and so the
grid and the frontiers, come from the centres. Updates are incremental
while no pose changes: only voxels appended since the last update are transformed and merged
(they arrived later, so they never displace an existing voxel's first observer). A pose change
rebuilds that submap's world keys and judges every voxel's first observer again, from all
submaps' observations kept sorted by key (observations.py: the moved submaps' rows are
replaced, the rest are not sorted again).

Each robot's own map (`robot_cloud`, the live evaluator's overlap asks for it every few sim
seconds, under the edge's lock) is kept the same way: per robot, the voxels of the parts it was
built from, extended by what those parts appended since and rebuilt only when one of that
robot's submaps moved.

`cloud_view` answers "what changed since version v" for either kind of map: every voxel
carries the `cloud_version` it was added at, every part's point the version it last moved
at, and a rebuild (voxels may have gone) makes the answer whole again. The live evaluator
then reads what changed, not the whole map, every few sim seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.arrays import insert_rows, unique_sorted
from services.common.geometry import transform_points
from services.common.voxels import centres, pack, unpack, voxel_indices
from services.edge_server.observations import ObservationTable
from services.edge_server.submap_store import StoredSubmap, SubmapKey, SubmapStore


@dataclass
class _WorldPart:
    """One submap's voxels in world keys, valid for `pose_version` and its first `n` voxels."""

    pose_version: int
    n: int
    keys_world: np.ndarray
    colors: np.ndarray
    first_tick: np.ndarray
    uid: int = 0  # the submap's number in this map: a voxel's source is (uid, index)
    points_world: np.ndarray | None = None  # (n, 3) float32 mean points, for `points_stamp`
    points_stamp: tuple[int, int, int] = (-1, -1, -1)  # (submap version, pose version, n)
    point_versions: np.ndarray | None = None  # (n,) cloud_version each point last moved at


@dataclass(frozen=True)
class CloudView:
    """A map as of `version`, whole or (`delta`) only the voxels added or moved since the
    version asked about; arrays sorted by key."""

    version: int
    delta: bool
    keys: np.ndarray  # (N,) int64 packed world voxel keys, sorted
    points_world: np.ndarray  # (N, 3) float32
    colors: np.ndarray  # (N, 3) uint8
    robot_ids: np.ndarray  # (N,) uint8 first observer


def _to_world_keys(sm: StoredSubmap, start: int, voxel_m: float) -> np.ndarray:
    centres_submap = centres(unpack(sm.keys[start:]), voxel_m)
    return pack(voxel_indices(transform_points(sm.T_world_submap, centres_submap), voxel_m))


def _first_observed(
    keys: np.ndarray, ticks: np.ndarray, robots: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique keys and, per key, the index of its earliest (tick, robot) entry (the
    first such entry on a tie). One unstable sort by key and a pass over the keys seen
    more than once: a three-key lexsort of a warehouse's millions of entries took 2-3× as
    long, on every rebuild."""
    order = np.argsort(keys)
    sorted_keys = keys[order]
    first = np.ones(sorted_keys.size, bool)
    first[1:] = sorted_keys[1:] != sorted_keys[:-1]
    start = np.flatnonzero(first)
    if start.size == sorted_keys.size:
        return sorted_keys, order
    rank = ticks[order].astype(np.int64) * 256 + robots[order]  # robots: uint8
    size = np.diff(np.append(start, sorted_keys.size))
    earliest = np.repeat(np.minimum.reduceat(rank, start), size) == rank
    return sorted_keys[start], np.minimum.reduceat(np.where(earliest, order, keys.size), start)


@dataclass
class _RobotMap:
    """One robot's own map (sorted unique world keys, colours, source (uid, index) of each
    voxel's point) and, per part it was built from, (pose_version, voxels taken)."""

    taken: dict[SubmapKey, tuple[int, int]]
    keys: np.ndarray
    colors: np.ndarray
    src_uid: np.ndarray
    src_idx: np.ndarray
    points: np.ndarray | None = None
    points_stamp: int = -1
    added_at: np.ndarray | None = None  # (N,) cloud_version each voxel was added at
    rebuilt_at: int = 0


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
    merged = [insert_rows(v, pos, nv[new]) for v, nv in zip(values, new_values, strict=True)]
    return np.insert(keys, pos, new_keys[new]), merged, new_keys[new]


class MergedMap:
    """P* in the world frame as sorted voxel keys with colour and first-observer robot."""

    def __init__(self, voxel_m: float) -> None:
        self.voxel_m = voxel_m
        self._parts: dict[SubmapKey, _WorldPart] = {}
        self.keys = np.zeros(0, np.int64)
        self.colors = np.zeros((0, 3), np.uint8)
        self.robot_ids = np.zeros(0, np.uint8)
        self.src_uid = np.zeros(0, np.int32)  # each voxel's point: part uid and index in it
        self.src_idx = np.zeros(0, np.int32)
        self._uids: dict[SubmapKey, int] = {}
        self._centres: np.ndarray | None = None
        self._points: np.ndarray | None = None
        self._points_version = 0  # bumps when a part's mean points are taken again
        self._store_version = -1
        self.version = 0  # bumps whenever the merged set changes
        self.cloud_version = 0  # bumps whenever a cloud would differ (keys or points)
        self.rebuilt_at = 0  # cloud_version of the last rebuild (voxels may have gone)
        self.added_at = np.zeros(0, np.int32)  # per voxel: cloud_version it was added at
        # sorted keys the last update inserted and removed (only a rebuild removes any)
        self.added_keys: np.ndarray = np.zeros(0, np.int64)
        self.removed_keys: np.ndarray = np.zeros(0, np.int64)
        self._robot_maps: dict[int, _RobotMap] = {}
        self._observations = ObservationTable()  # every part's voxels, sorted by key

    # -- update ----------------------------------------------------------------------------
    def update(self, store: SubmapStore) -> bool:
        """Bring P* up to date with the store; True when it changed."""
        if store.version == self._store_version:
            return False
        self._store_version = store.version
        moved: dict[int, np.ndarray] = {}  # uid → the world keys the part held
        deltas: list[tuple[np.ndarray, ...]] = []
        for sm in store.ordered():
            part = self._parts.get(sm.key)
            if part is None or part.pose_version != sm.pose_version:
                if part is not None:
                    moved[part.uid] = part.keys_world
                uid = self._uids.setdefault(sm.key, len(self._uids))
                part = _WorldPart(sm.pose_version, 0, np.zeros(0, np.int64),
                                  np.zeros((0, 3), np.uint8), np.zeros(0, np.int64), uid)
                self._parts[sm.key] = part
            if sm.keys.size > part.n:
                new_keys = _to_world_keys(sm, part.n, self.voxel_m)
                new_colors, new_ticks = sm.colors[part.n :], sm.first_tick[part.n :]
                robots = np.full(new_keys.size, sm.robot_id, np.uint8)
                uids = np.full(new_keys.size, part.uid, np.int32)
                idx = np.arange(part.n, sm.keys.size, dtype=np.int32)
                deltas.append((new_keys, new_colors, new_ticks, robots, uids, idx))
                part.keys_world = np.concatenate([part.keys_world, new_keys])
                part.colors = np.concatenate([part.colors, new_colors])
                part.first_tick = np.concatenate([part.first_tick, new_ticks])
                part.n = sm.keys.size
        self._observations.drop(moved)
        for new_keys, _, new_ticks, robots, uids, idx in deltas:
            self._observations.add(new_keys, new_ticks, robots, uids, idx)
        v = self.cloud_version + 1
        if self._snapshot_points(store, v):
            self._points = None
            self.cloud_version = v
        self.removed_keys = np.zeros(0, np.int64)
        if moved:
            self.added_keys, self.removed_keys = self._rebuild()
            self.added_at = np.full(self.keys.size, v, np.int32)
            self.rebuilt_at = v
        elif deltas:
            self._merge_delta(*(np.concatenate(parts) for parts in zip(*deltas, strict=True)),
                              version=v)
        else:
            return False
        self.cloud_version = v
        self._centres = self._points = None
        self.version += 1
        return True

    def _snapshot_points(self, store: SubmapStore, version: int) -> bool:
        """Take the world mean points of every part whose submap changed: here, at the
        update, so that the points, like the keys, are those of the messages the update saw
        (later deltas refine a submap's points in place); points that moved are stamped
        `version`. True when any was taken."""
        taken = False
        for sm in store.ordered():
            part = self._parts[sm.key]
            stamp = (sm.version, sm.pose_version, part.n)
            if part.points_stamp != stamp:
                points = transform_points(
                    sm.T_world_submap, sm.points[: part.n].astype(np.float64)
                ).astype(np.float32)
                versions = np.full(part.n, version, np.int32)
                old, old_versions = part.points_world, part.point_versions
                if old is not None and old_versions is not None:
                    k = min(old.shape[0], part.n)
                    same = np.all(old[:k] == points[:k], axis=1)
                    versions[:k][same] = old_versions[:k][same]
                part.points_world, part.point_versions = points, versions
                part.points_stamp = stamp
                taken = True
        self._points_version += taken
        return taken

    def _rebuild(self) -> tuple[np.ndarray, np.ndarray]:
        """The first observer of every voxel whose observations changed, from the
        observations kept sorted (observations.py); the other voxels keep theirs. Returns
        the keys inserted and the keys removed."""
        submap_of_uid = np.array([0] * len(self._uids), np.int64)
        for key, uid in self._uids.items():
            submap_of_uid[uid] = key[1]
        ch = self._observations.first_observers(submap_of_uid)
        at = np.searchsorted(self.keys, ch.keys)
        known = np.zeros(ch.keys.size, bool)
        inside = at < self.keys.size
        known[inside] = self.keys[at[inside]] == ch.keys[inside]
        now = known & ch.held
        # copies: views handed out earlier (cloud_view) keep the map they were taken from
        self.robot_ids, self.src_uid, self.src_idx, self.colors = (
            a.copy() for a in (self.robot_ids, self.src_uid, self.src_idx, self.colors))
        self.robot_ids[at[now]] = (ch.rank[now] & 255).astype(np.uint8)
        self.src_uid[at[now]], self.src_idx[at[now]] = ch.uid[now], ch.idx[now]
        self.colors[at[now]] = self._part_colors(ch.uid[now], ch.idx[now])
        gone = known & ~ch.held
        if gone.any():
            keep = np.ones(self.keys.size, bool)
            keep[at[gone]] = False
            self.keys, self.robot_ids, self.src_uid, self.src_idx = (
                a[keep] for a in (self.keys, self.robot_ids, self.src_uid, self.src_idx))
            self.colors = self.colors[keep]
        new = ~known & ch.held
        if new.any():
            at = np.searchsorted(self.keys, ch.keys[new])
            self.keys = np.insert(self.keys, at, ch.keys[new])
            self.robot_ids = np.insert(self.robot_ids, at, (ch.rank[new] & 255).astype(np.uint8))
            self.src_uid = np.insert(self.src_uid, at, ch.uid[new])
            self.src_idx = np.insert(self.src_idx, at, ch.idx[new])
            self.colors = insert_rows(self.colors, at, self._part_colors(ch.uid[new],
                                                                         ch.idx[new]))
        return ch.keys[new], ch.keys[gone]

    def _part_colors(self, src_uid: np.ndarray, src_idx: np.ndarray) -> np.ndarray:
        """(N, 3) uint8 colours the parts took for the voxels at (uid, index)."""
        if src_uid.size == 0:
            return np.zeros((0, 3), np.uint8)
        by_uid = {p.uid: p for p in self._parts.values()}
        used = unique_sorted(src_uid)
        offsets = np.zeros(int(used[-1]) + 1, np.int64)
        blocks, at = [], 0
        for uid in used.tolist():
            blocks.append(by_uid[uid].colors)
            offsets[uid] = at
            at += by_uid[uid].colors.shape[0]
        return np.concatenate(blocks)[offsets[src_uid] + src_idx]

    def _merge_delta(
        self, keys: np.ndarray, colors: np.ndarray, ticks: np.ndarray, robots: np.ndarray,
        uids: np.ndarray, src: np.ndarray, version: int,
    ) -> None:
        keys, idx = _first_observed(keys, ticks, robots)
        values = [self.colors, self.robot_ids, self.src_uid, self.src_idx, self.added_at]
        self.keys, values, self.added_keys = _insert_new(
            self.keys, values, keys, [colors[idx], robots[idx], uids[idx], src[idx],
                                      np.full(keys.size, version, np.int32)])
        self.colors, self.robot_ids, self.src_uid, self.src_idx, self.added_at = values

    # -- read ------------------------------------------------------------------------------
    @property
    def centres_world(self) -> np.ndarray:
        """(N, 3) float64 voxel centres of P* in the world frame (what the grid is built on)."""
        if self._centres is None:
            self._centres = centres(unpack(self.keys), self.voxel_m)
        return self._centres

    @property
    def points_world(self) -> np.ndarray:
        """(N, 3) float32 points of P* in the world frame: each voxel's first observation's
        mean point, as of the last update (later deltas of a submap refine its points)."""
        if self._points is None:
            self._points = self._gather(self.src_uid, self.src_idx)
        return self._points

    def _gather(self, src_uid: np.ndarray, src_idx: np.ndarray,
                versions: bool = False) -> np.ndarray:
        """(N, 3) float32 world mean points of the voxels at (uid, index), or with
        `versions` (N,) the cloud_version each of those points last moved at."""
        if src_uid.size == 0:
            return np.zeros(0, np.int32) if versions else np.zeros((0, 3), np.float32)
        by_uid = {p.uid: p for p in self._parts.values()}
        used = np.unique(src_uid)
        offsets = np.zeros(int(used.max()) + 1, np.int64)
        blocks, at = [], 0
        for uid in used.tolist():
            block = by_uid[uid].point_versions if versions else by_uid[uid].points_world
            assert block is not None  # taken by the update that added its voxels
            blocks.append(block)
            offsets[uid] = at
            at += block.shape[0]
        return np.concatenate(blocks)[offsets[src_uid] + src_idx]

    def cloud_view(self, robot_id: int, since: int) -> CloudView:
        """P* (robot_id −1) or one robot's own map: whole when `since` is −1 or older than
        the map's last rebuild (or newer than this map: another edge's), else only the
        voxels added or whose point moved after version `since`."""
        if robot_id < 0:
            keys, colors, robots = self.keys, self.colors, self.robot_ids
            points, added_at, rebuilt_at = self.points_world, self.added_at, self.rebuilt_at
            src_uid, src_idx = self.src_uid, self.src_idx
        else:
            points, colors = self.robot_cloud(robot_id)
            cached = self._robot_maps[robot_id]
            assert cached.added_at is not None  # set when the map was built
            keys, added_at, rebuilt_at = cached.keys, cached.added_at, cached.rebuilt_at
            robots = np.full(keys.size, robot_id, np.uint8)
            src_uid, src_idx = cached.src_uid, cached.src_idx
        delta = rebuilt_at <= since <= self.cloud_version
        if delta:
            changed = np.maximum(added_at, self._gather(src_uid, src_idx, versions=True)) > since
            keys, points, colors, robots = (a[changed] for a in (keys, points, colors, robots))
        return CloudView(self.cloud_version, delta, keys, points, colors, robots)

    def __len__(self) -> int:
        return int(self.keys.size)

    def robot_cloud(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]:
        """One robot's own map: (N, 3) float32 world points and (N, 3) colours of its submaps,
        each voxel once with the mean point and colour of its earliest observation; the
        voxels as of the last update."""
        parts = {k: p for k, p in self._parts.items() if k[0] == robot_id}
        cached = self._robot_maps.get(robot_id)
        if cached is None or any(k in cached.taken and cached.taken[k][0] != p.pose_version
                                 for k, p in parts.items()):
            cached = _robot_map(parts)  # first time, or a submap moved: from scratch
            cached.added_at = np.full(cached.keys.size, self.cloud_version, np.int32)
            cached.rebuilt_at = self.cloud_version
        else:
            _extend(cached, parts, self.cloud_version)
        self._robot_maps[robot_id] = cached
        if cached.points is None or cached.points_stamp != self._points_version:
            cached.points = self._gather(cached.src_uid, cached.src_idx)
            cached.points_stamp = self._points_version
        return cached.points, cached.colors

    def robot_centres(self, robot_id: int) -> np.ndarray:
        """(N, 3) float64 world voxel centres of `robot_cloud(robot_id)`, in its order."""
        self.robot_cloud(robot_id)
        return centres(unpack(self._robot_maps[robot_id].keys), self.voxel_m)


def _sources(parts: list[_WorldPart]) -> tuple[np.ndarray, np.ndarray]:
    """(uid, index) of every voxel of `parts`, concatenated in their order."""
    if not parts:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    uids = np.concatenate([np.full(p.keys_world.size, p.uid, np.int32) for p in parts])
    idx = np.concatenate([np.arange(p.keys_world.size, dtype=np.int32) for p in parts])
    return uids, idx


def _robot_map(parts: dict[SubmapKey, _WorldPart]) -> _RobotMap:
    """A robot's own map from all of its parts."""
    ordered = [parts[k] for k in sorted(parts)]
    taken = {k: (p.pose_version, p.keys_world.size) for k, p in parts.items()}
    uids, src = _sources(ordered)
    if not ordered:
        return _RobotMap(taken, np.zeros(0, np.int64), np.zeros((0, 3), np.uint8), uids, src)
    keys = np.concatenate([p.keys_world for p in ordered])
    ticks = np.concatenate([p.first_tick for p in ordered])
    uniq, idx = _first_observed(keys, ticks, np.zeros(keys.size, np.uint8))
    colors = np.concatenate([p.colors for p in ordered])[idx]
    return _RobotMap(taken, uniq, colors, uids[idx], src[idx])


def _extend(cached: _RobotMap, parts: dict[SubmapKey, _WorldPart], version: int) -> None:
    """Add the voxels the robot's unmoved parts appended since `cached` was built. They
    arrived in later plans, so later ticks: a voxel already held keeps its first observer."""
    new: list[tuple[np.ndarray, ...]] = []
    for k in sorted(parts):
        p = parts[k]
        start = cached.taken.get(k, (p.pose_version, 0))[1]
        if p.keys_world.size > start:
            n = p.keys_world.size - start
            new.append((p.keys_world[start:], p.first_tick[start:], p.colors[start:],
                        np.full(n, p.uid, np.int32), np.arange(start, start + n, dtype=np.int32)))
        cached.taken[k] = (p.pose_version, p.keys_world.size)
    if not new:
        return
    keys, ticks, colors, uids, src = (np.concatenate(a) for a in zip(*new, strict=True))
    keys, idx = _first_observed(keys, ticks, np.zeros(keys.size, np.uint8))
    assert cached.added_at is not None  # set when the map was built
    cached.keys, values, _ = _insert_new(
        cached.keys, [cached.colors, cached.src_uid, cached.src_idx, cached.added_at], keys,
        [colors[idx], uids[idx], src[idx], np.full(keys.size, version, np.int32)])
    cached.colors, cached.src_uid, cached.src_idx, cached.added_at = values
    cached.points = None
