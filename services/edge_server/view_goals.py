"""Goals far enough back to see a high region: f′ for surfaces above the camera's reach.

A level camera at height h with vertical half-FoV α sees a surface at horizontal distance d
only up to h + d·tan α. The nearest reachable cell to a region's anchor (`frontiers.py`) is
right for the floor, but for the top rim of what the robots have seen of a shelf or a wall
(low-density voxels at 1.3-1.5 m, the surface above them unseen) it is useless: from 0.5 m the
camera sees up to 0.7 m. A region whose height z_top (a high quantile of its voxels' heights)
needs d ≥ (z_top + margin − h) / tan α gets instead the reachable cell at a distance in
[d, d + extra] from its anchor, with a clear line of sight on the grid, whose bearing makes
the smallest angle with the face's outward normal (taken as the direction from the anchor to
the nearest reachable cell, the side the robots are on); the robot faces the region there
(`Goal.look_xy`). Regions low enough, or with no such cell, keep their goal.

Pure functions on grids and arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.grid import GridSpec


@dataclass(frozen=True)
class ViewGeometry:
    """The camera and the search for a far view (metres, radians)."""

    camera_height_m: float
    half_vfov_rad: float
    range_m: float
    margin_m: float = 0.4  # how far above z_top the view should reach
    extra_m: float = 1.0  # candidates up to this much beyond the needed distance
    max_incidence_rad: float = np.radians(75.0)  # bearing off the face's normal
    azimuths: int = 64
    slack_m: float = 0.3  # a line of sight may start inside the region's own cells

    def needed_m(self, z_top: np.ndarray) -> np.ndarray:
        """(F,) horizontal distance from which the camera sees `margin_m` above z_top."""
        rise = np.asarray(z_top, np.float64) + self.margin_m - self.camera_height_m
        return np.maximum(rise, 0.0) / np.tan(self.half_vfov_rad)


def region_top_z(labels: np.ndarray, z: np.ndarray, n: int, quantile: float) -> np.ndarray:
    """(n,) per label 0..n-1 the `quantile` of its heights (nearest rank); nan if empty."""
    out = np.full(n, np.nan)
    if not len(labels):
        return out
    order = np.lexsort((z, labels))
    lab, zs = labels[order], z[order]
    starts = np.searchsorted(lab, np.arange(n))
    counts = np.bincount(lab, minlength=n)
    has = counts > 0
    rank = starts[has] + np.minimum((quantile * (counts[has] - 1)).round().astype(np.int64),
                                    counts[has] - 1)
    out[has] = zs[rank]
    return out


def view_goals(
    anchor_rc: np.ndarray, goal_rc: np.ndarray, z_top: np.ndarray, see_through: np.ndarray,
    goal_ok: np.ndarray, spec: GridSpec, geometry: ViewGeometry,
) -> tuple[np.ndarray, np.ndarray]:
    """(F, 2) goal cells and (F,) bool moved: each region's far view where it needs one.

    `see_through`: (H, W) bool, known free cells (a line of sight crosses only these once
    it has left the region's own cells); `goal_ok`: cells a goal may be placed on.
    """
    anchor_rc = np.asarray(anchor_rc, np.int64).reshape(-1, 2)
    goal_rc = np.asarray(goal_rc, np.int64).reshape(-1, 2)
    n = len(anchor_rc)
    res = spec.resolution_m
    need = geometry.needed_m(z_top)
    have = np.hypot(*(goal_rc - anchor_rc).T) * res
    asks = np.flatnonzero(np.isfinite(need) & (need > have + res))
    new_rc, moved = goal_rc.copy(), np.zeros(n, bool)
    if not len(asks):
        return new_rc, moved
    theta = np.arange(geometry.azimuths) * (2 * np.pi / geometry.azimuths)
    direction = np.stack([np.sin(theta), np.cos(theta)], 1)  # (K, 2) in (row, col)
    far = (need[asks] + geometry.extra_m)
    rise = np.abs(z_top[asks] - geometry.camera_height_m)
    reach = np.sqrt(np.maximum(geometry.range_m**2 - rise**2, 0.0))
    steps = np.arange(1, int(np.ceil(far.max() / res)) + 1)
    # (A, K, S) cells along each ray
    rc = np.rint(anchor_rc[asks, None, None, :] + steps[None, None, :, None]
                 * direction[None, :, None, :]).astype(np.int64)
    inside = ((rc[..., 0] >= 0) & (rc[..., 0] < spec.height) & (rc[..., 1] >= 0)
              & (rc[..., 1] < spec.width))
    r, c = np.clip(rc[..., 0], 0, spec.height - 1), np.clip(rc[..., 1], 0, spec.width - 1)
    clear = see_through[r, c] & inside
    dist = steps[None, None, :] * res
    # within `slack_m` the ray may still cross the region's own cells (its face, the unknown
    # inside a shelf); past it the first cell that is not clear blocks the rest
    blocked = np.maximum.accumulate(~clear & (dist > geometry.slack_m), axis=2)
    ok = (clear & ~blocked & goal_ok[r, c]
          & (dist >= need[asks, None, None]) & (dist <= far[:, None, None])
          & (dist <= reach[:, None, None]))
    outward = (goal_rc[asks] - anchor_rc[asks]).astype(np.float64)
    norm = np.hypot(*outward.T)
    cos_off = np.where(norm[:, None] > 0, (outward @ direction.T)
                       / np.maximum(norm, 1e-9)[:, None], 1.0)  # (A, K)
    ok &= (cos_off >= np.cos(geometry.max_incidence_rad))[:, :, None]
    # best: the smallest angle off the normal, then the nearest distance
    score = np.where(ok, -cos_off[:, :, None] * 1e3 + dist, np.inf)
    flat = score.reshape(len(asks), -1)
    best = flat.argmin(axis=1)
    found = np.isfinite(flat[np.arange(len(asks)), best])
    k, s = np.unravel_index(best, score.shape[1:])
    pick = rc[np.arange(len(asks)), k, s]
    new_rc[asks[found]] = pick[found]
    moved[asks[found]] = True
    return new_rc, moved
