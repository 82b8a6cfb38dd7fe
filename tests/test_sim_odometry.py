"""Wheel odometry drifts by the configured amounts, deterministically."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.simulator.config import SimConfig
from services.simulator.core import Simulation
from services.simulator.odometry import OdometryNoise, WheelOdometry


def test_scale_and_heading_bias_on_a_straight_line() -> None:
    noise = OdometryNoise(scale_error=0.05, yaw_scale_error=0.0, heading_bias_rad_per_m=0.01)
    odom = WheelOdometry((1.0, 2.0, 0.0), noise, np.random.default_rng(0))
    for k in range(1, 101):
        pose, v, _ = odom.update((1.0 + 0.02 * k, 2.0, 0.0), 0.1)
    assert odom.distance_m == pytest.approx(2.0)
    assert pose[2] == pytest.approx(0.02)
    assert math.hypot(pose[0] - 1.0, pose[1] - 2.0) == pytest.approx(2.1, rel=1e-3)
    assert v == pytest.approx(0.2 * 1.05)


def test_yaw_scale_on_a_turn() -> None:
    noise = OdometryNoise(scale_error=0.0, yaw_scale_error=0.1, heading_bias_rad_per_m=0.0)
    odom = WheelOdometry((0.0, 0.0, 0.0), noise, np.random.default_rng(0))
    for k in range(1, 11):
        pose, _, omega = odom.update((0.0, 0.0, 0.1 * k), 0.1)
    assert pose[2] == pytest.approx(1.1)
    assert omega == pytest.approx(1.1)


def test_random_noise_is_seeded() -> None:
    noise = OdometryNoise(noise_m_per_sqrt_m=0.01, noise_rad_per_sqrt_rad=0.01)
    runs = []
    for seed in (1, 1, 2):
        odom = WheelOdometry((0.0, 0.0, 0.0), noise, np.random.default_rng(seed))
        for k in range(1, 50):
            odom.update((0.03 * k, 0.0, 0.02 * k), 0.1)
        runs.append(odom.pose)
    assert runs[0] == runs[1] != runs[2]


def test_simulation_odometry_starts_at_spawn_and_drifts() -> None:
    # Ideal sensors: the assertion checks the scale error alone, to 0.1 %; the default random
    # walk (0.01 m/√m, ~1.4 cm over 2 m) is tested in test_sim_sensors.py.
    cfg = SimConfig(
        world="bookstore", robots=1, spawn=[(1.0, 1.2, 0.0)], odom_scale_error=0.05,
        odom_yaw_scale_error=0.0, odom_heading_bias_rad_per_m=0.0, sensors="ideal",
    )
    sim = Simulation(cfg)
    assert sim.odometry(0).pose == sim.true_pose(0)
    for _ in range(40):
        sim.step({0: (0.5, 0.0)})
    true_x = sim.true_pose(0)[0] - 1.0
    odom_x = sim.odometry(0).pose[0] - 1.0
    assert true_x > 1.9
    assert odom_x == pytest.approx(1.05 * true_x, rel=1e-3)


def test_robots_wheels_differ_by_the_configured_spread_and_by_nothing_without_it() -> None:
    from services.simulator.core import odometry_noise

    same = SimConfig(seed=3)
    assert {odometry_noise(same, i) for i in range(4)} == {odometry_noise(same)}
    assert odometry_noise(same, 2).scale_error == same.odom_scale_error
    spread = SimConfig(seed=3, odom_error_spread=0.25)
    wheels = [odometry_noise(spread, i) for i in range(200)]
    scales = np.array([w.scale_error for w in wheels]) / spread.odom_scale_error
    assert len({w.scale_error for w in wheels}) == 200
    assert np.mean(scales) == pytest.approx(1.0, abs=0.06)
    assert np.std(scales) == pytest.approx(0.25, rel=0.15)
    assert odometry_noise(spread, 7) == odometry_noise(SimConfig(seed=3, odom_error_spread=0.25), 7)
    assert odometry_noise(spread, 7) != odometry_noise(SimConfig(seed=4, odom_error_spread=0.25), 7)
