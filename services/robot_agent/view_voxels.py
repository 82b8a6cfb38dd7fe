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

# (N, 3) base-frame voxel centres and the voxel edge (m) → (N,) bool: seen whole
HoldsWhole = Callable[[np.ndarray, float], np.ndarray]


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

    def holds_whole(self, centres_base: np.ndarray, voxel_m: float) -> np.ndarray:
        """(N,) whether each voxel (base-frame centre, edge `voxel_m`) was seen whole: its
        bounding sphere in front of the camera, in range, its image footprint (the sphere's
        square) inside the image and, with `valid`, a return at every pixel of it (the far
        ones lost to range, grazing angles or the DRF cut a voxel too). A sphere, not the
        eight corners: one projection per voxel, and only slightly stricter."""
        c = transform_points(invert(self.T_base_cam), centres_base)
        z = c[:, 2]
        radius = 0.5 * np.sqrt(3.0) * voxel_m
        ok = (z > radius + 1e-3) & (z + radius <= self.range_m)
        zs = np.where(ok, z, 1.0)
        fx, fy = self.K[0, 0], self.K[1, 1]
        u, v = fx * c[:, 0] / zs + self.K[0, 2], fy * c[:, 1] / zs + self.K[1, 2]
        # the sphere's image spans r·f/(z − r) either side of the centre's, at most
        du, dv = radius * fx / (zs - radius), radius * fy / (zs - radius)
        c0, c1 = _pixel_index(u - du), _pixel_index(u + du)
        r0, r1 = _pixel_index(v - dv), _pixel_index(v + dv)
        ok &= (c0 >= 0) & (c1 <= self.width - 1) & (r0 >= 0) & (r1 <= self.height - 1)
        if self.valid is None:
            return ok
        c0, c1, r0, r1 = (np.where(ok, a, 0) for a in (c0, c1, r0, r1))
        holes = np.zeros((self.height + 1, self.width + 1), np.int32)
        holes[1:, 1:] = np.cumsum(np.cumsum(~self.valid, axis=0, dtype=np.int32), axis=1)
        missing = holes[r1 + 1, c1 + 1] - holes[r0, c1 + 1] - holes[r1 + 1, c0] + holes[r0, c0]
        return ok & (missing == 0)


def _pixel_index(coord: np.ndarray) -> np.ndarray:
    """The pixel whose centre is nearest (pixel i spans i − ½ … i + ½)."""
    return np.floor(coord + 0.5).astype(np.int64)


def corners_inside(inside: Callable[[np.ndarray], np.ndarray]) -> HoldsWhole:
    """A voxel test from a point test on base-frame points: all eight corners inside (the
    voxel's edges taken along the base frame's axes, as for a map aligned with it)."""
    def holds_whole(centres_base: np.ndarray, voxel_m: float) -> np.ndarray:
        corners = centres_base[:, None, :] + voxel_m * _CORNERS[None]
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
    centres_loc = (np.floor(transform_points(T_loc_base, points_base) / voxel_m) + 0.5) * voxel_m
    return holds_whole(transform_points(invert(T_loc_base), centres_loc), voxel_m)
