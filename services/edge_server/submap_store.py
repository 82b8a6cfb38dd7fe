"""The edge's copy of every robot's submaps, built from `Submap` deltas.

A submap is keyed by (robot_id, submap_id). Its voxels are kept in the submap frame as packed
voxel keys (services.common.voxels) with the agent's latest mean point (decoded from the
message's offset code, at the edge's `voxel_m`, which must be the agents'), colour,
observation count and the tick each voxel was first received (the merged map uses it to name
a voxel's first observer). New voxels are only ever appended, so consumers can cache by
length. `version` bumps on new data and
`pose_version` when the pose changes, so the merged map and grid know what to recompute.

Poses: `T_reported` is the agent's latest estimate; `T_world_submap` is where the submap is
placed, the reported pose until the merger corrects it (`corrected`), after which reports no
longer move it (a later delta of an old submap carries the agent's re-anchored frame).
`T_odom` is the pose in the agent's own odometry frame, which corrections never move.
Sequence numbers are checked per (robot, epoch): a restarted agent starts a new epoch, and a
resend of data the edge already holds is applied idempotently (upserts) without a gap warning.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from schemas.messages import Submap
from services.common.arrays import union_rows_2, unique_first
from services.common.voxels import offset_points, pack, voxel_indices

log = logging.getLogger(__name__)

SubmapKey = tuple[int, int]


@dataclass
class StoredSubmap:
    """One submap: voxels (submap frame), free floor cells and its current world pose."""

    robot_id: int
    submap_id: int
    T_world_submap: np.ndarray
    cell_m: float
    keys: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    colors: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.uint8))
    counts: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint16))
    first_tick: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    free_cells: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    version: int = 0
    pose_version: int = 0
    epoch: int = 0
    T_reported: np.ndarray = field(default_factory=lambda: np.eye(4))
    T_odom: np.ndarray | None = None  # the agent's own frame, never corrected (None: not sent)
    corrected: bool = False

    @property
    def key(self) -> SubmapKey:
        return (self.robot_id, self.submap_id)


def _upsert(
    sm: StoredSubmap, keys: np.ndarray, points: np.ndarray, colors: np.ndarray,
    counts: np.ndarray, tick: int,
) -> None:
    """Insert new voxels, refresh mean point, colour and count of known ones; new voxels go
    to the end."""
    keys, first = unique_first(keys)
    points, colors, counts = points[first], colors[first], counts[first]
    known = np.zeros(keys.size, bool)
    if sm.keys.size:
        order = np.argsort(sm.keys, kind="stable")
        pos = np.minimum(np.searchsorted(sm.keys[order], keys), sm.keys.size - 1)
        known = sm.keys[order[pos]] == keys
        idx = order[pos[known]]
        sm.points[idx] = points[known]
        sm.colors[idx] = colors[known]
        sm.counts[idx] = counts[known]
    new = ~known
    sm.keys = np.concatenate([sm.keys, keys[new]])
    sm.points = np.concatenate([sm.points, points[new]])
    sm.colors = np.concatenate([sm.colors, colors[new]])
    sm.counts = np.concatenate([sm.counts, counts[new]])
    sm.first_tick = np.concatenate([sm.first_tick, np.full(int(new.sum()), tick, np.int64)])


class SubmapStore:
    """Every submap the edge has received, with per-robot seq-gap detection."""

    def __init__(self, voxel_m: float) -> None:
        self.voxel_m = voxel_m
        self.submaps: dict[SubmapKey, StoredSubmap] = {}
        self.last_seq: dict[tuple[int, int], int] = {}  # (robot, epoch) → last seq
        self.seq_gaps: Counter[int] = Counter()
        self.version = 0  # bumps on any change, for cheap "anything new?" checks

    def apply(self, msg: Submap) -> StoredSubmap:
        """Apply one submap (or delta): upsert voxels, add free cells, take its pose."""
        self._check_seq(msg.robot_id, msg.epoch, msg.seq)
        key = (msg.robot_id, msg.submap_id)
        sm = self.submaps.get(key)
        if sm is None:
            sm = StoredSubmap(msg.robot_id, msg.submap_id, msg.T_world_submap.copy(), msg.cell_m,
                              epoch=msg.epoch)
            self.submaps[key] = sm
        elif not sm.corrected and not np.array_equal(sm.T_world_submap, msg.T_world_submap):
            sm.T_world_submap = msg.T_world_submap.copy()
            sm.pose_version += 1
        sm.T_reported = msg.T_world_submap.copy()
        sm.T_odom = None if msg.T_odom_submap is None else msg.T_odom_submap.copy()
        centres_submap = msg.points_mm.T.astype(np.float64) / 1000.0  # mm → m, (N, 3)
        if centres_submap.shape[0]:
            indices = voxel_indices(centres_submap, self.voxel_m)
            points = centres_submap if not msg.offsets.size else offset_points(
                indices, msg.offsets, self.voxel_m, msg.offset_levels)
            _upsert(sm, pack(indices), points.astype(np.float32), msg.colors, msg.counts,
                    msg.tick)
        if msg.free_cells.shape[1]:
            sm.free_cells = union_rows_2(sm.free_cells, msg.free_cells.T.astype(np.int64))
        sm.cell_m = msg.cell_m
        sm.version += 1
        self.version += 1
        return sm

    def set_pose(self, key: SubmapKey, T_world_submap: np.ndarray) -> bool:
        """Place a submap by a corrected pose; True when it changed."""
        sm = self.submaps[key]
        sm.corrected = True
        if np.array_equal(sm.T_world_submap, T_world_submap):
            return False
        sm.T_world_submap = np.asarray(T_world_submap, dtype=np.float64).copy()
        sm.pose_version += 1
        self.version += 1
        return True

    def robot_ids(self) -> list[int]:
        return sorted({r for r, _ in self.submaps})

    def ordered(self) -> list[StoredSubmap]:
        """Submaps in a deterministic order (robot, submap id)."""
        return [self.submaps[k] for k in sorted(self.submaps)]

    def _check_seq(self, robot_id: int, epoch: int, seq: int) -> None:
        last = self.last_seq.get((robot_id, epoch))
        if last is not None and seq <= last:
            return  # a resend: applied idempotently, the counter does not go back
        if last is not None and seq != last + 1:
            self.seq_gaps[robot_id] += 1
            log.warning("robot %d epoch %d submap seq gap: %d after %d", robot_id, epoch, seq,
                        last)
        self.last_seq[(robot_id, epoch)] = seq
