"""The points of a frame whose registration-map voxel the camera saw whole.

The registration map (`registrar.py`) is a Gaussian voxel map: each voxel keeps the mean and
covariance of the points that fell in it. A voxel the view's boundary cuts (the range's far
edge, the image's sides, returns lost at grazing angles) holds only its inner part, so its
mean sits back toward the robot, and the next frame, which sees more of it, is pulled back.
Along an aisle that bias adds up frame after frame (bench/bench_aisle_lag.py; docs/agent.md,
"Only voxels the view saw whole"). Leaving out the points of the cut voxels, in the map's own
grid, removes a layer one voxel thick at the boundary: a later frame that sees the voxel whole
brings it in.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from services.common.geometry import invert, transform_points

_CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) - 0.5
# voxel keys packed into one int64: 21 bits per axis, offset so negative indices stay positive
_BITS, _OFFSET = 21, 1 << 20

# (M, 3) base-frame voxel centres and the (8, 3) base-frame offsets of a voxel's corners from
# its centre → (M,) bool: seen whole
HoldsWhole = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class CameraView:
    """What a pinhole depth camera returned: in front of it, inside the image, in range, and
    (with `valid`) at pixels that have a return."""

    K: np.ndarray  # (3, 3) intrinsics, pixels
    width: int  # image columns
    height: int  # image rows
    range_m: float  # largest depth (along the optical axis) with a return
    T_base_cam: np.ndarray  # (4, 4) optical frame (x right, y down, z forward) → base
    valid: np.ndarray | None = None  # (height, width) bool: the pixel has a return

    # the voxel's bounding sphere instead of its corners: its image square and its farthest
    # depth (z + r) must be inside, a stricter cut (docs/agent.md, "Only voxels the view saw
    # whole")
    sphere: bool = False

    def holds_whole(self, centres_base: np.ndarray, offsets_base: np.ndarray) -> np.ndarray:
        """(M,) whether each voxel was seen whole: its eight corners (or bounding sphere) in
        front of the camera, inside the image and either within the range or, with `valid`,
        over a footprint (the corners' pixel box) where every pixel has a return (the far
        ones lost to range, grazing angles or the DRF cut a voxel too)."""
        T_cam_base = invert(self.T_base_cam)
        if self.sphere:
            ok, c0, c1, r0, r1 = self._sphere_box(transform_points(T_cam_base, centres_base),
                                                  float(np.linalg.norm(offsets_base[0])))
        else:
            corners = (transform_points(T_cam_base, centres_base)[:, None, :]
                       + (offsets_base @ T_cam_base[:3, :3].T)[None])
            z = corners[..., 2]
            zs = np.where(z > 1e-6, z, 1.0)
            u = self.K[0, 0] * corners[..., 0] / zs + self.K[0, 2]
            v = self.K[1, 1] * corners[..., 1] / zs + self.K[1, 2]
            # pixel centres run 0 … W−1: a corner beyond the outermost centres is not seen
            inside = (z > 1e-6) & (u >= 0) & (u <= self.width - 1) & (v >= 0) \
                & (v <= self.height - 1)
            if self.valid is None:
                return (inside & (z <= self.range_m + 1e-9)).all(axis=1)
            ok = inside.all(axis=1)
            c0, c1 = _pixel_index(u.min(axis=1)), _pixel_index(u.max(axis=1))
            r0, r1 = _pixel_index(v.min(axis=1)), _pixel_index(v.max(axis=1))
        if self.valid is None:
            return ok
        c0, c1, r0, r1 = (np.where(ok, a, 0) for a in (c0, c1, r0, r1))
        holes = np.zeros((self.height + 1, self.width + 1), np.int32)
        holes[1:, 1:] = np.cumsum(np.cumsum(~self.valid, axis=0, dtype=np.int32), axis=1)
        missing = holes[r1 + 1, c1 + 1] - holes[r0, c1 + 1] - holes[r1 + 1, c0] + holes[r0, c0]
        return ok & (missing == 0)

    def _sphere_box(self, centres_cam: np.ndarray, radius: float,
                    ) -> tuple[np.ndarray, ...]:
        """(ok, first column, last column, first row, last row): the pixel square of each
        sphere's image, ok where it lies in front of the camera, in range and in the image."""
        z = centres_cam[:, 2]
        ok = (z > radius + 1e-3) & (z + radius <= self.range_m)
        zs = np.where(ok, z, 1.0)
        fx, fy = self.K[0, 0], self.K[1, 1]
        u = fx * centres_cam[:, 0] / zs + self.K[0, 2]
        v = fy * centres_cam[:, 1] / zs + self.K[1, 2]
        # the sphere's image spans at most r·f/(z − r) either side of its centre's
        du, dv = radius * fx / (zs - radius), radius * fy / (zs - radius)
        c0, c1 = _pixel_index(u - du), _pixel_index(u + du)
        r0, r1 = _pixel_index(v - dv), _pixel_index(v + dv)
        ok &= (c0 >= 0) & (c1 <= self.width - 1) & (r0 >= 0) & (r1 <= self.height - 1)
        return ok, c0, c1, r0, r1


def _pixel_index(coord: np.ndarray) -> np.ndarray:
    """The pixel whose centre is nearest (pixel i spans i − ½ … i + ½)."""
    return np.floor(coord + 0.5).astype(np.int64)


def corners_inside(inside: Callable[[np.ndarray], np.ndarray]) -> HoldsWhole:
    """A voxel test from a test on base-frame points: all eight corners inside."""
    def holds_whole(centres_base: np.ndarray, offsets_base: np.ndarray) -> np.ndarray:
        corners = centres_base[:, None, :] + offsets_base[None]
        return inside(corners.reshape(-1, 3)).reshape(len(centres_base), 8).all(axis=1)
    return holds_whole


def whole_voxel_mask(points_base: np.ndarray, T_loc_base: np.ndarray, voxel_m: float,
                     holds_whole: HoldsWhole) -> np.ndarray:
    """(N,) whether each base-frame point falls in a voxel of the `loc` grid (edge `voxel_m`,
    the registration map's) that the view holds whole, with the base at `T_loc_base`."""
    if len(points_base) == 0:
        return np.zeros(0, bool)
    if voxel_m <= 0:
        raise ValueError(f"voxel_m must be > 0, got {voxel_m}")
    idx = np.floor(transform_points(T_loc_base, points_base) / voxel_m).astype(np.int64)
    keys = ((idx[:, 0] + _OFFSET) << (2 * _BITS)) | ((idx[:, 1] + _OFFSET) << _BITS) \
        | (idx[:, 2] + _OFFSET)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    centres_base = transform_points(invert(T_loc_base), (idx[first] + 0.5) * voxel_m)
    offsets_base = (voxel_m * _CORNERS) @ T_loc_base[:3, :3]  # loc axes, in the base frame
    return holds_whole(centres_base, offsets_base)[inverse.ravel()]
