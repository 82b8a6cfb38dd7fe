"""Keyframe submaps: a 5 cm voxel map per keyframe, published as quantized deltas.

A submap's points live in the `submap` frame, the robot base pose when the keyframe started,
so the edge can move a whole submap when its pose is corrected. Each voxel keeps its mean point,
mean colour and observation count, and is sent as its centre plus a one-byte code of where in
the voxel its mean lies (`offsets`: on the surface, where the centre alone would stair-step it
by up to half a voxel; centres compress far better than means would). A voxel is (re)sent
when it is new, when its count reaches the next power of `resend_growth`, or when its mean
colour moves by `color_resend`: the edge gets counts within that factor, and colours within that
bound, at a fraction of the traffic of resending every seen voxel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common import voxels
from services.common.arrays import row_items, unique_groups, unique_sorted
from services.common.geometry import invert, wrap_angle, xyyaw_from_T
from services.robot_agent.config import AgentConfig

_INT16_MAX_MM = 32_000  # keep clear of the int16 limit
_FREE_HALF = 400  # free-cell bitmap half size in cells (±20 m at 5 cm): more than range + keyframe


@dataclass(frozen=True)
class SubmapDelta:
    """Voxels and free cells of one submap new or changed since its last message."""

    submap_id: int
    T_odom_submap: np.ndarray  # (4, 4) keyframe pose in the odometry frame
    points_mm: np.ndarray  # (3, N) int16 voxel centres, submap frame, mm
    colors: np.ndarray  # (N, 3) uint8
    counts: np.ndarray  # (N,) uint16
    free_cells: np.ndarray  # (2, M) int16 (x, y) cells in the submap frame
    offsets: np.ndarray  # (N,) uint8 where each voxel's mean lies (voxels.offset_codes)
    offset_levels: int  # L of `offsets`; 1: no means sent (empty offsets)


def _growth_level(values: np.ndarray, growth: int) -> np.ndarray:
    """(N,) 0 for 0, else 1 + floor(log_growth(value)): a voxel is resent when it rises."""
    out = np.zeros(values.shape, dtype=np.int64)
    pos = values > 0
    out[pos] = np.floor(np.log2(values[pos]) / np.log2(growth) + 1e-9).astype(np.int64) + 1
    return out


class VoxelSubmap:
    """The voxels and free floor cells of one keyframe."""

    def __init__(self, submap_id: int, T_odom_submap: np.ndarray, start_tick: int) -> None:
        self.submap_id = submap_id
        self.T_odom_submap = T_odom_submap.copy()
        self.start_tick = start_tick
        self.keys = np.empty(0, np.int64)  # sorted packed voxel indices
        self.color_sum = np.empty((0, 3), np.float64)
        self.point_sum = np.empty((0, 3), np.float64)  # for voxel means (not lattice centres)
        self.counts = np.empty(0, np.int64)
        self.sent_counts = np.empty(0, np.int64)  # 0 = never sent
        self.sent_colors = np.empty((0, 3), np.int64)
        self.free_seen: np.ndarray | None = np.zeros((2 * _FREE_HALF, 2 * _FREE_HALF), bool)
        self.free_done = np.empty((2, 0), np.int64)  # replaces free_seen once finished
        self.pending_free: list[np.ndarray] = []  # (2, M) int64 (x, y) cell batches
        self.pose_dirty = False  # the back end moved it: the next delta carries the new pose
        self.T_corrected: np.ndarray | None = None  # the back end's pose, once it moved it

    def __len__(self) -> int:
        return int(self.keys.size)

    def add_points(self, points_submap: np.ndarray, colors: np.ndarray, voxel_m: float) -> None:
        inside = np.abs(points_submap) * 1000.0 < _INT16_MAX_MM
        if not inside.all():  # rare; a per-row all() costs more than the rest of the frame
            keep = inside.all(axis=1)
            points_submap, colors = points_submap[keep], colors[keep]
        if points_submap.shape[0] == 0:
            return
        keys = voxels.pack(voxels.voxel_indices(points_submap, voxel_m))
        uniq, _, inverse, counts = unique_groups(keys)
        col_sum = np.stack(
            [np.bincount(inverse, weights=colors[:, d], minlength=uniq.size) for d in range(3)], 1
        )
        pt_sum = np.stack([np.bincount(inverse, weights=points_submap[:, d], minlength=uniq.size)
                           for d in range(3)], 1)
        idx = np.searchsorted(self.keys, uniq)
        known = idx < self.keys.size
        known[known] = self.keys[idx[known]] == uniq[known]
        if not known.all():
            self._grow(uniq[~known], idx[~known])
            idx = np.searchsorted(self.keys, uniq)
        self.counts[idx] += counts
        self.color_sum[idx] += col_sum
        self.point_sum[idx] += pt_sum

    def _grow(self, new_keys: np.ndarray, at: np.ndarray) -> None:
        """Insert sorted `new_keys` before the old positions `at` (no re-sort of the map)."""
        n = self.keys.size + new_keys.size
        old = np.ones(n, bool)
        old[at + np.arange(new_keys.size)] = False

        def spread(a: np.ndarray) -> np.ndarray:
            out = np.zeros((n, *a.shape[1:]), a.dtype)
            row_items(out)[old] = row_items(np.ascontiguousarray(a))  # whole rows at a time
            return out

        keys = spread(self.keys)
        keys[~old] = new_keys
        self.color_sum, self.counts = spread(self.color_sum), spread(self.counts)
        self.point_sum = spread(self.point_sum)
        self.sent_counts, self.sent_colors = spread(self.sent_counts), spread(self.sent_colors)
        self.keys = keys

    def add_free(self, free_xy_submap: np.ndarray, cell_m: float) -> None:
        if free_xy_submap.shape[0] == 0 or self.free_seen is None:
            return
        ij = np.floor(free_xy_submap / cell_m).astype(np.int64) + _FREE_HALF
        inside = (ij >= 0) & (ij < 2 * _FREE_HALF)
        if not inside.all():
            ij = ij[inside.all(axis=1)]
        ij = ij[~self.free_seen[ij[:, 0], ij[:, 1]]]
        if ij.shape[0]:
            flat = unique_sorted(ij[:, 0] * (2 * _FREE_HALF) + ij[:, 1])
            new = np.stack(np.divmod(flat, 2 * _FREE_HALF))
            self.free_seen[new[0], new[1]] = True
            self.pending_free.append(new - _FREE_HALF)

    def pose(self) -> np.ndarray:
        """The pose published: the back end's when it moved the submap, else the front
        end's (`T_odom_submap`, which frames integrate against and never changes)."""
        return self.T_odom_submap if self.T_corrected is None else self.T_corrected

    def mean_points(self) -> np.ndarray:
        """(N, 3) mean of the points in each voxel, submap frame: on a surface, unlike the
        voxel centres, which stair-step it by up to half a voxel."""
        return self.point_sum / np.maximum(self.counts, 1)[:, None]

    def mean_colors(self) -> np.ndarray:
        return np.round(self.color_sum / np.maximum(self.counts, 1)[:, None]).astype(np.int64)

    def free_cells(self) -> np.ndarray:
        """(2, M) int64 (x, y) cells ever seen free."""
        if self.free_seen is None:
            return self.free_done
        return np.argwhere(self.free_seen).T - _FREE_HALF

    def finish(self) -> None:
        """Keep a finished submap small: its free-cell bitmap (640 kB) becomes a cell list."""
        self.free_done = self.free_cells()
        self.free_seen = None

    def mark_unsent(self) -> None:
        """Forget what was sent: the next delta is the whole submap (the edge may have lost it)."""
        self.sent_counts[:] = 0
        self.sent_colors[:] = 0
        cells = self.free_cells()
        self.pending_free = [cells] if cells.size else []

    def take_delta(
        self, voxel_m: float, color_resend: int, levels: int = 5, growth: int = 2
    ) -> SubmapDelta | None:
        """The changed voxels and new free cells since the last call, marked as sent."""
        colors = self.mean_colors()
        dirty = (self.sent_counts == 0) & (self.counts > 0)
        dirty |= _growth_level(self.counts, growth) > _growth_level(self.sent_counts, growth)
        if color_resend > 0:
            moved = np.abs(colors - self.sent_colors).max(axis=1, initial=0) >= color_resend
            dirty |= moved & (self.sent_counts > 0)
        if not dirty.any() and not self.pending_free and not self.pose_dirty:
            return None
        self.pose_dirty = False
        self.sent_counts[dirty] = self.counts[dirty]
        self.sent_colors[dirty] = colors[dirty]
        indices = voxels.unpack(self.keys[dirty])
        centres = voxels.centres(indices, voxel_m)
        offsets = (voxels.offset_codes(indices, self.mean_points()[dirty], voxel_m, levels)
                   if levels > 1 else np.zeros(0, np.uint8))
        free = np.concatenate([np.empty((2, 0), np.int64), *self.pending_free], axis=1)
        self.pending_free = []
        return SubmapDelta(
            submap_id=self.submap_id,
            T_odom_submap=self.pose().copy(),
            points_mm=np.round(centres * 1000.0).astype(np.int16).T.copy(),
            colors=colors[dirty].astype(np.uint8),
            counts=np.minimum(self.counts[dirty], np.iinfo(np.uint16).max).astype(np.uint16),
            free_cells=np.ascontiguousarray(free.astype(np.int16)),
            offsets=offsets, offset_levels=levels,
        )


class KeyframeMapper:
    """The current keyframe submap, the finished ones (for resending), and when to switch.

    Submap ids start at `id_base` (the agent uses epoch × 10 000), so a restarted agent never
    reuses an id its previous life sent to the edge.
    """

    def __init__(self, config: AgentConfig, id_base: int = 0) -> None:
        self.config = config
        self.current: VoxelSubmap | None = None
        self.done: list[VoxelSubmap] = []
        self.next_id = id_base

    def needs_keyframe(self, T_odom_base: np.ndarray, tick: int) -> bool:
        cur = self.current
        if cur is None:
            return True
        T_sub_base = invert(cur.T_odom_submap) @ T_odom_base
        x, y, yaw = xyyaw_from_T(T_sub_base)
        return bool(
            np.hypot(x, y) >= self.config.keyframe_dist_m
            or abs(wrap_angle(yaw)) >= self.config.keyframe_yaw_rad
            or tick - cur.start_tick >= self.config.keyframe_max_ticks
        )

    def start_keyframe(self, T_odom_base: np.ndarray, tick: int) -> VoxelSubmap:
        if self.current is not None:
            self.current.finish()
            self.done.append(self.current)
        self.current = VoxelSubmap(self.next_id, T_odom_base, tick)
        self.next_id += 1
        return self.current

    def integrate(
        self, points_submap: np.ndarray, colors: np.ndarray, free_xy_submap: np.ndarray
    ) -> None:
        assert self.current is not None, "start_keyframe first"
        self.current.add_points(points_submap, colors, self.config.voxel_m)
        self.current.add_free(free_xy_submap, self.config.cell_m)

    def take_delta(self) -> SubmapDelta | None:
        if self.current is None:
            return None
        return self.current.take_delta(self.config.voxel_m, self.config.color_resend,
                                       self.config.mean_levels, self.config.resend_growth)

    def submaps(self) -> list[VoxelSubmap]:
        """Every submap, oldest first, the open one last."""
        return [*self.done, *([self.current] if self.current is not None else [])]

    def pose_of(self, submap_id: int) -> np.ndarray | None:
        """Published T_loc_submap of a submap this agent made (None for an unknown id)."""
        for sub in reversed(self.submaps()):
            if sub.submap_id == submap_id:
                return sub.pose()
        return None

    def set_poses(self, poses: dict[int, np.ndarray]) -> None:
        """Move submaps (their voxels stay in their own frame) and queue the new poses."""
        for sub in self.submaps():
            if sub.submap_id in poses:
                sub.T_corrected = np.asarray(poses[sub.submap_id], np.float64).copy()
                sub.pose_dirty = True

    def take_pose_updates(self) -> list[SubmapDelta]:
        """Pose-only deltas of finished submaps the back end moved."""
        out = []
        for sub in self.done:
            if sub.pose_dirty:
                delta = sub.take_delta(self.config.voxel_m, self.config.color_resend,
                                       self.config.mean_levels, self.config.resend_growth)
                out += [delta] if delta is not None else []
        return out

    def published(self) -> list[tuple[int, int]]:
        """(submap id, voxels sent at least once) of every submap, oldest first."""
        subs = [*self.done, *([self.current] if self.current is not None else [])]
        return [(sub.submap_id, int((sub.sent_counts > 0).sum())) for sub in subs]

    def resend_all(self) -> list[SubmapDelta]:
        """Every submap in full, oldest first (after the edge came back)."""
        out = []
        for sub in [*self.done, *([self.current] if self.current is not None else [])]:
            sub.mark_unsent()
            delta = sub.take_delta(self.config.voxel_m, self.config.color_resend,
                                   self.config.mean_levels, self.config.resend_growth)
            out += [delta] if delta is not None else []
        return out


def decode_points_m(points_mm: np.ndarray) -> np.ndarray:
    """(3, N) int16 mm → (N, 3) float64 metres (the edge's view; used by tests)."""
    return points_mm.T.astype(np.float64) / 1000.0
