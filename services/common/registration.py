"""Pairwise submap registration (small_gicp GICP) and the candidate pairs worth registering.

A pair is a candidate when the two submaps belong to different robots and their world boxes
(at the current estimates) overlap by at least `min_overlap_m3`. GICP starts from the current
relative estimate; a result is kept only when it converged, enough source points found a
partner and it moved the estimate less than a gate (a registration that wanders far is more
likely a wrong basin than a correction). Two optional gates judge the fit itself: the GICP
residual per inlier (a registration 5-10 cm off leaves surfaces apart that its inliers still
pair) and the planar condition (strongest over weakest translational information in the
plane: shelves and aisles that repeat slide along themselves), and the faces it pairs: each
point's surface normal turned toward where its submap was seen from, a registration whose
pairs are too often back to back has matched the two faces of one thin wall (robots on
either side of a partition see faces 10 cm apart, and GICP lays one on the other).
small_gicp's Hessian H is already in GTSAM's convention (rotation first, right perturbation
of T_target_source); its absolute scale depends on point count and covariances, so it is
rescaled to a mean translational σ of `sigma_m` before the robust kernels judge residuals
(field notes), keeping its shape (weak directions of a corridor stay weak).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import small_gicp
from gtsam import Pose3

# ruff: noqa: N806 (T_a_b names)


@dataclass(frozen=True)
class RegistrationParams:
    downsample_m: float = 0.15
    max_corr_m: float = 0.5
    fine_downsample_m: float = 0.1
    fine_corr_m: float = 0.12
    neighbors: int = 10
    max_iterations: int = 30
    min_inlier_frac: float = 0.5
    max_shift_m: float = 0.5
    max_turn_rad: float = 0.2
    sigma_m: float = 0.01
    max_mean_error: float = float("inf")  # GICP residual per inlier (small_gicp's `error`)
    max_planar_condition: float = float("inf")  # strongest / weakest planar translation info
    max_opposed_frac: float = 1.0  # of the flat pairs, back to back at most this share (1: off)
    viewpoint_m: tuple[float, float, float] = (0.0, 0.0, 0.35)  # the camera, submap frame


@dataclass(frozen=True)
class PairResult:
    T_target_source: np.ndarray
    info: np.ndarray  # (6, 6) GTSAM convention, scaled
    inlier_frac: float


def world_box(box_submap: np.ndarray, T_world_submap: np.ndarray) -> np.ndarray:
    """(2, 3) axis-aligned world box of a submap's (2, 3) own box (its corners, moved)."""
    return world_boxes(box_submap[None], T_world_submap[None])[0]


_CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])


def world_boxes(boxes_submap: np.ndarray, T_world_submap: np.ndarray) -> np.ndarray:
    """(n, 2, 3) world boxes of n submaps' (n, 2, 3) own boxes under their (n, 4, 4) poses."""
    axes = np.arange(3)
    corners = boxes_submap[:, _CORNERS, axes]  # (n, 8, 3): lo or hi per axis
    world = corners @ np.swapaxes(T_world_submap[:, :3, :3], 1, 2) + T_world_submap[:, None, :3, 3]
    return np.stack([world.min(axis=1), world.max(axis=1)], axis=1)


def overlapping_pairs(boxes: np.ndarray, min_volume: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Index pairs i < j of (n, 2, 3) axis-aligned boxes that share at least `min_volume`
    (> 0), and the shared volumes. A sweep along the axis where the boxes meet least: time
    and memory follow the pairs that meet along it, not n² (a 24-robot mission holds
    thousands of submaps, and their n × n overlap table alone took gigabytes)."""
    if min_volume <= 0:
        raise ValueError("min_volume must be > 0 (boxes that do not meet share 0)")
    n = boxes.shape[0]
    best: tuple[int, np.ndarray, np.ndarray] | None = None
    for axis in range(3):
        order = np.argsort(boxes[:, 0, axis], kind="stable")
        lo, hi = boxes[order, 0, axis], boxes[order, 1, axis]
        # in lo order, box p meets only the later boxes whose lo lies below its hi
        counts = np.maximum(np.searchsorted(lo, hi, side="left") - np.arange(1, n + 1), 0)
        if best is None or counts.sum() < best[0]:
            best = (int(counts.sum()), order, counts)
    empty = np.zeros(0, np.int64)
    if best is None or best[0] == 0:
        return empty, empty, np.zeros(0)
    total, order, counts = best
    p = np.repeat(np.arange(n), counts)
    q = p + 1 + np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    a, b = order[p], order[q]
    i, j = np.minimum(a, b), np.maximum(a, b)
    side = (np.minimum(boxes[i, 1], boxes[j, 1]) - np.maximum(boxes[i, 0], boxes[j, 0]))
    volume = np.prod(np.maximum(side, 0.0), axis=1)
    keep = volume >= min_volume
    return i[keep], j[keep], volume[keep]


def planar_condition(H: np.ndarray) -> float:
    """Strongest over weakest eigenvalue of the x, y information of a GICP Hessian (rotation
    first), with z, roll, pitch and then yaw marginalised: how much worse a registration pins
    the weakest horizontal direction than the strongest (inf: one direction is free)."""
    H = 0.5 * (H + H.T)
    planar, rest = [3, 4, 2], [5, 0, 1]  # tx, ty, rz | tz, rx, ry
    A, B, C = H[np.ix_(planar, planar)], H[np.ix_(planar, rest)], H[np.ix_(rest, rest)]
    try:
        Hp = A - B @ np.linalg.solve(C, B.T)
    except np.linalg.LinAlgError:
        Hp = A
    Ht = Hp[:2, :2] - np.outer(Hp[:2, 2], Hp[2, :2]) / Hp[2, 2] if Hp[2, 2] > 0 else Hp[:2, :2]
    weakest, strongest = np.linalg.eigvalsh(Ht)
    return float(strongest / weakest) if weakest > 0 else float("inf")


def flat_normals(covs: np.ndarray, points: np.ndarray, viewpoint: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) unit normals (each neighbourhood's least-spread axis) turned toward
    `viewpoint`, and (N,) whether the neighbourhood is flat (least spread under a fifth of
    the middle one), of points with (N, 3, 3) neighbourhood covariances."""
    spread, axes = np.linalg.eigh(covs)
    normals = axes[:, :, 0]
    away = np.einsum("ij,ij->i", normals, viewpoint - points) < 0
    normals[away] *= -1.0
    return normals, spread[:, 0] < 0.2 * spread[:, 1]


def opposed_fraction(target: Prepared, source: Prepared, T_target_source: np.ndarray,
                     corr_m: float, viewpoint: np.ndarray) -> float:
    """Of the source's fine points within `corr_m` of a target point where both are flat,
    the share whose normals, each turned toward its own submap's viewpoint, are back to back
    (cosine < −0.5) among those that are parallel either way (|cosine| > 0.5)."""
    R, t = T_target_source[:3, :3], T_target_source[:3, 3]
    src_points, src_normals, src_flat = source.fine_normals(viewpoint)
    moved = src_points @ R.T + t
    found, sq_dist = target.fine[1].batch_nearest_neighbor_search(moved, num_threads=1)
    found, near = np.asarray(found), np.asarray(sq_dist) <= corr_m**2
    if not near.any():
        return 0.0
    j = found[near]
    _, tgt_normals, tgt_flat = target.fine_normals(viewpoint)
    n_src, flat_src = src_normals[near], src_flat[near]
    n_tgt, flat_tgt = tgt_normals[j], tgt_flat[j]
    cos = np.einsum("ij,ij->i", n_src @ R.T, n_tgt)[flat_src & flat_tgt]
    parallel, opposed = np.count_nonzero(cos > 0.5), np.count_nonzero(cos < -0.5)
    return opposed / max(parallel + opposed, 1)


def scaled_info(H: np.ndarray, sigma_m: float) -> np.ndarray:
    """H rescaled so its translational block has mean diagonal 1/σ²; symmetrised."""
    H = 0.5 * (H + H.T)
    scale = float(np.mean(np.diag(H)[3:]))
    return H / (scale * sigma_m**2) if scale > 0 else np.zeros((6, 6))


@dataclass(frozen=True)
class Prepared:
    """A submap cloud downsampled, with covariances and KD-tree, at both levels (reusable)."""

    coarse: tuple[small_gicp.PointCloud, small_gicp.KdTree]
    fine: tuple[small_gicp.PointCloud, small_gicp.KdTree]
    n_fine: int
    _normals: dict[tuple[float, ...], tuple[np.ndarray, np.ndarray, np.ndarray]] = field(
        default_factory=dict, compare=False, repr=False)

    def fine_normals(self, viewpoint: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(points (N, 3), normals (N, 3), flat (N,)) of the fine cloud, as `flat_normals`
        gives them, computed once per viewpoint: a submap is judged against many others, and
        each point's eigen-decomposition is its own, so rows taken from the whole cloud's
        are the rows a subset's call would give."""
        key = tuple(float(v) for v in viewpoint)
        if key not in self._normals:
            cloud = self.fine[0]
            points = np.asarray(cloud.points())[:, :3]
            self._normals[key] = (points, *flat_normals(
                np.asarray(cloud.covs())[:, :3, :3], points, np.asarray(viewpoint)))
        return self._normals[key]


def prepare(points_submap: np.ndarray, params: RegistrationParams) -> Prepared:
    points = np.asarray(points_submap, np.float64)
    coarse = small_gicp.preprocess_points(points, params.downsample_m,
                                          num_neighbors=params.neighbors)
    fine = small_gicp.preprocess_points(points, params.fine_downsample_m,
                                        num_neighbors=params.neighbors)
    return Prepared(coarse, fine, fine[0].size())


def register(
    target: Prepared, source: Prepared, T_target_source_init: np.ndarray,
    params: RegistrationParams,
) -> PairResult | None:
    """GICP of source onto target (each in its own submap frame); None when rejected.

    Coarse to fine: a wide correspondence radius pulls in from the drifted estimate, a tight
    one then stops points beyond the other submap's edge from biasing the result."""
    coarse = small_gicp.align(
        target.coarse[0], source.coarse[0], target.coarse[1], T_target_source_init,
        registration_type="GICP", max_correspondence_distance=params.max_corr_m,
        num_threads=1, max_iterations=params.max_iterations,
    )
    res = small_gicp.align(
        target.fine[0], source.fine[0], target.fine[1], coarse.T_target_source,
        registration_type="GICP", max_correspondence_distance=params.fine_corr_m,
        num_threads=1, max_iterations=params.max_iterations,
    )
    frac = res.num_inliers / max(source.n_fine, 1)
    step = Pose3.Logmap(Pose3(T_target_source_init).between(Pose3(res.T_target_source)))
    if (not res.converged or frac < params.min_inlier_frac
            or np.linalg.norm(step[3:]) > params.max_shift_m
            or np.linalg.norm(step[:3]) > params.max_turn_rad
            or res.error > params.max_mean_error * max(res.num_inliers, 1)
            or (params.max_planar_condition < float("inf")
                and planar_condition(res.H) > params.max_planar_condition)
            or (params.max_opposed_frac < 1.0
                and opposed_fraction(target, source, res.T_target_source, params.fine_corr_m,
                                     np.asarray(params.viewpoint_m)) > params.max_opposed_frac)):
        return None
    return PairResult(res.T_target_source.copy(), scaled_info(res.H, params.sigma_m), frac)
