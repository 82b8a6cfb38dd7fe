"""The live time series' map figures, kept up to date as the maps change: only points that
appeared since the last sample are scored, and points that disappeared are taken back.

Why: scoring every sample's maps from scratch (a KD-tree of each map, a query of every truth
point) cost the launcher 58 of its 69 CPU-seconds in a 135 s house mission on two cores
(docs/benchmarks.md, issue 13); a sample now costs what changed since the last one.

The figures equal `scoring.map_quality`'s on the same points exactly, not approximately:
- what scoring needs of a map point depends on that point alone: whether it is a ghost (no
  static surface within ghost_dist) and which observable truth points lie strictly within the
  coverage radius (`cKDTree.query`'s distance bound is strict, `query_ball_point`'s is not, so
  its candidates are filtered). Per truth point we count the map points covering it; a point
  that disappears is looked up again (same inputs, same answer) and its counts taken back.
  Looking up again is simpler than caching each point's truth indices, and removals are rare
  (they come with pose corrections).
- a ghost is a per-voxel verdict, which equals the per-point one when every voxel of
  `voxel_m` holds one point: the edge's maps are voxel centres at that size. A map with two
  points in a voxel is refused (`MapTally.update` returns False; the caller scores from
  scratch).
A point is known by its voxel key and its coordinates: one that moved inside its voxel is a
removal plus an addition.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from itertools import chain

import numpy as np
from scipy.spatial import cKDTree

from services.common import voxels
from services.evaluator import metrics as mx
from services.evaluator.scoring import Probe, map_quality

GhostTest = Callable[[np.ndarray], np.ndarray]


class TruthIndex:
    """The observable truth points and their KD-tree, for radius look-ups."""

    def __init__(self, points: np.ndarray, tree: cKDTree, radius_m: float) -> None:
        self.points, self.tree, self.radius_m = points, tree, radius_m

    def __len__(self) -> int:
        return len(self.points)

    def hits(self, pts: np.ndarray) -> np.ndarray:
        """(N,) int32: for each truth point, how many of `pts` lie strictly within the radius
        (the bound of `metrics.covered_mask`)."""
        if len(pts) == 0 or len(self.points) == 0:
            return np.zeros(len(self.points), np.int32)
        lists = self.tree.query_ball_point(pts, self.radius_m, return_sorted=False)
        sizes = np.fromiter(map(len, lists), np.int64, len(lists))
        idx = np.fromiter(chain.from_iterable(lists), np.int64, int(sizes.sum()))
        d = self.points[idx] - pts[np.repeat(np.arange(len(pts)), sizes)]
        # the same float64 sum of squares, in the same order, as cKDTree's distance test
        d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
        inside = idx[d2 < self.radius_m * self.radius_m]
        return np.bincount(inside, minlength=len(self.points)).astype(np.int32)


class MapTally:
    """One map's points (sorted by voxel key) and, per truth point, the number of its counting
    points within the radius. With a ghost test, ghost points are kept but do not count."""

    def __init__(self, truth: TruthIndex, voxel_m: float, ghost: GhostTest | None) -> None:
        self.truth, self.voxel_m, self.ghost = truth, voxel_m, ghost
        self.keys = np.zeros(0, np.int64)
        self.points = np.zeros((0, 3))
        self.counting = np.zeros(0, bool)
        self.counts = np.zeros(len(truth), np.int32)

    @property
    def n_ghost(self) -> int:
        return int(self.counting.size - np.count_nonzero(self.counting))

    def covered(self) -> np.ndarray:
        """(N_truth,) bool: truth points a counting point covers."""
        return self.counts > 0

    def update(self, points: np.ndarray) -> bool:
        """Make the tally that of `points`; False (tally unchanged) when a voxel holds two."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        keys = voxels.pack(voxels.voxel_indices(pts, self.voxel_m))
        if keys.size > 1 and not np.all(keys[1:] > keys[:-1]):  # the edge sends them sorted
            order = np.argsort(keys, kind="stable")
            keys, pts = keys[order], pts[order]
            if np.any(keys[1:] == keys[:-1]):
                return False
        same, pos = self._unchanged(keys, pts)
        kept = np.zeros(self.keys.size, bool)
        kept[pos[same]] = True
        gone = ~kept & self.counting
        self.counts -= self.truth.hits(self.points[gone])
        counting = np.empty(keys.size, bool)
        counting[same] = self.counting[pos[same]]
        new = pts[~same]
        counting[~same] = ~self.ghost(new) if self.ghost is not None else True
        self.counts += self.truth.hits(new[counting[~same]])
        self.keys, self.points, self.counting = keys, pts, counting
        return True

    def _unchanged(self, keys: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(bool per new point: held before at the same coordinates, its index before)."""
        pos = np.searchsorted(self.keys, keys)
        same = pos < self.keys.size
        same[same] = self.keys[pos[same]] == keys[same]
        same[same] = np.all(self.points[pos[same]] == pts[same], axis=1)
        return same, pos


class LiveQuality:
    """`map_quality`'s series figures (coverage, overlap, BV, ghost volume) of a merged map and
    the robots' own maps that change from sample to sample; not thread-safe."""

    def __init__(self, probe: Probe) -> None:
        self.probe = probe
        ev = probe.ev
        self.truth = TruthIndex(probe.gt.observable_points_world, probe.observable_tree,
                                ev.coverage_radius_m)
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
        ok = self.merged.update(points_world)
        ok = all([tally.update(p) for tally, p in zip(self.robots, robot_points, strict=True)]
                 ) and ok
        if not ok:
            return map_quality(self.probe, points_world, robot_points)
        return self.figures(bool(robot_points))

    def figures(self, with_overlap: bool) -> dict[str, float | None]:
        """The tallies' figures, with `map_quality`'s formulas."""
        total = len(self.truth)
        n_ghost, n_occupied = self.merged.n_ghost, self.merged.keys.size
        covered = np.count_nonzero(self.merged.covered())
        return {
            "coverage_3d_pct": float(100.0 * covered / total) if total else 0.0,
            "overlap_3d_pct": (mx.overlap_pct([t.covered() for t in self.robots])
                               if with_overlap else None),
            "bounding_volume_pct": 100.0 * n_ghost / n_occupied if n_occupied else 0.0,
            "ghost_volume_m3": n_ghost * self.probe.ev.voxel_m**3,
        }
