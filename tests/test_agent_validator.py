"""The adaptive goal validator: t_e sums, the β window, and a robot blocked on its path."""

from __future__ import annotations

import math

import numpy as np

from schemas.messages import Goal
from services.robot_agent.config import AgentConfig
from services.robot_agent.local_grid import LocalGrid
from services.robot_agent.navigation import Navigator
from services.robot_agent.validator import PassLog, expected_times, window_exceeded

CFG = AgentConfig()
DT = 0.1


def test_expected_times_include_the_first_turn() -> None:
    t = expected_times(np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0]]), 0.0, 0.5, math.pi / 4)
    np.testing.assert_allclose(t, [2.0 + 2.0, 2.0 + 2.0])


def test_window_compares_time_over_the_last_beta_points() -> None:
    log = PassLog(start_tick=0)
    for k in range(1, 11):  # one point per second, t_e 1 s each
        log.passed(k * 10, np.array([1.0]))
    # window of β = 3: points passed at ticks 80, 90, 100, measured since tick 70
    assert not window_exceeded(log, 100, DT, current_t_e=1.0, beta=3, slack_s=0.0)  # 3 ≤ 4
    assert window_exceeded(log, 112, DT, current_t_e=1.0, beta=3, slack_s=0.0)  # 4.2 > 4
    assert not window_exceeded(log, 112, DT, current_t_e=1.0, beta=3, slack_s=0.5)


def _open_room() -> LocalGrid:
    grid = LocalGrid.centred(0.0, 0.0, 4.0, 0.05)
    s = np.arange(-3.0, 3.0, 0.025)
    walls = [np.stack([s, np.full_like(s, v)], 1) for v in (-3.0, 3.0)]
    walls += [np.stack([np.full_like(s, v), s], 1) for v in (-3.0, 3.0)]
    grid.update(np.empty((0, 2)), np.concatenate(walls))
    return grid


def _drive(barrier_x: float | None, ticks: int = 300):
    """Follow a goal 4 m ahead; an unseen barrier (glass door) may stop the robot at x."""
    nav, grid = Navigator(CFG, DT), _open_room()
    nav.set_goal(Goal(robot_id=0, tick=0, goal_id=1, x=2.0, y=0.0, frontier_class="weak",
                      revenue=1.0), 0)
    x, y, yaw = -2.0, 0.0, 0.0
    for k in range(ticks):
        cmd, ev = nav.step((x, y, yaw), grid, k)
        if ev is not None:
            return k, ev
        x = x + cmd.v_mps * math.cos(yaw) * DT
        if barrier_x is not None:
            x = min(x, barrier_x)
        y, yaw = y + cmd.v_mps * math.sin(yaw) * DT, yaw + cmd.omega_radps * DT
    return ticks, None


def test_validator_fires_on_a_blocked_path_and_not_on_a_free_one() -> None:
    k_free, free = _drive(None)
    assert free is not None and free.status == "reached"
    k_blocked, blocked = _drive(barrier_x=0.0)
    assert blocked is not None and blocked.status == "invalid" and "t_e" in blocked.reason
    # caught well before a whole-goal budget would (t_e of the 4 m path ≈ 8 s; stop at ~4 s)
    assert k_blocked * DT <= 20.0
