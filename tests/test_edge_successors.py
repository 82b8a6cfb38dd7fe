"""Successor goals: chosen from the goal the robot is about to reach, adopted on arrival."""

from __future__ import annotations

import numpy as np

from schemas.messages import Goal, GoalStatus
from services.edge_server.assignment import make_scorer
from services.edge_server.config import EdgeConfig
from services.edge_server.frontiers import FrontierSet
from services.edge_server.goals import ActiveGoal, GoalBook
from services.edge_server.successors import successor_frontiers
from services.robot_agent.agent import AgentCore
from services.robot_agent.config import AgentConfig
from services.robot_agent.navigation import StatusEvent

CELL = 0.1


def corridor_regions(cols: list[int]) -> tuple[np.ndarray, FrontierSet]:
    """A 3-cell-wide corridor 60 cells long; regions with their goals at the given columns."""
    trav = np.zeros((5, 60), bool)
    trav[1:4, :] = True
    rc = np.array([[2, c] for c in cols], np.int64)
    xy = (rc[:, ::-1] + 0.5) * CELL
    n = len(cols)
    fs = FrontierSet(labels=np.zeros(trav.shape, np.int32), sizes=np.full(n, 10),
                     centroid_xy=xy, anchor_rc=rc, anchor_xy=xy, goal_rc=rc, goal_xy=xy,
                     weak=np.zeros(n, bool), gain=np.ones(n), importance=np.ones(n))
    return trav, fs


def test_successor_is_the_best_frontier_from_the_goal_not_from_the_robot() -> None:
    # robot at column 20 heading for the goal at column 40; others at columns 5 and 50:
    # from the robot, 5 is nearer (15 vs 30 cells); from the goal, 50 is (10 vs 35)
    trav, fs = corridor_regions([40, 5, 50])
    scorer = make_scorer("space", EdgeConfig(space_view_radius_m=0.5))
    robot_xy = {0: np.array([2.05, 0.25])}
    usable = np.ones(3, bool)
    got = successor_frontiers({0: 0}, fs, trav, CELL, robot_xy, usable, scorer, 3.0)
    assert got == {0: 2}
    usable[2] = False  # e.g. a teammate holds it
    got = successor_frontiers({0: 0}, fs, trav, CELL, robot_xy, usable, scorer, 3.0)
    assert got == {0: 1}
    got = successor_frontiers({0: 0}, fs, trav, CELL, robot_xy, np.zeros(3, bool), scorer, 3.0)
    assert got == {}


def test_two_robots_never_queue_the_same_frontier() -> None:
    trav, fs = corridor_regions([30, 34, 55])
    scorer = make_scorer("space", EdgeConfig(space_view_radius_m=0.2))
    xy = {0: np.array([2.5, 0.25]), 1: np.array([3.9, 0.25])}
    got = successor_frontiers({0: 0, 1: 1}, fs, trav, CELL, xy, np.ones(3, bool), scorer, 3.0)
    assert got == {0: 2} or got == {1: 2}  # only one frontier is left for a successor


def test_the_edge_takes_an_adopted_successor_as_the_robots_goal() -> None:
    book = GoalBook(EdgeConfig())
    book.active[0] = ActiveGoal(1, (1.0, 1.0), (1.0, 1.2), 1.0)
    book.issued[1] = (1.0, 1.0, False)
    book.successors[0] = ActiveGoal(2, (3.0, 1.0), (3.0, 1.2), 0.0)
    book.issued[2] = (3.0, 1.0, False)
    book.on_status(GoalStatus(robot_id=0, tick=10, goal_id=1, status="reached"))
    assert 0 not in book.active
    book.on_status(GoalStatus(robot_id=0, tick=11, goal_id=2, status="active"))
    assert book.active[0].goal_id == 2 and 0 not in book.successors
    assert book.provisional == {0}  # the next plan scores it with the rest
    # a successor reported after a plan gave the robot another goal does not displace it
    book.successors[0] = ActiveGoal(3, (5.0, 1.0), (5.0, 1.2), 0.0)
    book.active[0] = ActiveGoal(4, (0.0, 0.0), (0.0, 0.2), 1.0)
    book.on_status(GoalStatus(robot_id=0, tick=20, goal_id=3, status="active"))
    assert book.active[0].goal_id == 4


def _goal(goal_id: int, queued: bool = False, cancel: bool = False) -> Goal:
    return Goal(robot_id=0, tick=1, goal_id=goal_id, x=1.0, y=2.0, frontier_class="unexplored",
                revenue=0.0, queued=queued, cancel=cancel)


def test_the_agent_adopts_its_queued_goal_only_when_a_goal_ends() -> None:
    core = AgentCore(AgentConfig(), 0, 0.1)
    core.on_goal(_goal(7, queued=True))
    assert core.goal is None and core.queued is not None  # kept, not driven to
    core._adopt_queued([StatusEvent(5, "active")])
    assert core.goal is None
    core._adopt_queued([StatusEvent(5, "reached")])
    assert core.goal is not None and core.goal.goal_id == 7 and not core.goal.queued
    assert core.queued is None
    core.goal = None
    core.on_goal(_goal(8, queued=True))
    core.on_goal(_goal(8, queued=True, cancel=True))  # withdrawn
    core._adopt_queued([StatusEvent(6, "invalid")])
    assert core.goal is None
    core.on_goal(_goal(9, queued=True))
    core.on_goal(_goal(10))  # a new goal from a plan replaces the successor too
    assert core.queued is None and core.goal is not None and core.goal.goal_id == 10
