"""The live time series' map figures, kept up to date as the maps change: only points that
appeared since the last sample are scored, and points that disappeared are taken back.

Why: scoring every sample's maps from scratch (a KD-tree of each map, a query of every truth
point) cost the launcher 58 of its 69 CPU-seconds in a 135 s house mission on two cores
(docs/benchmarks.md, issue 13); a sample now costs what changed since the last one.

The figures equal `scoring.map_quality`'s on the same points exactly, not approximately:
- coverage is `metrics.covered_mask` itself, asked only about the truth around what changed:
  truth within the radius of a point lies in that point's cell of a grid a bit coarser than
  the radius, or in one of the 26 around it. New counting points are asked about the
  uncovered truth around them; covered truth around points that went is asked again of the
  counting points left around it. (A count of covering points per truth point would make
  removals a subtraction, but listing every (point, truth) pair within the radius cost more
  than scoring from scratch: ~30 pairs a point.)
- a ghost is a per-voxel verdict (`Probe.ghost_point_mask`): a voxel of `voxel_m` is a ghost
  when none of its points lies within `ghost_dist_m` of a surface. Each point's own test is
  made once, when it appears; the voxels' verdicts are redrawn each sample from those (the
  edge's maps are voxel means, several to a voxel at this size), and a point whose voxel
  turned ghost or stopped being one is taken back or scored like one that went or came.
A point is known by its exact coordinates (`point_ids`): one that moved is a removal plus an
addition. A map holding one point twice is refused (`MapTally.update` returns False; the
caller scores from scratch).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from services.common import voxels
from services.evaluator import metrics as mx
from services.evaluator.scoring import Probe, map_quality

GhostTest = Callable[[np.ndarray], np.ndarray]


def _neighbour_offsets() -> np.ndarray:
    """Packed-key offsets of a cell's 3×3×3 neighbourhood (fields do not overflow: indices
    stay far inside ±2^20)."""
    d = np.array([-1, 0, 1], np.int64)
    dx, dy, dz = np.meshgrid(d, d, d, indexing="ij")
    return ((dx << 42) + (dy << 21) + dz).ravel()


NEIGHBOURS = _neighbour_offsets()


class TruthIndex:
    """The observable truth points bucketed in cells a bit larger than the coverage radius:
    every truth point within the radius of a point lies in that point's cell or one of its 26
    neighbours, so a change only looks at the truth around it."""

    def __init__(self, points: np.ndarray, radius_m: float) -> None:
        self.points, self.radius_m = points, radius_m
        self.cell_m = 1.25 * radius_m  # the margin keeps float rounding off the bound
        cells = self.cells_of(points)
        self.order = np.argsort(cells, kind="stable")
        self.sorted_cells = cells[self.order]

    def __len__(self) -> int:
        return len(self.points)

    def cells_of(self, pts: np.ndarray) -> np.ndarray:
        return voxels.pack(voxels.voxel_indices(pts, self.cell_m))

    def around(self, pts: np.ndarray) -> np.ndarray:
        """Indices of the truth points in the cells around `pts` (a superset of those
        within the radius of one of them)."""
        if len(pts) == 0:
            return np.zeros(0, np.int64)
        cells = np.unique(self.cells_of(pts))
        near = np.unique((cells[:, None] + NEIGHBOURS[None, :]).ravel())
        lo = np.searchsorted(self.sorted_cells, near, side="left")
        lens = np.searchsorted(self.sorted_cells, near, side="right") - lo
        idx = np.repeat(lo - np.cumsum(lens) + lens, lens) + np.arange(lens.sum())
        return self.order[idx]


def _mix(x: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser: every input bit moves every output bit (float32 values read
    as float64 have 29 zero low bits, which a plain product would keep)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def point_ids(pts: np.ndarray) -> np.ndarray:
    """(N,) uint64 id of each point's exact coordinates (a hash: equal points, equal ids;
    `MapTally.diff` checks the coordinates of every match)."""
    bits = np.ascontiguousarray(pts, dtype=np.float64).view(np.uint64).reshape(-1, 3)
    return _mix(_mix(_mix(bits[:, 0]) ^ bits[:, 1]) ^ bits[:, 2])


@dataclass(frozen=True)
class _Change:
    """A map's next points (sorted by id) against the tally's: which are new, which old
    ones are gone."""

    ids: np.ndarray
    pts: np.ndarray
    same: np.ndarray  # per new point: held before at the same coordinates
    pos: np.ndarray  # per new point: its index before, where `same`
    gone: np.ndarray  # per old point: no longer held


class MapTally:
    """One map's points (sorted by id) and the truth points its counting points cover
    (`metrics.covered_mask`). With a ghost test, a voxel all of whose points fail it is a
    ghost: its points are kept but do not count (`Probe.ghost_point_mask`)."""

    def __init__(self, truth: TruthIndex, voxel_m: float, ghost: GhostTest | None) -> None:
        self.truth, self.voxel_m, self.ghost = truth, voxel_m, ghost
        self.ids = np.zeros(0, np.uint64)
        self.points = np.zeros((0, 3))
        self.near = np.zeros(0, bool)  # per point: passes the ghost test on its own
        self.counting = np.zeros(0, bool)
        self.covered = np.zeros(len(truth), bool)
        self.n_voxels = 0
        self.n_ghost = 0

    def update(self, points: np.ndarray) -> bool:
        """Make the tally that of `points`; False (tally unchanged) when two are equal."""
        change = self.diff(points)
        if change is None:
            return False
        same, pos = change.same, change.pos
        near = np.empty(change.ids.size, bool)
        near[same] = self.near[pos[same]]
        near[~same] = self.near_of(change.pts[~same])
        counting = self._counting(change.pts, near)
        was = np.zeros(change.ids.size, bool)
        was[same] = self.counting[pos[same]]
        kept = np.zeros(self.ids.size, bool)  # old points still held and still counting
        kept[pos[same & counting]] = True
        lost = self.points[self.counting & ~kept]  # went, or their voxel became a ghost
        gained = change.pts[counting & ~was]
        self.ids, self.points, self.near, self.counting = change.ids, change.pts, near, counting
        self._cover(gained)
        self._uncover(lost)
        return True

    def diff(self, points: np.ndarray) -> _Change | None:
        """How `points` differ from the tally's; None when two of them are equal."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        ids = point_ids(pts)
        order = np.argsort(ids, kind="stable")
        ids, pts = ids[order], pts[order]
        if np.any(ids[1:] == ids[:-1]):
            return None
        pos = np.searchsorted(self.ids, ids)
        same = pos < self.ids.size
        same[same] = self.ids[pos[same]] == ids[same]
        same[same] = np.all(self.points[pos[same]] == pts[same], axis=1)
        gone = np.ones(self.ids.size, bool)
        gone[pos[same]] = False
        return _Change(ids, pts, same, pos, gone)

    def near_of(self, new_pts: np.ndarray) -> np.ndarray:
        """Which new points pass the ghost test on their own (all, without one)."""
        if self.ghost is None:
            return np.ones(len(new_pts), bool)
        return ~self.ghost(new_pts)

    def _counting(self, pts: np.ndarray, near: np.ndarray) -> np.ndarray:
        """Per point: its voxel holds a point that passes the ghost test; the voxel counts."""
        if self.ghost is None:  # every point counts; the voxels are not asked for
            return np.ones(len(pts), bool)
        keys = voxels.pack(voxels.voxel_indices(pts, self.voxel_m))
        uniq, inverse = np.unique(keys, return_inverse=True)
        cleared = np.zeros(uniq.size, bool)
        cleared[inverse[near]] = True
        self.n_voxels, self.n_ghost = int(uniq.size), int(uniq.size - np.count_nonzero(cleared))
        return cleared[inverse]

    def _cover(self, new: np.ndarray) -> None:
        """Truth the new counting points cover (only uncovered truth around them is asked)."""
        cand = self.truth.around(new)
        cand = cand[~self.covered[cand]]
        r = self.truth.radius_m
        self.covered[cand] = mx.covered_mask(new, self.truth.points[cand], r)

    def _uncover(self, gone: np.ndarray) -> None:
        """Covered truth around points that went is asked again of the counting points left
        around it (those within the radius of it lie in the cells around it)."""
        cand = self.truth.around(gone)
        cand = cand[self.covered[cand]]
        if cand.size == 0:
            return
        truth = self.truth.points[cand]
        near = np.isin(self.truth.cells_of(self.points),
                       (np.unique(self.truth.cells_of(truth))[:, None] + NEIGHBOURS).ravel())
        local = self.points[near & self.counting]
        self.covered[cand] = mx.covered_mask(local, truth, self.truth.radius_m)


class LiveQuality:
    """`map_quality`'s series figures (coverage, overlap, BV, ghost volume) of a merged map and
    the robots' own maps that change from sample to sample; not thread-safe."""

    def __init__(self, probe: Probe) -> None:
        self.probe = probe
        ev = probe.ev
        self.truth = TruthIndex(probe.gt.observable_points_world, ev.coverage_radius_m)
        self.merged = MapTally(self.truth, ev.voxel_m, self._is_ghost)
        self.robots: list[MapTally] = []

    def _is_ghost(self, pts: np.ndarray) -> np.ndarray:
        # `Probe.ghost_point_mask`'s test, for one point per voxel
        return ~(self.probe.surface_distance(pts) <= self.probe.ev.ghost_dist_m)

    def __call__(
        self, points_world: np.ndarray, robot_points: Sequence[np.ndarray] | None
    ) -> dict[str, float | None]:
        """The figures of these maps; from scratch (`map_quality`) where a map holds one
        point twice."""
        robot_points = list(robot_points or [])
        if len(self.robots) != len(robot_points):
            self.robots = [MapTally(self.truth, self.probe.ev.voxel_m, None)
                           for _ in robot_points]
        ok = [t.update(p) for t, p in zip([self.merged, *self.robots],
                                          [points_world, *robot_points], strict=True)]
        if not all(ok):
            return map_quality(self.probe, points_world, robot_points)
        return self.figures(bool(robot_points))

    def figures(self, with_overlap: bool) -> dict[str, float | None]:
        """The tallies' figures, with `map_quality`'s formulas."""
        total = len(self.truth)
        n_ghost, n_occupied = self.merged.n_ghost, self.merged.n_voxels
        covered = np.count_nonzero(self.merged.covered)
        return {
            "coverage_3d_pct": float(100.0 * covered / total) if total else 0.0,
            "overlap_3d_pct": (mx.overlap_pct([t.covered for t in self.robots])
                               if with_overlap else None),
            "bounding_volume_pct": 100.0 * n_ghost / n_occupied if n_occupied else 0.0,
            "ghost_volume_m3": n_ghost * self.probe.ev.voxel_m**3,
        }
