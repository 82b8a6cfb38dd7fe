"""bench/bench_odometry_chords.py: chords of wheels that over-turn, raw and turn-corrected."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from bench_odometry_chords import chord_scale, window_chords  # noqa: E402

from services.robot_agent.odometry_calibration import OdometryErrors  # noqa: E402
from services.simulator.odometry import OdometryNoise, WheelOdometry  # noqa: E402


def test_raw_chords_round_corners_fall_short_of_the_wheels_scale_corrected_ones_do_not() -> None:
    truth = [(0.0, 0.0, 0.0)]
    x = y = yaw = 0.0
    for i in range(60):  # 1 m legs joined by quarter turns on the move, left then right
        for omega, ticks in ((0.0, 20), (1.0 if i % 2 == 0 else -1.0, 16)):
            for _ in range(ticks):
                yaw += omega * 0.1 * (math.pi / 2) / 1.6
                x += 0.05 * math.cos(yaw)
                y += 0.05 * math.sin(yaw)
                truth.append((x, y, yaw))
    wheels = WheelOdometry(truth[0], OdometryNoise(0.02, 0.05, 0.0), np.random.default_rng(0))
    odom = np.array([truth[0]] + [wheels.update(p, 0.1)[0] for p in truth[1:]])
    rows = window_chords(odom, np.array(truth)[:, :2], 72, OdometryErrors(0.0, 0.05, 0.0))
    assert len(rows) == 30
    assert chord_scale(rows[:, 0], rows[:, 2]) < 0.0
    assert abs(chord_scale(rows[:, 1], rows[:, 2]) - 0.02) < 1e-3
