"""Where each robot's time went (services/evaluator/explain.py) and events.jsonl's order."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from services.evaluator.explain import (
    coverage_tick,
    explain_robot,
    goal_spans,
    markdown,
    revisits,
    state_times,
    turned_away,
)
from services.launcher.report import ordered_events

TICK_S = 0.1


def _goal(tick: int, goal_id: int, cls: str = "unexplored", cancel: bool = False) -> dict:
    return {"tick": tick, "kind": "goal", "goal_id": goal_id, "frontier_class": cls,
            "cancel": cancel}


def _status(tick: int, goal_id: int, status: str) -> dict:
    return {"tick": tick, "kind": "status", "goal_id": goal_id, "status": status}


def test_each_goal_gets_one_outcome() -> None:
    events = [
        _goal(10, 0), _status(11, 0, "active"), _status(50, 0, "reached"),
        _goal(60, 1), _status(61, 1, "active"),
        _goal(80, 2, "weak"),  # 1 replaced before it ended
        _status(85, 1, "invalid"),  # a late status of the replaced goal: ignored
        _status(120, 2, "invalid"),
        _goal(130, 3), _goal(130, 3),  # re-sent: one goal
        _goal(150, 3, cancel=True),
        _goal(170, 4), _status(200, 4, "unreachable"),
        _goal(210, 5),
    ]
    spans = goal_spans(events, end_tick=300)
    assert [(s.goal_id, s.outcome, s.start_tick, s.end_tick) for s in spans] == [
        (0, "reached", 10, 50), (1, "replaced", 60, 80), (2, "invalid", 80, 120),
        (3, "cancelled", 130, 150), (4, "unreachable", 170, 200), (5, "open", 210, 300)]


def test_a_queued_goal_starts_when_the_agent_adopts_it() -> None:
    queued = {"queued": True}
    events = [
        _goal(10, 0), _status(11, 0, "active"),
        {**_goal(30, 1), **queued}, {**_goal(40, 2, "weak"), **queued},  # 2 replaces 1
        _status(50, 0, "reached"), _status(51, 2, "active"),
        {**_goal(60, 3), **queued}, {**_goal(70, 3, cancel=True), **queued},  # withdrawn
        _status(90, 2, "reached"),
        {**_goal(95, 4), **queued}, _goal(100, 5),  # a new goal clears the successor
        _status(101, 5, "active"), _status(120, 5, "reached"), _status(121, 4, "active"),
    ]
    spans = goal_spans(events, end_tick=200)
    assert [(s.goal_id, s.frontier_class, s.outcome, s.start_tick, s.end_tick)
            for s in spans] == [
        (0, "unexplored", "reached", 10, 50), (2, "weak", "reached", 51, 90),
        (5, "unexplored", "reached", 100, 120)]


def test_time_and_distance_split_by_outcome() -> None:
    # 1 m/s along x for 30 s, sampled every tick
    stamps = np.arange(0, 301) * TICK_S
    xy = np.stack([stamps, np.zeros_like(stamps)], axis=1)
    events = [_goal(0, 0), _status(100, 0, "reached"), _goal(150, 1, "weak"),
              _status(200, 1, "invalid"),
              {"tick": 0, "kind": "state", "state": "following"},
              {"tick": 100, "kind": "state", "state": "idle"},
              {"tick": 150, "kind": "state", "state": "turning"}]
    out = explain_robot(events, stamps, xy, end_tick=300, tick_s=TICK_S)
    assert out.goals == {"reached": 1, "invalid": 1}
    assert out.time_s["reached"] == pytest.approx(10.0)
    assert out.time_s["invalid"] == pytest.approx(5.0)
    assert out.time_s["no goal"] == pytest.approx(15.0)
    assert out.distance_m["reached"] == pytest.approx(10.0)
    assert out.distance_m["no goal"] == pytest.approx(15.0)
    assert out.total_distance_m == pytest.approx(30.0)
    assert out.class_time_s == pytest.approx({"unexplored": 10.0, "weak": 5.0})
    assert out.state_time_s == pytest.approx({"following": 10.0, "idle": 5.0, "turning": 15.0})
    table = markdown({0: out})
    assert "10 / 10.0" in table and "reached 1, invalid 1" in table


def test_a_window_counts_only_what_lies_after_its_start() -> None:
    stamps = np.arange(0, 301) * TICK_S  # 1 m/s along x for 30 s
    xy = np.stack([stamps, np.zeros_like(stamps)], axis=1)
    events = [_goal(0, 0), _status(100, 0, "reached"), _goal(110, 1), _status(140, 1, "invalid"),
              _goal(150, 2, "weak"), _status(200, 2, "invalid"),
              {"tick": 0, "kind": "state", "state": "following"},
              {"tick": 100, "kind": "state", "state": "idle"},
              {"tick": 150, "kind": "state", "state": "turning"}]
    out = explain_robot(events, stamps, xy, end_tick=300, tick_s=TICK_S, start_tick=120)
    # goal 0 ended before the window; goal 1 reaches into it: its last 2 s count
    assert out.goals == {"invalid": 2}
    assert out.time_s["invalid"] == pytest.approx(2.0 + 5.0)
    assert out.time_s["no goal"] == pytest.approx(18.0 - 7.0)
    assert out.total_time_s == pytest.approx(18.0)
    assert out.total_distance_m == pytest.approx(18.0)
    assert out.distance_m["invalid"] == pytest.approx(7.0)
    assert out.class_time_s == pytest.approx({"unexplored": 2.0, "weak": 5.0})
    assert out.state_time_s == pytest.approx({"idle": 3.0, "turning": 15.0})
    whole = explain_robot(events, stamps, xy, end_tick=300, tick_s=TICK_S)
    assert whole.goals == {"reached": 1, "invalid": 2} and whole.total_time_s == 30.0


def test_coverage_tick_is_the_first_sample_at_the_level() -> None:
    series = [{"sim_time_s": 5.0, "coverage_3d_pct": 40.0},
              {"sim_time_s": 10.0, "coverage_3d_pct": None},
              {"sim_time_s": 15.0, "coverage_3d_pct": 95.5},
              {"sim_time_s": 20.0, "coverage_3d_pct": 94.0}]
    assert coverage_tick(series, 95.0, TICK_S) == 150
    assert coverage_tick(series, 40.0, TICK_S) == 50
    assert coverage_tick(series, 96.0, TICK_S) is None


def test_state_times_end_at_the_mission_end() -> None:
    events = [{"tick": 5, "kind": "state", "state": "idle"}]
    assert state_times(events, 25, TICK_S) == pytest.approx({"idle": 2.0})


def test_events_are_ordered_by_tick_not_arrival() -> None:
    """A goal's end and the next goal of the same tick: the end first, whatever arrived
    first; events after the mission's end are left out."""
    track = SimpleNamespace(events=[_goal(40, 2), _status(40, 1, "reached"), _goal(10, 1),
                                    _goal(90, 3)])
    monitor = SimpleNamespace(tracks={0: track})
    out = ordered_events(monitor, end_tick=50)
    assert [(e["tick"], e["kind"]) for e in out] == [(10, "goal"), (40, "status"),
                                                     (40, "goal")]
    assert all(e["robot"] == 0 for e in out)


def test_revisits_count_reached_goals_at_a_place_reached_before() -> None:
    def goal(tick: int, robot: int, goal_id: int, x: float, y: float) -> dict:
        return {**_goal(tick, goal_id), "robot": robot, "x": x, "y": y}

    def status(tick: int, robot: int, goal_id: int, s: str) -> dict:
        return {**_status(tick, goal_id, s), "robot": robot}

    events = [goal(10, 0, 0, 1.0, 1.0), status(20, 0, 0, "reached"),
              goal(10, 1, 1, 1.2, 1.0), status(30, 1, 1, "reached"),  # teammate, same place
              goal(40, 0, 2, 3.0, 1.0), status(50, 0, 2, "invalid"),
              goal(60, 0, 3, 3.0, 1.1), status(70, 0, 3, "reached"),  # first reach there
              goal(80, 1, 4, 1.0, 1.4), status(90, 1, 4, "reached")]  # back again
    assert revisits(events) == (2, 4)
    assert revisits(events, radius_m=0.1) == (0, 4)
    assert revisits([]) == (0, 0)


def test_turned_away_counts_replaced_goals_whose_place_came_back() -> None:
    def goal(tick: int, robot: int, goal_id: int, x: float) -> dict:
        return {**_goal(tick, goal_id), "robot": robot, "x": x, "y": 0.0}

    events = [goal(10, 0, 0, 1.0),
              goal(20, 0, 1, 5.0),  # replaced, 4 m away: ...
              goal(30, 1, 2, 1.3),  # ... and its place given again: churn
              goal(40, 0, 3, 5.5),  # replaced by one 0.5 m away: not counted
              goal(50, 0, 4, 9.0)]  # replaced, 3.5 m away, never given again
    assert turned_away(events) == (1, 2)
    assert turned_away(events, min_m=5.0) == (0, 0)
    assert turned_away([]) == (0, 0)


def test_stalled_counts_following_without_moving() -> None:
    """10 s following: 4 s driving at 1 m/s, then 6 s against something; the first second of
    the stall still sees the drive behind it. Turning in place is not a stall."""
    stamps = np.arange(0, 151) * TICK_S
    x = np.minimum(stamps, 4.0)
    xy = np.stack([x, np.zeros_like(x)], axis=1)
    events = [{"tick": 0, "kind": "state", "state": "following"},
              {"tick": 100, "kind": "state", "state": "turning"}]
    out = explain_robot(events, stamps, xy, end_tick=150, tick_s=TICK_S)
    assert out.stalled_s == pytest.approx(5.0, abs=0.15)  # 5.0-10.0 s
    assert "(stalled 5)" in markdown({0: out})
