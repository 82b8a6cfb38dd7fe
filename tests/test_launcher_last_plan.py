"""_await_last_plan: a capped run reads on until the last edge tick's plan is out."""

from __future__ import annotations

from collections import OrderedDict
from types import SimpleNamespace
from typing import Any

from schemas import messages as m
from schemas.keys import Keys
from services.common.bus import Inbound
from services.launcher.monitor import Monitor
from services.launcher.run import _await_last_plan


class FakeMonitor:
    """The edge's acknowledgement of each tick in `arrivals` arrives, one per pump."""

    def __init__(self, clock_tick: int, arrivals: list[int]) -> None:
        self.clock = SimpleNamespace(tick=clock_tick)
        self.recent_acks: OrderedDict[int, bool] = OrderedDict()
        self.arrivals = arrivals
        self.pumps = 0

    def pump(self, timeout: float) -> None:
        self.pumps += 1
        if self.arrivals:
            self.recent_acks[self.arrivals.pop(0)] = True


def test_reads_until_the_last_edge_tick_is_acknowledged() -> None:
    monitor = FakeMonitor(1203, [1190, 1200, 1210])
    _await_last_plan(monitor, 10)  # type: ignore[arg-type]
    assert 1200 in monitor.recent_acks and 1210 not in monitor.recent_acks


def test_gives_up_at_the_deadline_when_the_edge_never_plans() -> None:
    monitor = FakeMonitor(1200, [])
    _await_last_plan(monitor, 10, timeout_s=0.0)  # type: ignore[arg-type]
    assert monitor.recent_acks == {}


class _Bus:
    """Just what Monitor's constructor declares (no zenoh: messages are handed in)."""

    keys = Keys()

    def __getattr__(self, name: str) -> Any:
        return lambda *args, **kwargs: None


def test_the_monitor_takes_a_tick_as_planned_at_its_acknowledgement() -> None:
    """The edge acknowledges a tick after its frontiers and goals: the frontiers alone do
    not mark the tick, so the goals sent after them are waited for too."""
    monitor = Monitor(_Bus(), robots=1)  # type: ignore[arg-type]
    keys = _Bus.keys
    frontiers = m.Frontiers(tick=200, frontiers=[], complete=False)
    monitor._handle(Inbound(keys.map_frontiers(), frontiers))
    assert 200 not in monitor.recent_acks
    goal = m.Goal(robot_id=0, tick=200, goal_id=1, x=1.0, y=2.0,
                  frontier_class="unexplored", revenue=0.5)
    monitor._handle(Inbound(keys.goal(0), goal))
    monitor._handle(Inbound(keys.edge_ack(), m.EdgeAck(tick=200)))
    assert 200 in monitor.recent_acks
    assert monitor.tracks[0].events[-1]["goal_id"] == 1
