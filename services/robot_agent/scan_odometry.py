"""The heading increment between consecutive frames, from the frames themselves.

Wheel odometry loses heading while a robot turns in place (1 % turn scale, a 0.01 rad/√rad
random walk: 0.1-0.3° per 9° frame step), so the drift filter must expect that much, and a
frame-to-map registration that is 1-2° off still passes its gate. That happens on a turn into
ground the map covers in part: the frame's yaw is barely determined against the map (GICP's
yaw information drops 10-20 × once translation is free), yet it converges. Two consecutive
frames overlap far more (84° field of view, 9° apart), and registered to each other they give
the turn to about a hundredth of a degree (three missions' 5520 frame steps: median 0.009°, p99
0.18°, against raw odometry's 0.089° / 0.51°; bench/bench_scan_heading.py, docs/agent.md,
"Heading from consecutive frames"). The localizer fuses the two turns by their variances.

Only the heading is taken: the wheels measure translation well, and a frame of one plain wall
lets a scan-to-scan registration slide along it. Pure: small_gicp and numpy, no clock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import small_gicp

from services.common.geometry import invert, wrap_angle, xyyaw_from_T


@dataclass(frozen=True)
class ScanOdometryParams:
    max_corr_m: float = 0.3
    max_iterations: int = 20
    min_inlier_frac: float = 0.5  # of the new frame's points matched in the previous one
    # the frames' turn is kept only this close to odometry's: base + per radian turned
    gate_rad: float = 0.01
    gate_rad_per_rad: float = 0.05
    sigma_rad: float = 0.0025  # its σ per frame step
    # frames too hidden by teammates to register against the map still give the turn
    when_hidden: bool = False


@dataclass
class _Frame:
    cloud: small_gicp.PointCloud
    tree: small_gicp.KdTree
    T_odom_base: np.ndarray


class ScanOdometry:
    """The previous frame, and the heading change to the next one."""

    def __init__(self, params: ScanOdometryParams) -> None:
        self.params = params
        self._prev: _Frame | None = None

    def reset(self) -> None:
        """Forget the previous frame (the next one is not consecutive to it)."""
        self._prev = None

    def turn(self, cloud: small_gicp.PointCloud, tree: small_gicp.KdTree,
             T_odom_base: np.ndarray) -> float | None:
        """Heading change (rad) from the previous frame to this one, or None where the frames
        do not give it (no previous frame, no convergence, little overlap, or a turn odometry
        cannot have made). This frame becomes the previous one."""
        prev, self._prev = self._prev, _Frame(cloud, tree, T_odom_base.copy())
        if prev is None:
            return None
        p = self.params
        T_prev_cur = invert(prev.T_odom_base) @ T_odom_base
        res = small_gicp.align(prev.cloud, cloud, prev.tree, T_prev_cur,
                               registration_type="GICP", max_correspondence_distance=p.max_corr_m,
                               num_threads=1, max_iterations=p.max_iterations)
        if not res.converged or res.num_inliers < p.min_inlier_frac * cloud.size():
            return None
        odom_turn = float(xyyaw_from_T(T_prev_cur)[2])
        scan_turn = float(xyyaw_from_T(res.T_target_source)[2])
        if abs(wrap_angle(scan_turn - odom_turn)) > p.gate_rad + p.gate_rad_per_rad * abs(
                odom_turn):
            return None
        return scan_turn
