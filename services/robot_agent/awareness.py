"""Mutual awareness (paper §III-A): which teammates may appear in the observer's camera.

Planar geometry on pose estimates only, vectorized over teammates. `visible_paper` is the
paper's test verbatim: a target is in view iff

    0 ≤ d ≤ γ  and  |Δθ| + c/d ≤ FoV/2 − α,   α = arctan(R / d),

i.e. the whole robot circle (plus the buffer c/d) lies inside the FoV. A robot only partly in
view (at the image border) fails that test and would be mapped, so the DRF uses
`in_view_partial` by default: any part of the buffered circle inside the FoV,

    |Δθ| − α − c/d ≤ FoV/2.

Both share `angle_to_targets`; docs/agent.md measures the two against the simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Bearing:
    """Per-target range d (m), normalised angle Δθ (rad) and angular size α (rad)."""

    d: np.ndarray
    dtheta: np.ndarray
    alpha: np.ndarray


def normalize_angle(angle: np.ndarray | float) -> np.ndarray:
    """((a + π) mod 2π) − π, the paper's normalisation into [−π, π)."""
    return np.mod(np.asarray(angle, dtype=np.float64) + math.pi, 2 * math.pi) - math.pi


def angle_to_targets(
    pose_obs: tuple[float, float, float], xy_targets: np.ndarray, radius_m: float
) -> Bearing:
    """Range, Δθ and α of (N, 2) target positions seen from the observer pose (x, y, ψ)."""
    xy = np.asarray(xy_targets, dtype=np.float64).reshape(-1, 2)
    rel = xy - np.array(pose_obs[:2])
    d = np.hypot(rel[:, 0], rel[:, 1])
    theta_norm = normalize_angle(np.arctan2(rel[:, 1], rel[:, 0]))
    psi_norm = normalize_angle(pose_obs[2])
    dtheta = normalize_angle(theta_norm - psi_norm)
    alpha = np.arctan2(radius_m, d)  # arctan(R / d), defined at d = 0 too (→ π/2)
    return Bearing(d, dtheta, alpha)


def _buffer(d: np.ndarray, c: float) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.where(d > 0, c / np.maximum(d, 1e-12), np.inf)


def visible_paper(
    pose_obs: tuple[float, float, float], xy_targets: np.ndarray, *, radius_m: float,
    fov_rad: float, range_m: float, c: float,
) -> np.ndarray:
    """(N,) bool: the paper's inequality |Δθ| + c/d ≤ FoV/2 − α within range γ."""
    b = angle_to_targets(pose_obs, xy_targets, radius_m)
    in_range = (b.d >= 0) & (b.d <= range_m)
    return in_range & (np.abs(b.dtheta) + _buffer(b.d, c) <= fov_rad / 2 - b.alpha)


def in_view_partial(
    pose_obs: tuple[float, float, float], xy_targets: np.ndarray, *, radius_m: float,
    fov_rad: float, range_m: float, c: float,
) -> np.ndarray:
    """(N,) bool: some part of the robot circle grown by c/d is inside the FoV, and its near
    side within γ in depth.

    The camera clips z-depth (the distance along the optical axis) at γ, not the range: at
    the image border a robot 6.7 m away is still within 5 m of depth, and missions mapped
    such robots as ghosts. The circle's smallest depth is d·cos Δθ − R.
    """
    b = angle_to_targets(pose_obs, xy_targets, radius_m)
    in_range = b.d * np.cos(b.dtheta) - radius_m <= range_m
    with np.errstate(invalid="ignore"):
        return in_range & (np.abs(b.dtheta) - b.alpha - _buffer(b.d, c) <= fov_rad / 2)
