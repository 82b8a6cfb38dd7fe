"""Robots stop at walls and at each other, respect velocity limits, and runs repeat exactly."""

from __future__ import annotations

import math

import numpy as np

from services.simulator.config import SimConfig
from services.simulator.core import Simulation
from services.simulator.robots import FOOTPRINT_M


def drive(sim: Simulation, commands: dict[int, tuple[float, float]], seconds: float) -> None:
    for _ in range(round(seconds / sim.cfg.tick_s)):
        sim.step(commands)


def test_robot_stops_at_wall() -> None:
    # Bookstore west wall: inner face at x = 0.05.
    sim = Simulation(SimConfig(world="bookstore", robots=1, spawn=[(1.0, 1.2, math.pi)]))
    drive(sim, {0: (0.5, 0.0)}, 4.0)
    x, y, yaw = sim.true_pose(0)
    assert 0.05 + FOOTPRINT_M[0] / 2 - 0.02 < x < 0.05 + FOOTPRINT_M[0] / 2 + 0.03
    assert abs(y - 1.2) < 0.05 and abs(abs(yaw) - math.pi) < 0.05
    drive(sim, {0: (0.5, 0.0)}, 1.0)
    assert abs(sim.true_pose(0)[0] - x) < 0.01  # stays put


def test_velocity_limits() -> None:
    sim = Simulation(SimConfig(world="bookstore", robots=1, spawn=[(1.0, 1.2, 0.0)]))
    drive(sim, {0: (3.0, 0.0)}, 1.0)
    x = sim.true_pose(0)[0]
    assert 1.0 + 0.45 < x <= 1.0 + 0.5 + 1e-3
    sim = Simulation(SimConfig(world="bookstore", robots=1, spawn=[(1.0, 1.2, 0.0)]))
    drive(sim, {0: (0.0, -5.0)}, 1.0)
    assert -math.pi / 4 - 1e-3 <= sim.true_pose(0)[2] < -math.pi / 4 + 0.05


def test_turning_robot_moves_along_its_heading() -> None:
    sim = Simulation(SimConfig(world="bookstore", robots=1, spawn=[(1.0, 1.2, math.pi / 2)]))
    drive(sim, {0: (0.3, 0.0)}, 1.0)
    x, y, _ = sim.true_pose(0)
    assert abs(x - 1.0) < 0.01 and 1.45 < y < 1.51


def test_robots_cannot_pass_through_each_other() -> None:
    cfg = SimConfig(world="bookstore", robots=2, spawn=[(1.0, 1.2, 0.0), (3.0, 1.2, math.pi)])
    sim = Simulation(cfg)
    for _ in range(40):
        sim.step({0: (0.5, 0.0), 1: (0.5, 0.0)})
        x0, x1 = sim.true_pose(0)[0], sim.true_pose(1)[0]
        assert x1 - x0 > FOOTPRINT_M[0] - 0.02
    assert x1 - x0 < FOOTPRINT_M[0] + 0.05  # they did meet


def run(seed: int) -> tuple[list, list, bytes]:
    """Trajectories, odometry and the depth of the last frame of a noisy 3-robot run."""
    cfg = SimConfig(world="house", robots=3, seed=seed, odom_noise_m_per_sqrt_m=0.01,
                    odom_noise_rad_per_sqrt_rad=0.01, depth_noise_per_m2=0.01,
                    render_backend="raycast")
    sim = Simulation(cfg)
    rng = np.random.default_rng(7)  # the same commands in every run
    poses, odoms = [], []
    for _ in range(40):
        sim.step({i: (rng.uniform(-0.2, 0.5), rng.uniform(-0.8, 0.8)) for i in range(3)})
        poses.append([sim.true_pose(i) for i in range(3)])
        odoms.append([sim.odometry(i) for i in range(3)])
    return poses, odoms, sim.render(1).depth_m.tobytes()


def test_same_seed_same_run() -> None:
    first, again, other = run(3), run(3), run(4)
    assert first == again
    assert other[0] == first[0]  # physics has no randomness ...
    assert other[1] != first[1] and other[2] != first[2]  # ... the sensor noise is seeded
