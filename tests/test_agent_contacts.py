"""The bumper layer (contacts.py): a stall marks what the camera missed, a teammate does not."""

from __future__ import annotations

import math

import numpy as np

from schemas.messages import Goal
from services.common.grid import GridSpec
from services.robot_agent.config import AgentConfig
from services.robot_agent.contacts import ContactLayer, ContactParams
from services.robot_agent.local_grid import OCCUPIED, LocalGrid
from services.robot_agent.navigation import Navigator

NOBODY = np.zeros((0, 2))


def _stall(layer: ContactLayer, pose: tuple[float, float, float], ticks: int,
           teammates: np.ndarray = NOBODY) -> list[bool]:
    return [layer.observe(k, pose, 0.3, teammates) for k in range(ticks)]


def test_a_second_pushing_without_moving_marks_the_front() -> None:
    layer = ContactLayer(ContactParams(), robot_radius_m=0.18)
    added = _stall(layer, (1.0, 2.0, 0.0), 11)
    assert added == [False] * 10 + [True] and layer.n_contacts == 1
    assert np.allclose(layer.points_xy[len(layer.points_xy) // 2], [1.23, 2.0])
    spec = GridSpec(0.0, 0.0, 0.05, 80, 80)
    cells = layer.mark(np.zeros(spec.shape, np.int8), spec, 11)
    assert cells[spec.cell_of(np.array([[1.23, 2.0]]))[0][0],
                 spec.cell_of(np.array([[1.23, 2.0]]))[0][1]] == OCCUPIED
    assert (cells == OCCUPIED).sum() >= 5
    assert layer.active(11)
    forgotten = layer.mark(np.zeros(spec.shape, np.int8), spec, 10 + ContactParams().ttl_ticks)
    assert not (forgotten == OCCUPIED).any() and not layer.active(10 + ContactParams().ttl_ticks)


def test_moving_turning_or_a_teammate_close_leave_no_mark() -> None:
    layer = ContactLayer(ContactParams(), robot_radius_m=0.18)
    for k in range(30):  # driving at 5 cm per tick
        assert not layer.observe(k, (0.05 * k, 0.0, 0.0), 0.5, NOBODY)
    assert not any(layer.observe(k, (2.0, 0.0, 0.1 * k), 0.0, NOBODY) for k in range(30))
    assert not any(_stall(layer, (2.0, 0.0, 0.0), 30, np.array([[2.6, 0.0]])))
    assert layer.n_contacts == 0


def test_the_navigator_plans_around_a_contact() -> None:
    """A chair the grid shows as free floor: after the stall, the path avoids its front."""
    config = AgentConfig(contact_layer=True)
    nav = Navigator(config, 0.1)
    grid = LocalGrid.centred(0.0, 0.0, 3.0, 0.05)
    xs = np.arange(-2.0, 2.0, 0.05)
    grid.update(np.array([(x, y) for x in xs for y in xs]), np.zeros((0, 2)))
    nav.set_goal(Goal(robot_id=0, goal_id=1, tick=0, x=1.5, y=0.0, frontier_class="unexplored",
                      revenue=1.0), 0)
    pose = (0.0, 0.0, 0.0)
    cmd, _ = nav.step(pose, grid, 1)
    assert cmd.v_mps > 0 and np.all(np.abs(nav.path_xy[:, 1]) < 0.05)  # straight ahead
    for tick in range(2, 14):
        nav.observe_motion(tick, pose, 0.3, NOBODY)
    nav.step(pose, grid, 14)
    assert nav.contacts is not None and nav.contacts.n_contacts == 1
    ahead = nav.path_xy[(nav.path_xy[:, 0] > 0.15) & (nav.path_xy[:, 0] < 0.35)]
    assert len(ahead) and np.all(np.abs(ahead[:, 1]) > 0.15)
    assert math.isclose(nav.path_xy[-1][0], 1.5, abs_tol=0.1)


def test_a_goal_only_reachable_through_a_contact_is_unreachable() -> None:
    """A stall in a corridor: pushing on would only stall again until the validator gave up;
    the goal ends unreachable at once (the edge sets it aside; the mark fades in 15 s)."""
    nav = Navigator(AgentConfig(contact_layer=True), 0.1)
    grid = LocalGrid.centred(0.0, 0.0, 3.0, 0.05)
    xs = np.arange(-3.0, 3.0, 0.05)
    thick = np.arange(0.4, 1.2, 0.05)  # walls thicker than the goal snap
    walls = [(x, s * y) for x in xs for y in thick for s in (-1, 1)]
    end = [(x, y) for x in np.arange(1.8, 2.6, 0.05) for y in np.arange(-0.4, 0.41, 0.05)]
    grid.update(np.array([(x, y) for x in xs[xs < 1.8] for y in np.arange(-0.35, 0.36, 0.05)]),
                np.array(walls + end))
    nav.set_goal(Goal(robot_id=0, goal_id=1, tick=0, x=1.5, y=0.0, frontier_class="unexplored",
                      revenue=1.0), 0)
    pose = (0.0, 0.0, 0.0)
    cmd, event = nav.step(pose, grid, 1)
    assert event is None and nav.path_xy is not None  # the corridor is open
    for tick in range(2, 14):
        nav.observe_motion(tick, pose, 0.3, NOBODY)
    cmd, event = nav.step(pose, grid, 14)
    assert nav.contacts is not None and nav.contacts.n_contacts == 1
    assert event is not None and event.status == "unreachable"
    assert event.reason == "only through what the robot ran into"


def _corridor_navigator(config: AgentConfig) -> tuple[Navigator, LocalGrid]:
    """A robot in a dead-end corridor that has just stalled facing its only way on."""
    nav = Navigator(config, 0.1)
    grid = LocalGrid.centred(0.0, 0.0, 3.0, 0.05)
    xs = np.arange(-3.0, 3.0, 0.05)
    thick = np.arange(0.4, 1.2, 0.05)
    walls = [(x, s * y) for x in xs for y in thick for s in (-1, 1)]
    back = [(x, y) for x in np.arange(-1.2, -0.4, 0.05) for y in np.arange(-0.4, 0.41, 0.05)]
    grid.update(np.array([(x, y) for x in xs[xs > -0.4] for y in np.arange(-0.35, 0.36, 0.05)]),
                np.array(walls + back))
    nav.set_goal(Goal(robot_id=0, goal_id=1, tick=0, x=1.5, y=0.0, frontier_class="unexplored",
                      revenue=1.0), 0)
    nav.step((0.0, 0.0, 0.0), grid, 1)
    for tick in range(2, 14):
        nav.observe_motion(tick, (0.0, 0.0, 0.0), 0.3, NOBODY)
    return nav, grid


def test_a_robot_its_marks_box_in_forgets_them_after_a_few_goals() -> None:
    """The marks close the only way out (a robot stalled at the narrow gap it came in by):
    the first goals end unreachable, the third in a row forgets the marks and drives; with
    `contact_boxed_in_goals=0` every goal ends unreachable until the marks fade."""
    for limit, drives_at in ((3, 3), (0, None)):
        nav, grid = _corridor_navigator(AgentConfig(contact_layer=True,
                                                    contact_boxed_in_goals=limit))
        outcomes = []
        for k in range(1, 5):
            tick = 14 + k
            if k > 1:
                nav.set_goal(Goal(robot_id=0, goal_id=k, tick=tick, x=1.5 + 0.05 * k, y=0.0,
                                  frontier_class="unexplored", revenue=1.0), tick)
            cmd, event = nav.step((0.0, 0.0, 0.0), grid, tick)
            outcomes.append("drive" if event is None and cmd.v_mps > 0 else event.status)
        expected = ["unreachable"] * 4 if drives_at is None else \
            ["unreachable"] * (drives_at - 1) + ["drive"] * (5 - drives_at)
        assert outcomes == expected, (limit, outcomes)
        assert nav.contacts is not None and nav.contacts.active(18) == (drives_at is None)
