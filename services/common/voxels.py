"""Voxel hashing: integer voxel keys packed into one int64, and voxel downsampling.

Packing keys into one int64 and using np.unique beats open3d's voxel_down_sample here
(field notes: 19 ms vs 41 ms at 200k points).
"""

from __future__ import annotations

import numpy as np

from services.common.arrays import unique_groups

_BITS = 21
_OFFSET = 1 << (_BITS - 1)
_MASK = (1 << _BITS) - 1


def voxel_indices(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """(N, 3) int64 voxel indices of (N, 3) points (voxel i covers [i·v, (i+1)·v))."""
    return np.floor(np.asarray(points, dtype=np.float64) / voxel_m).astype(np.int64)


def pack(indices: np.ndarray) -> np.ndarray:
    """(N, 3) int64 indices → (N,) int64 keys; each index must lie in ±2^20."""
    shifted = indices + _OFFSET
    if shifted.size and (shifted.min() < 0 or shifted.max() > _MASK):
        raise ValueError("voxel index out of the packable range ±2^20")
    return (shifted[:, 0] << (2 * _BITS)) | (shifted[:, 1] << _BITS) | shifted[:, 2]


def z_of(keys: np.ndarray) -> np.ndarray:
    """(N,) int64 z index of each key (= unpack(keys)[:, 2], without the other two)."""
    return (np.asarray(keys, dtype=np.int64) & _MASK) - _OFFSET


def xy_of(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) int64 x and y indices of each key (unpack's first two columns, without z)."""
    keys = np.asarray(keys, dtype=np.int64)
    return ((keys >> (2 * _BITS)) & _MASK) - _OFFSET, ((keys >> _BITS) & _MASK) - _OFFSET


def unpack(keys: np.ndarray) -> np.ndarray:
    """(N,) int64 keys → (N, 3) int64 indices."""
    keys = np.asarray(keys, dtype=np.int64)
    out = np.stack([(keys >> (2 * _BITS)) & _MASK, (keys >> _BITS) & _MASK, keys & _MASK], axis=1)
    return out - _OFFSET


def centres(indices: np.ndarray, voxel_m: float) -> np.ndarray:
    """(N, 3) float64 centres of voxels with the given indices."""
    return (indices.astype(np.float64) + 0.5) * voxel_m


def offset_codes(
    indices: np.ndarray, points: np.ndarray, voxel_m: float, levels: int
) -> np.ndarray:
    """(N,) uint8 cell (i, j, k) of an L×L×L split of each voxel that holds its point, coded
    (i·L + j)·L + k (L = `levels` ≤ 6); a point outside its voxel is clamped to it."""
    if not 1 <= levels <= 6:
        raise ValueError(f"levels must be 1..6, got {levels}")
    frac = np.asarray(points, np.float64) / voxel_m - indices
    ijk = np.clip(np.floor(frac * levels), 0, levels - 1).astype(np.int64)
    return ((ijk[:, 0] * levels + ijk[:, 1]) * levels + ijk[:, 2]).astype(np.uint8)


def offset_points(
    indices: np.ndarray, codes: np.ndarray, voxel_m: float, levels: int
) -> np.ndarray:
    """(N, 3) float64 centres of the coded cells (`offset_codes`' inverse, within a cell)."""
    codes = np.asarray(codes, np.int64)
    ijk = np.stack([codes // (levels * levels), (codes // levels) % levels, codes % levels], 1)
    return (indices + (ijk + 0.5) / levels) * voxel_m


def downsample(
    points: np.ndarray, voxel_m: float, colors: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """Average points (and colours) per voxel.

    Returns (keys (M,) int64 sorted, mean points (M, 3) float64, mean colours (M, 3) uint8 or
    None, counts (M,) int64).
    """
    keys = pack(voxel_indices(points, voxel_m))
    uniq, _, inverse, counts = unique_groups(keys)
    mean = np.stack(
        [np.bincount(inverse, weights=points[:, d], minlength=uniq.size) for d in range(3)], 1
    ) / counts[:, None]
    mean_colors = None
    if colors is not None:
        mean_colors = (
            np.stack(
                [np.bincount(inverse, weights=colors[:, d], minlength=uniq.size) for d in range(3)],
                1,
            )
            / counts[:, None]
        ).round().astype(np.uint8)
    return uniq, mean, mean_colors, counts
