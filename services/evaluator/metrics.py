"""SPEC §5 metrics as pure functions on arrays, and the metrics.json record (SPEC §7).

Percentages are 0-100. 2D masks live on world-aligned grids (services.common.grid.GridSpec);
grids of different origins are compared at the truth grid's cell centres.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from services.common import voxels
from services.common.arrays import in_sorted, unique_sorted
from services.common.grid import GridSpec

METRICS_KEYS = (
    "coverage_3d_pct", "coverage_3d_in_sight_pct", "coverage_2d_pct", "overlap_3d_pct",
    "overlap_2d_pct", "rmse_3d_cm",
    "bounding_volume_pct", "mapping_time_s", "t90_s", "t99_s", "total_distance_m",
    "bytes_per_robot", "ate_rmse_cm", "ate_rmse_cm_per_robot", "sim_time_s", "wall_time_s",
    "robots", "world", "planner", "drf", "merge", "seed", "completed",
)


def _pct(part: int | float, whole: int | float) -> float:
    return 100.0 * float(part) / float(whole) if whole else 0.0


def _points(points: np.ndarray) -> np.ndarray:
    return np.asarray(points, dtype=np.float64).reshape(-1, 3)


def covered_mask(
    map_points_world: np.ndarray, gt_points: np.ndarray, radius_m: float
) -> np.ndarray:
    """(N_gt,) bool: a map point lies within radius of each ground-truth point (strictly
    nearer than radius, as the KD-tree's bound has it).

    A truth point that shares a cell of side radius/2 with a map point (in the grid or in the
    grid offset by a quarter radius) is covered unasked: the two lie within 0.87·radius.
    Only the rest go to the KD-tree, which gives the same mask as asking them all."""
    map_points_world, gt_points = _points(map_points_world), _points(gt_points)
    if len(map_points_world) == 0:
        return np.zeros(len(gt_points), dtype=bool)
    covered = np.zeros(len(gt_points), dtype=bool)
    side = radius_m / 2
    for shift in (0.0, side / 2):
        cells = unique_sorted(voxels.pack(voxels.voxel_indices(map_points_world + shift, side)))
        ask = ~covered
        covered[ask] = in_sorted(voxels.pack(voxels.voxel_indices(gt_points[ask] + shift, side)),
                                 cells)
    ask = ~covered
    if ask.any():
        dist, _ = cKDTree(map_points_world).query(gt_points[ask], distance_upper_bound=radius_m)
        covered[ask] = np.isfinite(dist)
    return covered


def coverage_3d(
    map_points_world: np.ndarray, gt_points: np.ndarray, radius_m: float = 0.10,
    ghost_mask: np.ndarray | None = None,
) -> float:
    """% of (observable) ground-truth points with a non-ghost map point within radius."""
    pts = _points(map_points_world)
    if ghost_mask is not None:
        pts = pts[~np.asarray(ghost_mask, dtype=bool)]
    return _pct(covered_mask(pts, gt_points, radius_m).sum(), len(_points(gt_points)))


def overlap_pct(covered_by_robot: Sequence[np.ndarray]) -> float:
    """The one overlap definition, the paper's "% of the map covered more than once": of the
    ground truth (points or cells) that any robot's own map covers, the % that two or more
    robots' maps cover. One bool mask per robot over the same truth; 0 when none is covered.

    Own maps, not a merged map split by first observer: a merged voxel seen by two robots
    belongs to one of them there, which undercounts the overlap."""
    counts = np.sum([np.asarray(c, dtype=bool) for c in covered_by_robot], axis=0,
                    dtype=np.int32)
    return _pct(np.count_nonzero(counts >= 2), np.count_nonzero(counts >= 1))


def overlap_3d(
    per_robot_points_world: Sequence[np.ndarray], gt_points: np.ndarray, radius_m: float = 0.10
) -> float:
    """`overlap_pct` over ground-truth points: covered = a robot's point within radius."""
    return overlap_pct([covered_mask(p, gt_points, radius_m) for p in per_robot_points_world])


def resample_mask(mask: np.ndarray, src: GridSpec, dst: GridSpec) -> np.ndarray:
    """Mask on grid src looked up at grid dst's cell centres (False outside src)."""
    rows, cols = np.indices(dst.shape)
    rc = src.cell_of(dst.centre_of(np.stack([rows.ravel(), cols.ravel()], 1)))
    inside = src.contains(rc)
    out = np.zeros(dst.height * dst.width, dtype=bool)
    out[inside] = np.asarray(mask, dtype=bool)[rc[inside, 0], rc[inside, 1]]
    return out.reshape(dst.shape)


def coverage_2d(
    known_mask: np.ndarray, known_spec: GridSpec, truth_free: np.ndarray, truth_spec: GridSpec
) -> float:
    """% of reachable free truth cells that the map knows (free or occupied)."""
    known = resample_mask(known_mask, known_spec, truth_spec)
    return _pct((known & truth_free).sum(), np.count_nonzero(truth_free))


def overlap_2d(
    per_robot_known: Sequence[tuple[np.ndarray, GridSpec]], truth_free: np.ndarray,
    truth_spec: GridSpec,
) -> float:
    """`overlap_pct` over reachable free truth cells: covered = known to a robot's grid."""
    return overlap_pct([resample_mask(mask, spec, truth_spec) & truth_free
                        for mask, spec in per_robot_known])


def rmse_3d_cm(map_points_world: np.ndarray, gt_points: np.ndarray) -> float | None:
    """RMS distance (cm) from every map point to its nearest ground-truth surface point.

    The floor of this figure is the sampling error: at 1000 pts/m², ≈ √(1/(π·1000)) = 1.8 cm
    for points lying exactly on the surface.
    """
    pts = _points(map_points_world)
    if len(pts) == 0:
        return None
    dist, _ = cKDTree(_points(gt_points)).query(pts)
    return float(np.sqrt(np.mean(dist**2)) * 100.0)


def ghost_voxels(
    map_points_world: np.ndarray, static_surface_points: np.ndarray, voxel_m: float = 0.05,
    ghost_dist_m: float = 0.10,
) -> tuple[np.ndarray, np.ndarray]:
    """(keys of occupied voxels, bool ghost per voxel): every point of a ghost voxel lies
    more than ghost_dist from every static surface point."""
    pts = _points(map_points_world)
    keys = voxels.pack(voxels.voxel_indices(pts, voxel_m))
    uniq, inverse = np.unique(keys, return_inverse=True)
    dist, _ = cKDTree(_points(static_surface_points)).query(
        pts, distance_upper_bound=ghost_dist_m
    )
    near = np.zeros(len(uniq), dtype=bool)
    near[inverse[np.isfinite(dist)]] = True  # one point near a surface clears the voxel
    return uniq, ~near


def bounding_volume_pct(
    map_points_world: np.ndarray, static_surface_points: np.ndarray, voxel_m: float = 0.05,
    ghost_dist_m: float = 0.10,
) -> float:
    """Ghost voxel volume as % of all occupied voxel volume (all voxels are equal)."""
    if len(_points(map_points_world)) == 0:
        return 0.0
    uniq, ghost = ghost_voxels(map_points_world, static_surface_points, voxel_m, ghost_dist_m)
    return _pct(ghost.sum(), len(uniq))


def path_length(trajectory_xy: np.ndarray) -> float:
    """Length (m) of a (T, 2) or (T, 3) polyline."""
    traj = np.asarray(trajectory_xy, dtype=np.float64)
    return float(np.linalg.norm(np.diff(traj, axis=0), axis=1).sum()) if len(traj) > 1 else 0.0


# evo's default association window (`evo_ape --t_max_diff`); a tick is 0.1 s, so at most one
# pose of the other trajectory lies this close
ASSOCIATE_MAX_DIFF_S = 0.01


def associate_stamps(
    stamps_ref: np.ndarray, stamps_est: np.ndarray, max_diff_s: float = ASSOCIATE_MAX_DIFF_S
) -> tuple[np.ndarray, np.ndarray]:
    """(ref indices, est indices) of poses at matching times, exactly as evo's nearest-time
    sync (`evo.core.sync.associate_trajectories(ref, est)`) pairs them: every pose of the
    trajectory with fewer poses (est on a tie) takes the nearest stamp of the other within
    max_diff_s, the earlier one on a tie, or is dropped; a pose of the longer one may serve
    twice. Like evo, a repeated stamp pairs with its last copy, except when the longer
    trajectory's stamps are out of order (never so in a run folder): then evo's linear search,
    which takes the first nearest stamp in file order."""
    ref = np.asarray(stamps_ref, dtype=np.float64).ravel()
    est = np.asarray(stamps_est, dtype=np.float64).ravel()
    if len(ref) == 0 or len(est) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    est_longer = len(est) > len(ref)
    short, long = (ref, est) if est_longer else (est, ref)
    if np.any(np.diff(long) < 0):
        i_short, i_long = _nearest_linear(short, long, max_diff_s)
        return (i_short, i_long) if est_longer else (i_long, i_short)
    # the same float operations as evo's binary search, so borderline stamps match alike
    idx = np.minimum(np.searchsorted(long, short, side="right"), len(long) - 1)
    diff_ub = long[idx] - short
    diff_lb = np.where(idx > 0, short - long[idx - 1], np.inf)
    take_ub = (diff_ub <= max_diff_s) & (diff_ub < diff_lb)
    take_lb = ~take_ub & (diff_lb <= max_diff_s) & (diff_lb <= diff_ub)
    in_range = (short >= long[0] - max_diff_s) & (short <= long[-1] + max_diff_s)
    keep = in_range & (take_ub | take_lb)
    i_short = np.flatnonzero(keep)
    i_long = np.where(take_ub, idx, idx - 1)[keep]
    return (i_short, i_long) if est_longer else (i_long, i_short)


def _nearest_linear(
    short: np.ndarray, long: np.ndarray, max_diff_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """evo's fallback for unsorted stamps: argmin of |long - s| for each s, in row chunks."""
    rows = max(1, 4_000_000 // len(long))  # bounds the (rows, len(long)) distance matrix
    i_short, i_long = [], []
    for start in range(0, len(short), rows):
        diff = np.abs(long[None, :] - short[start:start + rows, None])
        best = np.argmin(diff, axis=1)
        ok = np.flatnonzero(diff[np.arange(len(best)), best] <= max_diff_s)
        i_short.append(start + ok)
        i_long.append(best[ok])
    return np.concatenate(i_short), np.concatenate(i_long)


def ate_rmse_cm(
    stamps_gt: np.ndarray, positions_gt: np.ndarray, stamps_est: np.ndarray,
    positions_est: np.ndarray, max_diff_s: float = ASSOCIATE_MAX_DIFF_S,
) -> float | None:
    """Absolute trajectory error (cm): RMS of the position error over the associated poses,
    translation only and without alignment (start poses are known, estimates are in the world
    frame); `evo_ape tum GT EST` × 100. None when no pose pairs up.

    positions: (T, 2) or (T, 3) world coordinates, the same dimension on both sides."""
    i_gt, i_est = associate_stamps(stamps_gt, stamps_est, max_diff_s)
    if len(i_gt) == 0:
        return None
    gt = np.asarray(positions_gt, dtype=np.float64)[i_gt]
    est = np.asarray(positions_est, dtype=np.float64)[i_est]
    error = np.linalg.norm(est - gt, axis=1)
    return float(np.sqrt(np.mean(error**2)) * 100.0)


def mean_ate_cm(per_robot_cm: Sequence[float | None]) -> float | None:
    """Mean over the robots that have an ATE (a robot without estimated poses has none)."""
    values = [v for v in per_robot_cm if v is not None]
    return float(np.mean(values)) if values else None


def t_at_coverage(times_s: np.ndarray, coverage_pct: np.ndarray, pct: float) -> float | None:
    """First time coverage reaches pct (T90: pct=90), or None if it never does."""
    reached = np.flatnonzero(np.asarray(coverage_pct) >= pct)
    return float(np.asarray(times_s)[reached[0]]) if len(reached) else None


def coverage_times(series: Sequence[dict[str, Any]], sample_every_s: float | None
                   ) -> tuple[float | None, float | None]:
    """(T90, T99) from the time series' rows (sim_time_s, coverage_3d_pct). None for both
    when the mission was not sampled (`sample_every_s` 0): the series then holds only the
    final row, and the mapping time is no T90. `sample_every_s` None: a run folder from
    before the launcher wrote it, taken as sampled."""
    if sample_every_s is not None and sample_every_s <= 0:
        return None, None
    times = np.array([r["sim_time_s"] for r in series], dtype=np.float64)
    cov = np.array([r["coverage_3d_pct"] for r in series], dtype=np.float64)
    return t_at_coverage(times, cov, 90.0), t_at_coverage(times, cov, 99.0)


def assemble_metrics(**values: Any) -> dict[str, Any]:
    """The metrics.json record: exactly METRICS_KEYS, missing ones None; unknown keys refused."""
    unknown = set(values) - set(METRICS_KEYS)
    if unknown:
        raise KeyError(f"not metrics.json keys: {sorted(unknown)}")
    out = {}
    for key in METRICS_KEYS:
        value = values.get(key)
        if isinstance(value, np.generic):
            value = value.item()  # JSON-serialisable scalars
        out[key] = value
    return out
