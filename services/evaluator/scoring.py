"""metrics.json from a run's maps, grids, trajectories and time series (SPEC §5, §7).

One function scores both the live run (`spacemap run`) and a finished run folder
(`spacemap eval`), so the two agree by construction; `Probe` holds the ground truth's
KD-trees so that the live coverage time series stays cheap.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from schemas import messages as m
from services.common import voxels
from services.common.arrays import in_sorted, unique_sorted
from services.common.grid import GridSpec
from services.evaluator import metrics as mx
from services.evaluator.config import EvalConfig
from services.evaluator.ground_truth import GroundTruth

# Live-only fields: measured while the mission ran, copied from live.json by `spacemap eval`.
LIVE_KEYS = ("mapping_time_s", "bytes_per_robot", "sim_time_s", "wall_time_s", "completed")


def grid_spec(grid: m.OccupancyGrid) -> GridSpec:
    H, W = grid.cells.shape
    return GridSpec(grid.origin_x, grid.origin_y, grid.resolution_m, H, W)


@dataclass
class Probe:
    """Ground truth plus its KD-trees, built once per run."""

    gt: GroundTruth
    ev: EvalConfig
    _surface_tree: cKDTree | None = field(default=None, repr=False)
    _observable_tree: cKDTree | None = field(default=None, repr=False)
    _surface_cells: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    _free_cells: tuple[GridSpec, np.ndarray, int] | None = field(default=None, repr=False)
    # the last `map_quality` (maps' digest, figures): a mission's end scores the same final
    # maps twice, as the series' last row and as metrics.json (read back from the PLY files)
    _quality_memo: tuple[bytes, dict[str, float | None]] | None = field(default=None,
                                                                        repr=False)

    @property
    def surface_tree(self) -> cKDTree:
        if self._surface_tree is None:
            self._surface_tree = cKDTree(self.gt.surface_points_world)
        return self._surface_tree

    @property
    def observable_tree(self) -> cKDTree:
        """The observable truth points' KD-tree (the live series' radius look-ups)."""
        if self._observable_tree is None:
            self._observable_tree = cKDTree(self.gt.observable_points_world)
        return self._observable_tree

    def surface_distance(self, points_world: np.ndarray) -> np.ndarray:
        """(N,) distance of each point to the nearest static surface sample."""
        if len(points_world) == 0:
            return np.zeros(0)
        dist, _ = self.surface_tree.query(points_world)
        return dist

    def near_surface(self, points_world: np.ndarray) -> np.ndarray:
        """(N,) bool: `surface_distance(points) <= ghost_dist_m`, exactly: a point sharing a
        cell of side ghost_dist/2 with a surface sample (in either of two grids offset by half
        a cell) passes unasked; the rest are asked with a search cut short past that distance
        (the tree keeps neighbours strictly nearer than its bound, so the bound sits a hair
        above the threshold)."""
        limit = self.ev.ghost_dist_m
        pts = np.asarray(points_world, np.float64).reshape(-1, 3)
        near = np.zeros(len(pts), bool)
        for shift, cells in zip((0.0, limit / 4), self.surface_cells, strict=True):
            ask = ~near
            near[ask] = in_sorted(voxels.pack(voxels.voxel_indices(pts[ask] + shift, limit / 2)),
                                  cells)
        if not near.all():
            dist, _ = self.surface_tree.query(pts[~near],
                                              distance_upper_bound=limit * (1 + 1e-9))
            near[~near] = dist <= limit
        return near

    @property
    def surface_cells(self) -> tuple[np.ndarray, np.ndarray]:
        """Sorted keys of the cells of side ghost_dist/2 that hold a surface sample, in the
        grid and in the grid offset by half a cell: every point of such a cell lies within
        0.87·ghost_dist of the sample, so passes the ghost test unasked."""
        if self._surface_cells is None:
            limit, surface = self.ev.ghost_dist_m, self.gt.surface_points_world
            self._surface_cells = tuple(
                unique_sorted(voxels.pack(voxels.voxel_indices(surface + shift, limit / 2)))
                for shift in (0.0, limit / 4))
        return self._surface_cells

    def ghost_point_mask(
        self, points_world: np.ndarray, dist: np.ndarray
    ) -> tuple[np.ndarray, int, int]:
        """(per-point ghost mask, ghost voxels, occupied voxels): a voxel is a ghost when
        every one of its points lies > ghost_dist from every static surface point."""
        if len(points_world) == 0:
            return np.zeros(0, dtype=bool), 0, 0
        keys = voxels.pack(voxels.voxel_indices(points_world, self.ev.voxel_m))
        uniq, inverse = np.unique(keys, return_inverse=True)
        near = np.zeros(len(uniq), dtype=bool)
        near[inverse[dist <= self.ev.ghost_dist_m]] = True  # one near point clears the voxel
        return ~near[inverse], int((~near).sum()), len(uniq)

    def covered(self, points_world: np.ndarray) -> np.ndarray:
        """(N_observable,) bool: observable truth points with a map point within radius."""
        return mx.covered_mask(
            points_world, self.gt.observable_points_world, self.ev.coverage_radius_m
        )

    def coverage_2d(self, grid: m.OccupancyGrid | None) -> float | None:
        """`metrics.coverage_2d` of a grid; the free truth cells' places in it are kept
        while its geometry stays the same (the live series asks every sample)."""
        if grid is None:
            return None
        spec = grid_spec(grid)
        if self._free_cells is None or self._free_cells[0] != spec:
            fg = self.gt.free_grid
            rc = spec.cell_of(fg.spec.centre_of(np.argwhere(fg.free)))
            self._free_cells = (spec, rc[spec.contains(rc)], int(np.count_nonzero(fg.free)))
        _, rc, free = self._free_cells
        known = np.count_nonzero(grid.cells[rc[:, 0], rc[:, 1]] >= 0)
        return 100.0 * float(known) / float(free) if free else 0.0

    def overlap_3d(self, robot_points: Sequence[np.ndarray] | None) -> float | None:
        """`metrics.overlap_3d` of the robots' own maps on the observable truth (None
        without them); the time series and metrics.json both take it from here."""
        if not robot_points:
            return None
        return mx.overlap_3d(robot_points, self.gt.observable_points_world,
                             self.ev.coverage_radius_m)

    def overlap_2d(self, grids: Sequence[m.OccupancyGrid] | None) -> float | None:
        if not grids:
            return None
        fg = self.gt.free_grid
        return mx.overlap_2d([(g.cells >= 0, grid_spec(g)) for g in grids], fg.free, fg.spec)


def maps_digest(points_world: np.ndarray, robot_points: Sequence[np.ndarray] | None) -> bytes:
    """A digest of a map and the robots' own maps by their float64 coordinates (a float32
    cloud and its float64 PLY copy give the same one)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(b"robots %d" % len(robot_points) if robot_points else b"no robots")
    for a in (points_world, *(robot_points or ())):
        a = np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(-1, 3))
        h.update(len(a).to_bytes(8, "little"))
        h.update(a.tobytes())
    return h.digest()


def map_quality(
    probe: Probe, points_world: np.ndarray, robot_points: Sequence[np.ndarray] | None
) -> dict[str, float | None]:
    """3D coverage (ghost points excluded), RMSE, BV and ghost volume of one map, and the 3D
    overlap of `robot_points`, each robot's own map (None: no overlap). The same maps as the
    probe's last call give its figures again without scoring them."""
    key = maps_digest(points_world, robot_points)
    memo = probe._quality_memo
    if memo is not None and memo[0] == key:
        return dict(memo[1])
    quality = _map_quality(probe, points_world, robot_points)
    probe._quality_memo = (key, dict(quality))
    return quality


def _map_quality(
    probe: Probe, points_world: np.ndarray, robot_points: Sequence[np.ndarray] | None
) -> dict[str, float | None]:
    pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    dist = probe.surface_distance(pts)
    ghost, n_ghost, n_occupied = probe.ghost_point_mask(pts, dist)
    total = len(probe.gt.observable_points_world)
    cov = 100.0 * probe.covered(pts[~ghost]).sum() / total if total else 0.0
    return {
        "coverage_3d_pct": float(cov),
        "overlap_3d_pct": probe.overlap_3d(robot_points),
        "rmse_3d_cm": float(np.sqrt(np.mean(dist**2)) * 100.0) if len(pts) else None,
        "bounding_volume_pct": 100.0 * n_ghost / n_occupied if n_occupied else 0.0,
        "ghost_volume_m3": n_ghost * probe.ev.voxel_m**3,
    }


def coverage_in_sight(probe: Probe, points_world: np.ndarray) -> float:
    """`coverage_3d_pct` against every truth point some viewpoint sees, whatever the camera's
    incidence limit (the observable truth before that limit counted): ghosts excluded alike."""
    pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    in_sight = probe.gt.surface_points_world[probe.gt.in_sight]
    if len(in_sight) == 0:
        return 0.0
    near = probe.near_surface(pts)
    ghost, _, _ = probe.ghost_point_mask(pts, np.where(near, 0.0, np.inf))
    covered = mx.covered_mask(pts[~ghost], in_sight, probe.ev.coverage_radius_m)
    return 100.0 * float(covered.sum()) / len(in_sight)


def distance_at(
    times_s: np.ndarray, tracks: Sequence[tuple[np.ndarray, np.ndarray]]
) -> list[float]:
    """Summed ground-truth path length of all robots up to each time in `times_s`.

    tracks: (stamps_s (T,), xy (T, 2)) per robot."""
    out = np.zeros(len(times_s))
    for stamps, xy in tracks:
        if len(xy) < 2:
            continue
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
        idx = np.searchsorted(stamps, np.asarray(times_s) + 1e-9, side="right") - 1
        out += np.where(idx >= 0, cum[np.clip(idx, 0, None)], 0.0)
    return [float(v) for v in out]


def score(
    probe: Probe,
    merged_points_world: np.ndarray,
    robot_points: Sequence[np.ndarray] | None,
    merged_grid: m.OccupancyGrid | None,
    robot_grids: Sequence[m.OccupancyGrid] | None,
    tracks: Sequence[tuple[np.ndarray, np.ndarray]],
    est_tracks: Sequence[tuple[np.ndarray, np.ndarray]],
    series: Sequence[dict[str, Any]],
    live: dict[str, Any],
    identity: dict[str, Any],
) -> dict[str, Any]:
    """Every SPEC §7 key. `tracks` / `est_tracks`: (stamps_s, xy) of each robot's ground-truth
    and estimated trajectory; `series` rows need sim_time_s and coverage_3d_pct (T90/T99);
    `live` holds LIVE_KEYS and sample_every_s (0: no T90/T99); `identity` holds robots,
    world, planner, drf, seed."""
    quality = map_quality(probe, merged_points_world, robot_points)
    ate = [mx.ate_rmse_cm(t_gt, xy_gt, t_est, xy_est)
           for (t_gt, xy_gt), (t_est, xy_est) in zip(tracks, est_tracks, strict=True)]
    t90_s, t99_s = mx.coverage_times(series, live.get("sample_every_s"))
    return mx.assemble_metrics(
        coverage_3d_pct=quality["coverage_3d_pct"],
        coverage_3d_in_sight_pct=coverage_in_sight(probe, merged_points_world),
        coverage_2d_pct=probe.coverage_2d(merged_grid),
        overlap_3d_pct=quality["overlap_3d_pct"],
        overlap_2d_pct=probe.overlap_2d(robot_grids),
        rmse_3d_cm=quality["rmse_3d_cm"],
        bounding_volume_pct=quality["bounding_volume_pct"],
        t90_s=t90_s,
        t99_s=t99_s,
        total_distance_m=sum(mx.path_length(xy) for _, xy in tracks),
        ate_rmse_cm=mx.mean_ate_cm(ate),
        ate_rmse_cm_per_robot=ate,
        **{k: live.get(k) for k in LIVE_KEYS},
        **identity,
    )
