"""The unknown floor a goal looks into (visible_unknown.py) and the `space` term built on it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from services.common.grid import GridSpec
from services.edge_server.assignment import make_scorer
from services.edge_server.config import EdgeConfig
from services.edge_server.coordination import RobotStates
from services.edge_server.frontiers import FrontierSet
from services.edge_server.visible_unknown import live_unknown, visible_unknown_m2

SPEC = GridSpec(0.0, 0.0, 0.05, 200, 200)
CENTRE = np.array([[100, 100]])


def room(radius_m: float, door_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Known free disk of `radius_m` around the centre cell, walled by a ring one cell
    thick, with an opening of `door_rad` radians facing +x; unknown outside."""
    rows, cols = np.mgrid[:200, :200]
    r = np.hypot(rows - 100, cols - 100) * SPEC.resolution_m
    bearing = np.abs(np.arctan2(rows - 100, cols - 100))
    ring = (r >= radius_m) & (r < radius_m + 0.07)
    occupied = ring & (bearing > door_rad / 2)
    known = (r < radius_m) | occupied
    return occupied, known


def test_open_unknown_floor_is_the_disk_in_range() -> None:
    nothing = np.zeros((200, 200), bool)
    area = visible_unknown_m2(nothing, ~nothing, CENTRE, SPEC, 3.0)
    assert area[0] == pytest.approx(math.pi * 9.0, rel=0.05)


def test_a_closed_room_hides_the_unknown_behind_its_walls_and_a_door_shows_it() -> None:
    occupied, known = room(1.0)
    closed = visible_unknown_m2(occupied, ~known, CENTRE, SPEC, 3.0)[0]
    assert closed < 0.3  # cells the ring's rasterisation misses, no more
    occupied, known = room(1.0, door_rad=math.pi / 2)
    opened = visible_unknown_m2(occupied, ~known, CENTRE, SPEC, 3.0)[0]
    # a quarter of the annulus from 1 m to 3 m
    assert opened == pytest.approx(math.pi * (9.0 - 1.0) / 4, rel=0.15)


def test_only_unknown_behind_a_long_frontier_is_live() -> None:
    """The unknown beyond a door is live; with the door shut the same unknown is not (a
    cabinet's inside, the world behind a wall seen whole), and neither is a door narrower
    than the minimum frontier."""
    occupied, known = room(1.0, door_rad=math.pi / 2)
    free = known & ~occupied
    live = live_unknown(free, known, 10)
    assert live[100, 180] and not live[100, 100]
    assert visible_unknown_m2(occupied, live, CENTRE, SPEC, 3.0)[0] > 5.0
    occupied, known = room(1.0)
    assert not live_unknown(known & ~occupied, known, 10).any()
    occupied, known = room(1.0, door_rad=0.3)  # 0.3 m of frontier: 6 cells
    assert not live_unknown(known & ~occupied, known, 40).any()


def test_no_goals_no_gain() -> None:
    nothing = np.zeros((200, 200), bool)
    assert visible_unknown_m2(nothing, nothing, np.zeros((0, 2), np.int64), SPEC, 3.0).shape \
        == (0,)


def test_space_with_the_view_gain_goes_to_the_door() -> None:
    """Two equal regions at equal distance: the one looking into unknown floor wins, unless a
    teammate's goal is already there."""
    xy = np.array([[2.0, 0.0], [-2.0, 0.0]])
    fs = FrontierSet(labels=np.zeros((1, 1), np.int32), sizes=np.full(2, 10), centroid_xy=xy,
                     anchor_rc=np.zeros((2, 2), np.int64), anchor_xy=xy,
                     goal_rc=np.zeros((2, 2), np.int64), goal_xy=xy, weak=np.zeros(2, bool),
                     gain=np.ones(2), importance=np.ones(2),
                     unknown_view_m2=np.array([0.0, 6.0]))
    path = np.array([[2.0, 2.0]])
    robot = RobotStates(np.zeros((1, 2)), np.array([math.pi / 2]), np.zeros((0, 2)))
    plain = make_scorer("space", EdgeConfig(space_view_gain_per_m2=0.0)).score(path, fs, robot)
    assert plain[0, 0] == plain[0, 1]
    scorer = make_scorer("space", EdgeConfig(space_view_gain_per_m2=0.1))
    assert int(np.argmax(scorer.score(path, fs, robot)[0])) == 1
    held = RobotStates(np.zeros((1, 2)), np.array([math.pi / 2]), np.array([[-2.5, 0.0]]))
    assert int(np.argmax(scorer.score(path, replace(fs), held)[0])) == 0
