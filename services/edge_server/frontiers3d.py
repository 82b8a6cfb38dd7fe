"""Bi-variate spatial frontier detection (the paper's Alg. 1), exact and vectorized.

After the voxel downsample (ϱ) every point of P*_d is a voxel centre on one integer lattice, so
the neighbours of a point within r_s are exactly the occupied lattice cells at a fixed set of
integer offsets (the ball stencil, K offsets). For every point we need ρ = Σ occ, Σ occ·o and
Σ occ·|o|² over its stencil: small integers, computed exactly either from per-(x, y)-column
bit masks and lookup tables (`ball_sums.py`, r_s ≤ 3 voxels, the configured case) or, for any
stencil, by gathering the K stencil cells of every point from a dense occupancy array and one
small matrix product (`gather_sums`). The neighbourhood variance (mean squared distance to the
neighbourhood mean, Alg. 1 line 7) is then ϱ²·(Σ|o|²/ρ − |Σo/ρ|²): exact, no per-point Python
loop, no KD-tree. ρ includes the point itself (‖p_i − p_i‖ ≤ r_s).

Regions, goals and gains are built from these masks in `spatial_frontiers.py`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.arrays import unique_sorted
from services.common.voxels import pack, unpack, voxel_indices
from services.edge_server.ball_sums import ball_sums, fits

CHUNK = 1024  # points per gather block: keeps the K×chunk block in cache


def ball_offsets(radius_vox: float) -> np.ndarray:
    """(K, 3) int64 lattice offsets o with |o| ≤ radius (in voxels), sorted, zero included."""
    r = int(np.floor(radius_vox + 1e-9))
    g = np.mgrid[-r : r + 1, -r : r + 1, -r : r + 1].reshape(3, -1).T
    return g[(g**2).sum(axis=1) <= radius_vox**2 + 1e-9].astype(np.int64)


def full_ball_variance(offsets: np.ndarray) -> float:
    """Variance (voxel²) of a fully occupied stencil: the normaliser of σ² for the entropy."""
    o = offsets.astype(np.float64)
    return float(((o - o.mean(axis=0)) ** 2).sum(axis=1).mean())


def gather_sums(indices: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(5, N) int64 [ρ, Σo, Σ|o|²] by gathering all K stencil cells of every voxel: any
    stencil; the reference `ball_sums` is checked against
    (tests/test_edge_frontier_ball_sums.py)."""
    n = indices.shape[0]
    pad = int(np.abs(offsets).max())
    lo = indices.min(axis=0) - pad
    dims = indices.max(axis=0) - lo + pad + 1
    strides = np.array([dims[1] * dims[2], dims[2], 1], np.int64)
    flat = (indices - lo) @ strides
    occ = np.zeros(int(np.prod(dims)), np.uint8)
    occ[flat] = 1
    off_flat = offsets @ strides
    # rows: 1, ox, oy, oz, |o|² → one product gives ρ, Σo, Σ|o|² for a block of points
    A = np.concatenate([np.ones((1, len(offsets))), offsets.T, (offsets**2).sum(1)[None]])
    A = A.astype(np.float32)
    sums = np.empty((5, n), np.float32)
    for s in range(0, n, CHUNK):
        block = flat[s : s + CHUNK]
        gathered = np.take(occ, off_flat[:, None] + block[None, :]).astype(np.float32)
        # c_einsum, not BLAS: a multi-threaded BLAS on a busy 2-core machine is 10-50× slower
        sums[:, s : s + CHUNK] = np.einsum("wk,kn->wn", A, gathered, optimize=False)
    return sums.astype(np.int64)  # small integers: exact in float32


def density_variance(indices: np.ndarray, radius_vox: float) -> tuple[np.ndarray, np.ndarray]:
    """ρ (N,) int counts and σ² (N,) float64 in voxel² for unique (N, 3) lattice indices."""
    n = indices.shape[0]
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    offsets = ball_offsets(radius_vox)
    # column bit masks for r_s ≤ 3 voxels: same integers, ~2× less time on the house map
    sums = ball_sums(indices, offsets) if fits(offsets) else gather_sums(indices, offsets)
    rho = sums[0]
    mean = sums[1:4].astype(np.float64) / rho
    var = sums[4].astype(np.float64) / rho - (mean**2).sum(axis=0)
    return rho, np.maximum(var, 0.0)


@dataclass(frozen=True)
class PointFrontiers:
    """Alg. 1 output on P*_d: lattice indices, ρ, σ² (m²) and the F_u / F_w masks."""

    indices: np.ndarray  # (N, 3) int64 voxel indices of P*_d
    points_world: np.ndarray  # (N, 3) voxel centres
    rho: np.ndarray  # (N,) neighbour counts within r_s (self included)
    var_m2: np.ndarray  # (N,) neighbourhood variance, m²
    unexplored: np.ndarray  # (N,) bool, ρ < δ_d
    weak: np.ndarray  # (N,) bool, σ² > δ_v
    full_count: int  # K: ρ of a point inside a solid ball (normaliser of ρ)
    full_var_m2: float  # σ² of a solid ball (normaliser of σ²)


def detect_point_frontiers(
    points_world: np.ndarray, voxel_m: float, radius_m: float, delta_d: float, delta_v_m2: float
) -> PointFrontiers:
    """Alg. 1: downsample at ϱ = voxel_m, ρ and σ² within r_s, F_u = ρ < δ_d, F_w = σ² > δ_v."""
    points_world = np.asarray(points_world, np.float64).reshape(-1, 3)
    keys = unique_sorted(pack(voxel_indices(points_world, voxel_m)))
    return lattice_frontiers(unpack(keys), voxel_m, radius_m, delta_d, delta_v_m2)


def lattice_frontiers(
    idx: np.ndarray, voxel_m: float, radius_m: float, delta_d: float, delta_v_m2: float
) -> PointFrontiers:
    """Alg. 1 on an already downsampled cloud given as unique (N, 3) voxel indices at ϱ."""
    radius_vox = radius_m / voxel_m
    rho, var_vox = density_variance(idx, radius_vox)
    var_m2 = var_vox * voxel_m**2
    offsets = ball_offsets(radius_vox)
    return PointFrontiers(
        indices=idx, points_world=(idx + 0.5) * voxel_m, rho=rho, var_m2=var_m2,
        unexplored=rho < delta_d, weak=var_m2 > delta_v_m2, full_count=len(offsets),
        full_var_m2=full_ball_variance(offsets) * voxel_m**2,
    )


def neg_x_log_x(x: np.ndarray) -> np.ndarray:
    """−x log x on [0, 1] (0 at x = 0): the paper's non-probabilistic Shannon entropy."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    out = np.zeros_like(x)
    pos = x > 0
    out[pos] = -x[pos] * np.log(x[pos])
    return out


def point_entropy(pf: PointFrontiers, weak: bool, sel: np.ndarray | None = None) -> np.ndarray:
    """(N,) −ρ̂ log ρ̂ (ρ̂ = ρ / K) or −σ̂² log σ̂² (σ̂² = σ² / σ²_ball): both in [0, 1/e];
    of the voxels `sel` only when given (elementwise: the same values)."""
    pick = slice(None) if sel is None else sel
    if weak:
        return neg_x_log_x(pf.var_m2[pick] / pf.full_var_m2)
    return neg_x_log_x(pf.rho[pick] / pf.full_count)
