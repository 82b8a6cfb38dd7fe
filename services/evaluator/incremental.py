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
- a ghost is a per-voxel verdict, which equals the per-point one (`Probe.surface_distance`
  of that point alone) when every voxel of `voxel_m` holds one point: the edge's maps are
  voxel centres at that size. A map with two points in a voxel is refused
  (`MapTally.update` returns False; the caller scores from scratch).
A point is known by its voxel key and its coordinates: one that moved inside its voxel is a
removal plus an addition.
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


@dataclass(frozen=True)
class _Change:
    """A map's next points (sorted by key) against the tally's: which are new, which old
    ones are gone."""

    keys: np.ndarray
    pts: np.ndarray
    same: np.ndarray  # per new point: held before at the same coordinates
    pos: np.ndarray  # per new point: its index before, where `same`
    gone: np.ndarray  # per old point: no longer held


class MapTally:
    """One map's points (sorted by voxel key) and the truth points its counting points cover
    (`metrics.covered_mask`). With a ghost test, ghost points are kept but do not count."""

    def __init__(self, truth: TruthIndex, voxel_m: float, ghost: GhostTest | None) -> None:
        self.truth, self.voxel_m, self.ghost = truth, voxel_m, ghost
        self.keys = np.zeros(0, np.int64)
        self.points = np.zeros((0, 3))
        self.counting = np.zeros(0, bool)
        self.covered = np.zeros(len(truth), bool)

    @property
    def n_ghost(self) -> int:
        return int(self.counting.size - np.count_nonzero(self.counting))

    def update(self, points: np.ndarray) -> bool:
        """Make the tally that of `points`; False (tally unchanged) when a voxel holds two."""
        change = self.diff(points)
        if change is None:
            return False
        gone = self.points[change.gone & self.counting]
        new = change.pts[~change.same]
        counting_new = self.counting_of(new)
        counting = np.empty(change.keys.size, bool)
        counting[change.same] = self.counting[change.pos[change.same]]
        counting[~change.same] = counting_new
        self.keys, self.points, self.counting = change.keys, change.pts, counting
        self._cover(new[counting_new])
        self._uncover(gone)
        return True

    def diff(self, points: np.ndarray) -> _Change | None:
        """How `points` differ from the tally's; None when a voxel holds two of them."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        keys = voxels.pack(voxels.voxel_indices(pts, self.voxel_m))
        if keys.size > 1 and not np.all(keys[1:] > keys[:-1]):  # the edge sends them sorted
            order = np.argsort(keys, kind="stable")
            keys, pts = keys[order], pts[order]
            if np.any(keys[1:] == keys[:-1]):
                return None
        pos = np.searchsorted(self.keys, keys)
        same = pos < self.keys.size
        same[same] = self.keys[pos[same]] == keys[same]
        same[same] = np.all(self.points[pos[same]] == pts[same], axis=1)
        gone = np.ones(self.keys.size, bool)
        gone[pos[same]] = False
        return _Change(keys, pts, same, pos, gone)

    def counting_of(self, new_pts: np.ndarray) -> np.ndarray:
        """Which new points count (all, or the non-ghosts)."""
        if self.ghost is None:
            return np.ones(len(new_pts), bool)
        return ~self.ghost(new_pts)

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
        """The figures of these maps; from scratch (`map_quality`) where a map has two points
        in one voxel."""
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
        n_ghost, n_occupied = self.merged.n_ghost, self.merged.keys.size
        covered = np.count_nonzero(self.merged.covered)
        return {
            "coverage_3d_pct": float(100.0 * covered / total) if total else 0.0,
            "overlap_3d_pct": (mx.overlap_pct([t.covered for t in self.robots])
                               if with_overlap else None),
            "bounding_volume_pct": 100.0 * n_ghost / n_occupied if n_occupied else 0.0,
            "ghost_volume_m3": n_ghost * self.probe.ev.voxel_m**3,
        }
