"""Where each robot's time and distance went (issue 12): a pure reading of a run's events.

A run folder's `events.jsonl` holds, per robot and in tick order, the goals the edge sent,
the statuses the agent reported and the agent's navigation state changes (what the monitor
saw on the bus). Each goal is given one outcome:

- `reached`, `invalid` (the adaptive validator gave up), `unreachable` (no path): the agent's
  first terminal status for it;
- `cancelled`: the edge withdrew it (`Goal.cancel`);
- `replaced`: the edge sent another goal before it ended (re-assignment churn);
- `open`: still active when the mission ended.

A goal's span runs from its assignment to that outcome; the robot's distance over the span
comes from its ground-truth path (the evaluator's, never the agents'). Time without a goal
is `no goal`. States (`idle` = spinning with no goal, `turning`, `following`) are summed
from their changes; `stalled` is the part of `following` in which the true position moved
less than 1 cm over the last second (pushing at what the camera missed, or yielding to a
teammate: docs/agent.md, "Blocked by what the camera misses").

With a window start (`start_tick`), every figure covers only the ticks from there to the end:
spans, states and distances are clipped to it, and a goal counts when its span reaches into
it (`spacemap eval --explain --from-coverage P`: the mission after the 3D coverage first
reached P %, where the tail's time goes).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

OUTCOMES = ("reached", "invalid", "unreachable", "cancelled", "replaced", "open")
TERMINAL = ("reached", "invalid", "unreachable")


@dataclass
class Span:
    """One goal from assignment to outcome."""

    goal_id: int
    frontier_class: str
    start_tick: int
    end_tick: int = -1
    outcome: str = "open"


@dataclass
class RobotExplain:
    """A robot's time (s) and distance (m) by goal outcome, goal class and state."""

    goals: Counter[str] = field(default_factory=Counter)  # outcome → count
    time_s: dict[str, float] = field(default_factory=dict)  # outcome or "no goal" → s
    distance_m: dict[str, float] = field(default_factory=dict)  # same keys → m
    class_time_s: dict[str, float] = field(default_factory=dict)  # frontier class → s
    state_time_s: dict[str, float] = field(default_factory=dict)  # nav state → s
    stalled_s: float = 0.0  # "following" without moving (1 cm over 1 s)
    total_time_s: float = 0.0
    total_distance_m: float = 0.0


def goal_spans(events: Sequence[dict[str, Any]], end_tick: int) -> list[Span]:
    """Every goal of one robot's tick-ordered events, with its outcome and end tick. A
    queued goal (a successor) starts when the agent reports it active."""
    spans: list[Span] = []
    current: Span | None = None
    queued: dict[int, str] = {}  # successor goal id → frontier class
    for ev in events:
        tick = int(ev["tick"])
        if ev["kind"] == "goal" and ev.get("queued"):
            if ev.get("cancel"):
                queued.pop(int(ev["goal_id"]), None)
            else:
                queued = {int(ev["goal_id"]): str(ev.get("frontier_class", ""))}
            continue
        if ev["kind"] == "status" and ev["status"] == "active" and ev["goal_id"] in queued:
            if current is not None:
                current.end_tick, current.outcome = tick, "replaced"
            current = Span(int(ev["goal_id"]), queued.pop(int(ev["goal_id"])), tick)
            spans.append(current)
            continue
        if ev["kind"] == "goal":
            if ev.get("cancel"):
                if current is not None and current.goal_id == ev["goal_id"]:
                    current.end_tick, current.outcome, current = tick, "cancelled", None
                continue
            if current is not None and current.goal_id == ev["goal_id"]:
                continue  # the same goal re-sent
            queued = {}  # a new goal replaces the agent's successor too
            if current is not None:
                current.end_tick, current.outcome = tick, "replaced"
            current = Span(int(ev["goal_id"]), str(ev.get("frontier_class", "")), tick)
            spans.append(current)
        elif (ev["kind"] == "status" and ev["status"] in TERMINAL and current is not None
              and current.goal_id == ev["goal_id"]):
            current.end_tick, current.outcome, current = tick, ev["status"], None
    if current is not None:
        current.end_tick = end_tick
    return spans


def path_length(stamps_s: np.ndarray, xy: np.ndarray, t0: float, t1: float) -> float:
    """Metres driven between sim times t0 and t1 along a sampled path."""
    if len(xy) < 2 or t1 <= t0:
        return 0.0
    seg = np.hypot(*np.diff(xy, axis=0).T)
    inside = (stamps_s[1:] > t0) & (stamps_s[1:] <= t1)
    return float(seg[inside].sum())


def state_times(events: Sequence[dict[str, Any]], end_tick: int, tick_s: float,
                start_tick: int = 0) -> dict[str, float]:
    """Seconds in each navigation state from `start_tick` to `end_tick`, from the state
    changes."""
    out: Counter[str] = Counter()
    changes = [(int(e["tick"]), str(e["state"])) for e in events if e["kind"] == "state"]
    for (tick, state), (next_tick, _) in zip(changes, changes[1:] + [(end_tick, "")],
                                             strict=True):
        ticks = min(next_tick, end_tick) - max(tick, start_tick)
        if start_tick == 0 or next_tick > start_tick:  # wholly before the window: not listed
            out[state or "unknown"] += max(ticks, 0) * tick_s
    return dict(out)


def stalled_time(events: Sequence[dict[str, Any]], stamps_s: np.ndarray, xy: np.ndarray,
                 tick_s: float, window_s: float = 1.0, min_move_m: float = 0.01,
                 start_s: float = -np.inf) -> float:
    """Seconds of the true path's samples (after `start_s`) in state "following" whose
    position is within `min_move_m` of where it was `window_s` earlier."""
    changes = [(int(e["tick"]) * tick_s, str(e["state"])) for e in events
               if e["kind"] == "state"]
    if len(xy) < 2 or not changes:
        return 0.0
    times = np.array([t for t, _ in changes])
    following = np.array([state == "following" for _, state in changes])
    at = np.searchsorted(times, stamps_s + 1e-9, side="right") - 1
    now_following = np.where(at >= 0, following[np.maximum(at, 0)], False)
    back = np.maximum(np.searchsorted(stamps_s, stamps_s - window_s + 1e-9, side="right") - 1, 0)
    still = (stamps_s - stamps_s[back] >= window_s - 1e-6) & (
        np.hypot(*(xy - xy[back]).T) < min_move_m)
    step = float(np.median(np.diff(stamps_s)))
    return float(np.count_nonzero(now_following & still & (stamps_s > start_s)) * step)


def explain_robot(events: Sequence[dict[str, Any]], stamps_s: np.ndarray, xy: np.ndarray,
                  end_tick: int, tick_s: float, start_tick: int = 0) -> RobotExplain:
    """One robot's breakdown from `start_tick` to `end_tick`; `stamps_s`, `xy` its true path
    (N,), (N, 2)."""
    start_s = start_tick * tick_s
    out = RobotExplain(state_time_s=state_times(events, end_tick, tick_s, start_tick),
                       stalled_s=stalled_time(events, stamps_s, xy, tick_s,
                                              start_s=start_s if start_tick else -np.inf))
    out.total_time_s = (end_tick - start_tick) * tick_s
    out.total_distance_m = path_length(stamps_s, xy, start_s if start_tick else -1.0,
                                       end_tick * tick_s)
    time, dist, cls = Counter(), Counter(), Counter()
    covered = 0.0
    for span in goal_spans(events, end_tick):
        t0, t1 = max(span.start_tick, start_tick) * tick_s, span.end_tick * tick_s
        if span.end_tick <= start_tick:
            continue
        out.goals[span.outcome] += 1
        time[span.outcome] += t1 - t0
        dist[span.outcome] += path_length(stamps_s, xy, t0, t1)
        cls[span.frontier_class] += t1 - t0
        covered += t1 - t0
    time["no goal"] = max(out.total_time_s - covered, 0.0)
    dist["no goal"] = max(out.total_distance_m - sum(dist.values()), 0.0)
    out.time_s, out.distance_m, out.class_time_s = dict(time), dict(dist), dict(cls)
    return out


def markdown(per_robot: dict[int, RobotExplain]) -> str:
    """Two tables: time / distance by goal outcome, and goals, classes and states."""
    keys = [*OUTCOMES, "no goal"]
    head = "| robot | " + " | ".join(keys) + " | total |"
    lines = ["Time s / distance m by goal outcome (a goal's span: assignment to outcome)", "",
             head, "|---|" + "---:|" * (len(keys) + 1)]
    for robot, r in per_robot.items():
        cells = [f"{r.time_s.get(k, 0.0):.0f} / {r.distance_m.get(k, 0.0):.1f}" for k in keys]
        lines.append(f"| {robot} | " + " | ".join(cells)
                     + f" | {r.total_time_s:.0f} / {r.total_distance_m:.1f} |")
    lines += ["", "| robot | goals by outcome | time by frontier class s | time by state s |",
              "|---|---|---|---|"]
    for robot, r in per_robot.items():
        goals = ", ".join(f"{k} {r.goals[k]}" for k in OUTCOMES if r.goals[k])
        classes = ", ".join(f"{k} {v:.0f}" for k, v in sorted(r.class_time_s.items()))
        states = ", ".join(f"{k} {v:.0f}" for k, v in sorted(r.state_time_s.items()))
        states += f" (stalled {r.stalled_s:.0f})"
        lines.append(f"| {robot} | {goals} | {classes} | {states} |")
    return "\n".join(lines) + "\n"


def revisits(events: Sequence[dict[str, Any]], radius_m: float = 0.5) -> tuple[int, int]:
    """(reached goals within `radius_m` of a goal reached earlier by any robot, reached goals):
    trips back to a place a visit did not clear."""
    where = {(e["robot"], e["goal_id"]): (float(e["x"]), float(e["y"]))
             for e in events if e["kind"] == "goal" and not e.get("cancel")}
    reached = [where[key] for e in sorted(events, key=lambda e: int(e["tick"]))
               if e["kind"] == "status" and e["status"] == "reached"
               and (key := (e["robot"], e["goal_id"])) in where]
    xy = np.array(reached).reshape(-1, 2)
    again = sum(bool((np.hypot(*(xy[:i] - xy[i]).T) < radius_m).any()) for i in range(len(xy)))
    return again, len(xy)


def turned_away(events: Sequence[dict[str, Any]], min_m: float = 1.0, radius_m: float = 0.75
                ) -> tuple[int, int]:
    """(replaced goals whose place a goal of any robot got again later, goals replaced by one
    at least `min_m` away): robots turned from a region nobody had seen yet (churn)."""
    goals = sorted((int(e["tick"]), int(e["robot"]), int(e["goal_id"]), float(e["x"]),
                     float(e["y"])) for e in events
                    if e["kind"] == "goal" and not e.get("cancel") and not e.get("queued"))
    where = {(r, g): (x, y) for _, r, g, x, y in goals}
    end = max((int(e["tick"]) for e in events), default=0)
    away = again = 0
    for robot in sorted({r for _, r, _, _, _ in goals}):
        spans = goal_spans(sorted((e for e in events if e.get("robot") == robot),
                                  key=lambda e: int(e["tick"])), end)
        for old, new in zip(spans[:-1], spans[1:], strict=True):
            a, b = where.get((robot, old.goal_id)), where.get((robot, new.goal_id))
            if old.outcome != "replaced" or a is None or b is None or np.hypot(
                    b[0] - a[0], b[1] - a[1]) < min_m:
                continue
            away += 1
            again += any(t > old.end_tick and np.hypot(x - a[0], y - a[1]) < radius_m
                         for t, _, _, x, y in goals)
    return again, away


def explain_events(events: Sequence[dict[str, Any]],
                   tracks: Sequence[tuple[np.ndarray, np.ndarray]], end_tick: int,
                   tick_s: float, start_tick: int = 0) -> dict[int, RobotExplain]:
    """Every robot's breakdown from a run's events (each with a "robot") and true paths."""
    return {robot: explain_robot([e for e in events if e.get("robot") == robot], stamps, xy,
                                 end_tick, tick_s, start_tick)
            for robot, (stamps, xy) in enumerate(tracks)}


def coverage_tick(series: Sequence[dict[str, Any]], pct: float, tick_s: float) -> int | None:
    """The tick of the first time-series sample whose 3D coverage is at least `pct` (None:
    never reached)."""
    for row in series:
        value = row.get("coverage_3d_pct")
        if value is not None and float(value) >= pct:
            return round(float(row["sim_time_s"]) / tick_s)
    return None
