"""The live time series' map figures, kept up to date as the maps change: only points that
appeared since the last sample are scored, and points that disappeared are taken back.

Why: scoring every sample's maps from scratch (a KD-tree of each map, a query of every truth
point) cost the launcher 58 of its 69 CPU-seconds in a 135 s house mission on two cores
(docs/benchmarks.md, issue 13); a sample now costs what changed since the last one.

The figures equal `scoring.map_quality`'s on the same points exactly, not approximately:
- coverage is `metrics.covered_mask`'s query, asked only about the truth around what changed
  (`truth_cells.TruthIndex`). New counting points are asked about the uncovered truth around
  them: a truth point with one of them in its own cell of side radius/2 (in either of two
  grids offset by half a cell) is covered unasked (they lie within 0.87·radius). Each
  covered truth point keeps one covering point as its witness; only truth whose witness
  went, moved or stopped counting is asked again, of the counting points around it. (A
  count of covering points per truth point would make removals a subtraction, but listing
  every (point, truth) pair within the radius cost more than scoring from scratch: ~30
  pairs a point.)
- a ghost is a per-voxel verdict (`Probe.ghost_point_mask`): a voxel of `voxel_m` is a ghost
  when none of its points lies within `ghost_dist_m` of a surface. Each point's own test is
  made once, when it appears; the voxels' verdicts are redrawn each sample from those (the
  edge's maps are voxel means, several to a voxel at this size), and a point whose voxel
  turned ghost or stopped being one is taken back or scored like one that went or came.
A point is known by its exact coordinates (`point_ids`), or by the edge's voxel key where the
sampler asks the edge for what changed since its last sample (`MapTally.apply`): then a sample
costs the points that changed, not the map. One that moved is a removal plus an addition. A
map holding one point twice is refused (`MapTally.update` returns False; the caller scores
from scratch).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from services.common import voxels
from services.common.arrays import in_sorted, unique_sorted
from services.evaluator import metrics as mx
from services.evaluator.point_slots import PointSlots
from services.evaluator.scoring import Probe, map_quality
from services.evaluator.truth_cells import TruthIndex

GhostTest = Callable[[np.ndarray], np.ndarray]


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


def keyed_ids(keys: np.ndarray) -> np.ndarray:
    """(N,) uint64 ids of points known by an int64 key (the edge's world voxel keys, one
    point per key), in the keys' order: a sorted key array stays sorted."""
    return np.asarray(keys, np.int64).view(np.uint64) ^ np.uint64(1 << 63)


class MapTally:
    """One map's points (sorted by id) and the truth points its counting points cover
    (`metrics.covered_mask`). With a ghost test, a voxel all of whose points fail it is a
    ghost: its points are kept but do not count (`Probe.ghost_point_mask`). The voxels'
    verdicts are kept as counts per voxel (points held, points that pass the test) and
    redrawn for the voxels a sample touched only; without a test every point counts, and no
    voxels are counted (`n_voxels`, `n_ghost` stay 0).

    Two ways in: `update(points)`, the whole map, its points known by their coordinates;
    `apply(ids, points, whole)`, points known by a key (`keyed_ids`), either the whole map
    or (whole=False) only those added or moved since the last call, which costs what changed.
    """

    def __init__(self, truth: TruthIndex, voxel_m: float, ghost: GhostTest | None) -> None:
        self.truth, self.voxel_m, self.ghost = truth, voxel_m, ghost
        self.keyed = False  # ids are keyed_ids (apply), not coordinate hashes (update)
        self.store = PointSlots()  # the held points, by slot
        self.ids = np.zeros(0, np.uint64)  # sorted ids of the held points
        self.slot = np.zeros(0, np.int64)  # their slots, in id order
        self.covered = np.zeros(len(truth), bool)
        self.witness = np.zeros(len(truth), np.uint64)  # per covered truth point: a coverer
        self.vkeys = np.zeros(0, np.int64)  # sorted keys of the occupied voxels
        self.vpoints = np.zeros(0, np.int64)  # per voxel: points held
        self.vnear = np.zeros(0, np.int64)  # per voxel: points that pass the ghost test
        self.n_voxels = 0
        self.n_ghost = 0

    def update(self, points: np.ndarray) -> bool:
        """Make the tally that of `points`; False (tally unchanged) when two are equal."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        ids = point_ids(pts)
        order = np.argsort(ids, kind="stable")
        ids, pts = ids[order], pts[order]
        if np.any(ids[1:] == ids[:-1]):
            return False
        if self.keyed:
            self._apply(np.ones(self.ids.size, bool), ids, pts)
        else:
            same, removed = self._match(ids, pts, whole=True)
            if np.any(in_sorted(ids[~same], self.ids[~removed])):  # a hash shared: refuse
                return False
            self._apply(removed, ids[~same], pts[~same])
        self.keyed = False
        return True

    def apply(self, ids: np.ndarray, points: np.ndarray, whole: bool) -> bool:
        """Make the tally that of keyed points (`ids` sorted, unique): these and no others
        (`whole`), or these replacing or joining the held ones. False (tally unchanged) for
        a change to a tally that does not hold keyed points, or ids out of order."""
        ids = np.asarray(ids, np.uint64)
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if (not whole and not self.keyed) or np.any(ids[1:] <= ids[:-1]):
            return False
        if self.keyed or not whole:
            same, removed = self._match(ids, pts, whole)
        else:  # hashed ids never match keyed ones
            same, removed = np.zeros(ids.size, bool), np.ones(self.ids.size, bool)
        self._apply(removed, ids[~same], pts[~same])
        self.keyed = True
        return True

    def _match(self, ids: np.ndarray, pts: np.ndarray, whole: bool
               ) -> tuple[np.ndarray, np.ndarray]:
        """Per given point: held already at the same coordinates; per held point: removed
        (not among the given ones when `whole`; given with other coordinates)."""
        pos = np.searchsorted(self.ids, ids)  # sorted needles: a fast, forward search
        found = pos < self.ids.size
        found[found] = self.ids[pos[found]] == ids[found]
        same = found.copy()
        same[found] = np.all(self.store.points[self.slot[pos[found]]] == pts[found], axis=1)
        if whole:
            removed = np.ones(self.ids.size, bool)
            removed[pos[same]] = False
        else:
            removed = np.zeros(self.ids.size, bool)
            removed[pos[found & ~same]] = True
        return same, removed

    def _apply(self, removed: np.ndarray, add_ids: np.ndarray, add_pts: np.ndarray) -> None:
        """Take back the `removed` held points (a mask over `ids`) and score the new ones
        (sorted ids, none a kept point's)."""
        store = self.store
        gone = self.slot[removed]
        add_near = self.near_of(add_pts)
        add_voxel = voxels.pack(voxels.voxel_indices(add_pts, self.voxel_m))
        flipped = np.zeros(0, np.int64)
        if self.ghost is not None:  # without a test every point counts: no verdicts to keep
            flipped = self._recount(store.voxel[gone], store.near[gone], add_voxel, add_near)
        lost = gone[store.counting[gone]]
        store.kill(gone)
        stop = start = np.zeros(0, np.int64)
        if flipped.size:  # a kept point's verdict changes only with its voxel's
            hit = np.flatnonzero(store.used("alive") & in_sorted(store.used("voxel"), flipped))
            now = self._cleared(store.voxel[hit])
            stop, start = hit[store.counting[hit] & ~now], hit[~store.counting[hit] & now]
            store.counting[hit] = now
        add_counting = self._cleared(add_voxel)
        new = store.append(add_ids, add_pts, add_near, add_counting, add_voxel,
                           self.truth.cells_of(add_pts))
        if removed.any():
            keep = ~removed
            self.ids, self.slot = self.ids[keep], self.slot[keep]
        at = np.searchsorted(self.ids, add_ids)
        self.ids = np.insert(self.ids, at, add_ids)
        self.slot = np.insert(self.slot, at, new)
        lost = np.concatenate([lost, stop])
        self._uncover(store.ids[lost], store.cell[lost])
        gained = np.concatenate([new[add_counting], start])
        self._cover(store.points[gained], store.ids[gained], store.cell[gained])
        moved = store.compact()
        if moved is not None:
            self.slot = moved[self.slot]

    def near_of(self, new_pts: np.ndarray) -> np.ndarray:
        """Which new points pass the ghost test on their own (all, without one)."""
        if self.ghost is None:
            return np.ones(len(new_pts), bool)
        return ~self.ghost(new_pts)

    def _recount(self, gone_voxel: np.ndarray, gone_near: np.ndarray,
                 add_voxel: np.ndarray, add_near: np.ndarray) -> np.ndarray:
        """Move the per-voxel counts by the points that went and came; the sorted keys of
        the voxels held before whose verdict (holds a point that passes the ghost test)
        changed: the voxels of the points kept."""
        touched = unique_sorted(np.concatenate([gone_voxel, add_voxel]))
        old = in_sorted(touched, self.vkeys)
        new = touched[~old]
        if new.size:
            at = np.searchsorted(self.vkeys, new)
            self.vkeys = np.insert(self.vkeys, at, new)
            self.vpoints = np.insert(self.vpoints, at, 0)
            self.vnear = np.insert(self.vnear, at, 0)
        where = np.searchsorted(self.vkeys, touched)
        before = self.vnear[where] > 0
        for keys, near, sign in ((gone_voxel, gone_near, -1), (add_voxel, add_near, 1)):
            i = np.searchsorted(self.vkeys, keys)
            np.add.at(self.vpoints, i, sign)
            np.add.at(self.vnear, i[near], sign)
        flipped = touched[old & (before != (self.vnear[where] > 0))]
        if np.any(self.vpoints[where] == 0):
            alive = self.vpoints > 0
            self.vkeys, self.vpoints, self.vnear = (
                self.vkeys[alive], self.vpoints[alive], self.vnear[alive])
        self.n_voxels = int(self.vkeys.size)
        self.n_ghost = int(self.n_voxels - np.count_nonzero(self.vnear))
        return flipped

    def _cleared(self, voxel: np.ndarray) -> np.ndarray:
        """Per point (by its voxel's key, held): its voxel counts (all do without a test)."""
        if self.ghost is None:
            return np.ones(voxel.size, bool)
        return self.vnear[np.searchsorted(self.vkeys, voxel)] > 0

    def _cover(self, new_pts: np.ndarray, new_ids: np.ndarray, new_cells: np.ndarray) -> None:
        """Truth the new counting points cover (only uncovered truth around them is asked),
        each with the nearest of them as its witness."""
        cand = self.truth.around_cells(new_cells)
        cand = cand[~self.covered[cand]]
        if cand.size == 0:
            return
        for shifted in (False, True):  # first: a new point in the same fine cell
            keys = self.truth.fine_cells_of(new_pts, shifted)
            order = np.argsort(keys, kind="stable")
            keys = keys[order]
            truth_keys = (self.truth.fine_shifted if shifted else self.truth.fine)[cand]
            at = np.minimum(np.searchsorted(keys, truth_keys), keys.size - 1)
            same = keys[at] == truth_keys
            self.covered[cand[same]] = True
            self.witness[cand[same]] = new_ids[order[at[same]]]
            cand = cand[~same]
        self._ask(cand, new_pts, new_ids)

    def _uncover(self, gone_ids: np.ndarray, gone_cells: np.ndarray) -> None:
        """Covered truth whose witness went (or moved) is asked again of the counting points
        around it: any other truth keeps a counting point within the radius, its witness."""
        if gone_ids.size == 0:
            return
        cand = self.truth.around_cells(gone_cells)  # a witness lies within its truth's radius
        cand = cand[self.covered[cand]]
        cand = cand[in_sorted(self.witness[cand], unique_sorted(gone_ids))]
        if cand.size == 0:
            return
        store = self.store
        local = self.truth.near_cells(store.used("cell"), cand) & store.used("counting")
        self._ask(cand, store.used("points")[local], store.used("ids")[local])

    def _ask(self, cand: np.ndarray, pts: np.ndarray, ids: np.ndarray) -> None:
        """Set the truth points `cand` covered or not by `pts` (`metrics.covered_mask`'s
        query), the nearest as the witness of those covered."""
        if cand.size == 0:
            return
        if len(pts) == 0:
            self.covered[cand] = False
            return
        # a tree used once: the sliding-midpoint build (unbalanced, uncompacted) costs less,
        # and the query's answer does not depend on the tree's shape
        tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)
        dist, nearest = tree.query(self.truth.points[cand],
                                   distance_upper_bound=self.truth.radius_m)
        hit = np.isfinite(dist)
        self.covered[cand] = hit
        self.witness[cand[hit]] = ids[nearest[hit]]


@dataclass(frozen=True)
class MapChange:
    """One map as a sample sees it: the whole map, its points known by their coordinates
    (ids None), or points known by key (`keyed_ids`), the whole map or only those added or
    moved since the last sample (whole=False)."""

    points: np.ndarray  # (N, 3) world frame, metres
    ids: np.ndarray | None = None  # (N,) uint64 sorted keyed_ids
    whole: bool = True


class LiveQuality:
    """`map_quality`'s series figures (coverage, overlap, BV, ghost volume) of a merged map and
    the robots' own maps that change from sample to sample; not thread-safe."""

    def __init__(self, probe: Probe) -> None:
        self.probe = probe
        ev = probe.ev
        self.truth = TruthIndex(probe.gt.observable_points_world, ev.coverage_radius_m)
        self.merged = MapTally(self.truth, ev.voxel_m, self._is_ghost)
        self.robots: list[MapTally] = []
        probe.surface_tree, probe.surface_cells  # noqa: B018  built now, not in the first sample

    def _is_ghost(self, pts: np.ndarray) -> np.ndarray:
        # `Probe.ghost_point_mask`'s test, for one point per voxel
        return ~self.probe.near_surface(pts)

    def __call__(
        self, points_world: np.ndarray, robot_points: Sequence[np.ndarray] | None
    ) -> dict[str, float | None]:
        """The figures of these whole maps; from scratch (`map_quality`) where a map holds
        one point twice."""
        robot_points = list(robot_points or [])
        figures = self.apply(MapChange(points_world), [MapChange(p) for p in robot_points])
        if figures is None:
            return map_quality(self.probe, points_world, robot_points)
        return figures

    def apply(self, merged: MapChange, robots: Sequence[MapChange]
              ) -> dict[str, float | None] | None:
        """The figures after these changes; None where a tally refused one (a point held
        twice, a change to a map it does not hold keyed): the caller then sends whole maps."""
        if len(self.robots) != len(robots):
            self.robots = [MapTally(self.truth, self.probe.ev.voxel_m, None) for _ in robots]
        ok = [t.update(c.points) if c.ids is None else t.apply(c.ids, c.points, c.whole)
              for t, c in zip([self.merged, *self.robots], [merged, *robots], strict=True)]
        return self.figures(bool(robots)) if all(ok) else None

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
