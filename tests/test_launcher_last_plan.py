"""_await_last_plan: a capped run reads on until the last edge tick's plan is out."""

from __future__ import annotations

from collections import OrderedDict
from types import SimpleNamespace

from services.launcher.run import _await_last_plan


class FakeMonitor:
    """Frontiers of each tick in `arrivals` arrive one per pump."""

    def __init__(self, clock_tick: int, arrivals: list[int]) -> None:
        self.clock = SimpleNamespace(tick=clock_tick)
        self.recent_frontiers: OrderedDict[int, int] = OrderedDict()
        self.arrivals = arrivals
        self.pumps = 0

    def pump(self, timeout: float) -> None:
        self.pumps += 1
        if self.arrivals:
            self.recent_frontiers[self.arrivals.pop(0)] = 0


def test_reads_until_the_frontiers_of_the_last_edge_tick() -> None:
    monitor = FakeMonitor(1203, [1190, 1200, 1210])
    _await_last_plan(monitor, 10)  # type: ignore[arg-type]
    assert 1200 in monitor.recent_frontiers and 1210 not in monitor.recent_frontiers


def test_gives_up_at_the_deadline_when_the_edge_never_plans() -> None:
    monitor = FakeMonitor(1200, [])
    _await_last_plan(monitor, 10, timeout_s=0.0)  # type: ignore[arg-type]
    assert monitor.recent_frontiers == {}
