"""The exploration-complete verdict.

Complete when no assignable frontier has been left for `complete_after_plans` consecutive plans,
the grid knows at least `complete_min_known_cells` cells, and at least `complete_warmup_s` of sim
time has passed (robots spin in place at the start and the map is still nearly empty). The
verdict is sticky: the mission's mapping time is the first plan that reached it.
"""

from __future__ import annotations

from services.edge_server.config import EdgeConfig


class CompletionJudge:
    def __init__(self, config: EdgeConfig, tick_s: float) -> None:
        self.config = config
        self.tick_s = tick_s
        self.empty_plans = 0
        self.complete = False
        self.complete_tick: int | None = None

    def update(self, tick: int, assignable_frontiers: int, known_cells: int) -> bool:
        """Record one plan's outcome; returns the (sticky) verdict."""
        if self.complete:
            return True
        self.empty_plans = self.empty_plans + 1 if assignable_frontiers == 0 else 0
        if (
            self.empty_plans >= self.config.complete_after_plans
            and known_cells >= self.config.complete_min_known_cells
            and tick * self.tick_s >= self.config.complete_warmup_s
        ):
            self.complete = True
            self.complete_tick = tick
        return self.complete
