"""The points of a frame whose registration-map voxel the camera saw whole.

The registration map (`registrar.py`) is a Gaussian voxel map: each voxel keeps the mean and
covariance of the points that fell in it. A voxel the view's boundary cuts (the range's far
edge, the image's sides) holds only its inner part, so its mean sits back toward the robot,
and the next frame, which sees more of it, is pulled back. Along an aisle that bias adds up
frame after frame (bench/bench_aisle_lag.py; docs/agent.md, "Only voxels the view saw
whole"). Leaving out the points of the cut voxels, in the map's own grid, removes a layer one
voxel thick at the boundary: a later frame that sees the voxel whole brings it in.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from services.common.geometry import invert, transform_points

_CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
# voxel keys packed into one int64: 21 bits per axis, offset so negative indices stay positive
_BITS, _OFFSET = 21, 1 << 20


@dataclass(frozen=True)
class CameraView:
    """What a pinhole depth camera can return: in front of it, inside the image, in range."""

    K: np.ndarray  # (3, 3) intrinsics, pixels
    width: int  # image columns
    height: int  # image rows
    range_m: float  # largest depth (along the optical axis) with a return
    T_base_cam: np.ndarray  # (4, 4) optical frame (x right, y down, z forward) → base

    def contains(self, points_base: np.ndarray) -> np.ndarray:
        """(N,) whether each base-frame point lies inside the view (occlusion aside)."""
        p = transform_points(invert(self.T_base_cam), points_base)
        z = p[:, 2]
        ok = (z > 1e-6) & (z <= self.range_m)
        zs = np.where(ok, z, 1.0)
        u = self.K[0, 0] * p[:, 0] / zs + self.K[0, 2]
        v = self.K[1, 1] * p[:, 1] / zs + self.K[1, 2]
        # pixel centres run 0 … W−1: a corner beyond the outermost centres is not seen
        return ok & (u >= 0) & (u <= self.width - 1) & (v >= 0) & (v <= self.height - 1)


def whole_voxel_mask(points_base: np.ndarray, T_loc_base: np.ndarray, voxel_m: float,
                     inside: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """(N,) whether each base-frame point falls in a voxel of the `loc` grid (edge `voxel_m`,
    the registration map's) whose eight corners all lie inside the view, with the base at
    `T_loc_base` and `inside` the view's test on base-frame points."""
    if len(points_base) == 0:
        return np.zeros(0, bool)
    if voxel_m <= 0:
        raise ValueError(f"voxel_m must be > 0, got {voxel_m}")
    idx = np.floor(transform_points(T_loc_base, points_base) / voxel_m).astype(np.int64)
    keys = ((idx[:, 0] + _OFFSET) << (2 * _BITS)) | ((idx[:, 1] + _OFFSET) << _BITS) \
        | (idx[:, 2] + _OFFSET)
    unique_keys, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    corners_loc = (idx[first][:, None, :] + _CORNERS[None]).reshape(-1, 3) * voxel_m
    seen = inside(transform_points(invert(T_loc_base), corners_loc))
    whole = seen.reshape(len(unique_keys), 8).all(axis=1)
    return whole[inverse.ravel()]
