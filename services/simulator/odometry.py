"""Wheel odometry with seeded, configurable drift.

Each tick the true planar motion increment (in the robot's previous true base frame) is
corrupted and integrated onto the odometry pose:
- translation scaled by (1 + scale_error), plus white noise growing with √distance;
- rotation scaled by (1 + yaw_scale_error), plus a heading bias per metre travelled
  (a mismatched wheel radius makes a straight drive curve), plus white noise with √angle.
The odometry frame is the world frame at spawn, so the first pose equals the true spawn pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.common.geometry import wrap_angle
from services.simulator.worlds import Pose


@dataclass(frozen=True)
class OdometryNoise:
    scale_error: float = 0.02  # relative error of distance travelled
    yaw_scale_error: float = 0.01  # relative error of angle turned
    heading_bias_rad_per_m: float = 0.005  # systematic yaw drift per metre travelled
    noise_m_per_sqrt_m: float = 0.0  # random-walk translation noise
    noise_rad_per_sqrt_rad: float = 0.0  # random-walk rotation noise


def relative_motion(prev: Pose, curr: Pose) -> tuple[float, float, float]:
    """Increment (dx, dy, dyaw) from `prev` to `curr`, expressed in the `prev` base frame."""
    c, s = math.cos(prev[2]), math.sin(prev[2])
    wx, wy = curr[0] - prev[0], curr[1] - prev[1]
    return c * wx + s * wy, -s * wx + c * wy, float(wrap_angle(curr[2] - prev[2]))


class WheelOdometry:
    """Integrates corrupted true increments; deterministic for a given generator."""

    def __init__(self, spawn: Pose, noise: OdometryNoise, rng: np.random.Generator) -> None:
        self.noise = noise
        self.rng = rng
        self.pose: Pose = spawn
        self._last_true: Pose = spawn
        self.distance_m = 0.0

    def update(self, true_pose: Pose, dt_s: float) -> tuple[Pose, float, float]:
        """Advance to `true_pose`; returns (odometry pose, measured v m/s, measured ω rad/s)."""
        dx, dy, dyaw = relative_motion(self._last_true, true_pose)
        self._last_true = true_pose
        n = self.noise
        dist = math.hypot(dx, dy)
        k = 1.0 + n.scale_error
        if n.noise_m_per_sqrt_m > 0 and dist > 0:
            k += n.noise_m_per_sqrt_m * math.sqrt(dist) * float(self.rng.standard_normal()) / dist
        mdx, mdy = k * dx, k * dy
        mdyaw = dyaw * (1.0 + n.yaw_scale_error) + n.heading_bias_rad_per_m * dist * (
            1.0 if dx >= 0 else -1.0
        )
        if n.noise_rad_per_sqrt_rad > 0 and dyaw != 0:
            mdyaw += n.noise_rad_per_sqrt_rad * math.sqrt(abs(dyaw)) * float(
                self.rng.standard_normal()
            )
        x, y, yaw = self.pose
        c, s = math.cos(yaw), math.sin(yaw)
        self.pose = (x + c * mdx - s * mdy, y + s * mdx + c * mdy, float(wrap_angle(yaw + mdyaw)))
        self.distance_m += dist
        return self.pose, math.copysign(k * dist, dx) / dt_s, mdyaw / dt_s
