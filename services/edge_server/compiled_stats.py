"""Alg. 1's per-voxel ρ and σ² from the packed lattice sums, compiled (numba): one pass.

`IncrementalFrontiers` reads the packed sums of every voxel of P* at each plan. In numpy that
is some thirty passes over the voxels (five bit fields unpacked, three means, their squares,
the variance, two thresholds): 20-30 ms a plan at 270k voxels, most of Alg. 1's cost once its
sums are kept incrementally. Here one loop does it per voxel, with the same float operations
in the same order, so every array is bit-identical to the numpy path
(tests/test_edge_frontier_cache.py):
- fields: ((v + half) & mask) − half, then v ← (v − field) >> bits, as `ball_sums.unpack_fields`;
- means Σo / ρ as float64 divisions, their squares summed x, y, then z, as numpy's reduction
  over the first axis of a (3, N) array;
- σ² = max(Σ|o|² / ρ − that sum, 0) · voxel², with numpy's `maximum` (a −0.0 becomes +0.0).

Imported lazily (numba's import and cache load cost about half a CPU-second once).
"""

from __future__ import annotations

import numba
import numpy as np

from services.edge_server.ball_sums import FIELD_BITS

_BITS = tuple(FIELD_BITS)


@numba.njit(cache=True, nogil=True)
def voxel_stats_into(
    sums: np.ndarray, flat: np.ndarray, voxel_m2: float, delta_d: float, delta_v_m2: float,
    rho: np.ndarray, var_m2: np.ndarray, unexplored: np.ndarray, weak: np.ndarray,
) -> None:
    """Fill ρ (int64), σ² (float64, m²) and the two masks of the voxels at box offsets `flat`
    (the packed sums `sums[flat]`)."""
    fields = np.empty(5, np.int64)
    for i in range(flat.size):
        v = sums[flat[i]]
        for j in range(5):
            bits = _BITS[j]
            half = np.int64(1) << (bits - 1)
            field = ((v + half) & ((np.int64(1) << bits) - 1)) - half
            fields[j] = field
            v = (v - field) >> bits
        r = fields[0]
        mx, my, mz = fields[1] / r, fields[2] / r, fields[3] / r
        var = fields[4] / r - ((mx * mx + my * my) + mz * mz)
        var = (var if var > 0.0 else 0.0) * voxel_m2
        rho[i] = r
        var_m2[i] = var
        unexplored[i] = r < delta_d
        weak[i] = var > delta_v_m2


def voxel_stats(sums: np.ndarray, flat: np.ndarray, voxel_m: float, delta_d: float,
                delta_v_m2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(ρ, σ² m², unexplored, weak) of the voxels at box offsets `flat`, each (N,)."""
    n = flat.size
    rho, var_m2 = np.empty(n, np.int64), np.empty(n, np.float64)
    unexplored, weak = np.empty(n, np.bool_), np.empty(n, np.bool_)
    voxel_stats_into(sums, np.ascontiguousarray(flat, np.int64), float(voxel_m**2),
                     float(delta_d), float(delta_v_m2), rho, var_m2, unexplored, weak)
    return rho, var_m2, unexplored, weak
