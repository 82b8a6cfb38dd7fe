"""The exploration-complete verdict, and where robots have already looked from close by.

Complete when no assignable frontier has been left for `complete_after_plans` consecutive plans,
the grid knows at least `complete_min_known_cells` cells, and at least `complete_warmup_s` of sim
time has passed (robots spin in place at the start and the map is still nearly empty). The
verdict is sticky: the mission's mapping time is the first plan that reached it.

"Assignable" excludes F_w regions a robot's camera has already covered from within
`weak_visit_range_m` (`VisitLog`): a surface that stays noisy after a close look is not improved
by another one, and without this rule weak regions keep goals alive forever.
"""

from __future__ import annotations

import math

import numpy as np

from services.edge_server.config import EdgeConfig


class VisitLog:
    """Robot viewpoints (x, y, heading), one per robot and plan once it moved or turned."""

    def __init__(self, range_m: float, fov_rad: float, min_step_m: float = 0.25,
                 min_turn_rad: float = 0.3) -> None:
        self.range_m = range_m
        self.half_fov = fov_rad / 2
        self.min_step_m = min_step_m
        self.min_turn_rad = min_turn_rad
        self.views = np.zeros((0, 3))
        self._last: dict[int, tuple[float, float, float]] = {}

    def record(self, robot_id: int, x: float, y: float, heading: float) -> None:
        last = self._last.get(robot_id)
        if last is not None:
            turn = abs(math.remainder(heading - last[2], math.tau))
            if math.hypot(x - last[0], y - last[1]) < self.min_step_m and turn < self.min_turn_rad:
                return  # a near-duplicate viewpoint: keeps the log small
        self._last[robot_id] = (x, y, heading)
        self.views = np.vstack([self.views, [x, y, heading]])

    def seen(self, xy_world: np.ndarray) -> np.ndarray:
        """(F,) bool: points inside some viewpoint's horizontal FoV and within range."""
        xy_world = np.asarray(xy_world, np.float64).reshape(-1, 2)
        if not len(self.views) or not len(xy_world):
            return np.zeros(len(xy_world), bool)
        d = xy_world[:, None, :] - self.views[None, :, :2]
        dist = np.hypot(d[..., 0], d[..., 1])
        bearing = np.arctan2(d[..., 1], d[..., 0]) - self.views[None, :, 2]
        off = np.abs(np.remainder(bearing + np.pi, 2 * np.pi) - np.pi)
        return ((dist <= self.range_m) & (off <= self.half_fov)).any(axis=1)


class CompletionJudge:
    def __init__(self, config: EdgeConfig, tick_s: float) -> None:
        self.config = config
        self.tick_s = tick_s
        self.empty_plans = 0
        self.tail_plans = 0
        self.complete = False
        self.complete_tick: int | None = None

    def update(self, tick: int, assignable_frontiers: int, known_cells: int,
               unexplored_fraction: float | None = None, edge_ticks: int = 1) -> bool:
        """Record one plan's outcome; returns the (sticky) verdict. `unexplored_fraction`:
        the assignable F_u regions' voxels over the merged map's (None: not asked, as in a
        grid-fallback plan). `edge_ticks`: the edge ticks this plan stands for (the ones
        skipped since the last plan, plus its own), so the counts stay in edge ticks."""
        if self.complete:
            return True
        cfg = self.config
        self.empty_plans = self.empty_plans + edge_ticks if assignable_frontiers == 0 else 0
        tail = (cfg.complete_unexplored_fraction > 0 and unexplored_fraction is not None
                and unexplored_fraction <= cfg.complete_unexplored_fraction)
        self.tail_plans = self.tail_plans + edge_ticks if tail else 0
        if (
            (self.empty_plans >= cfg.complete_after_plans
             or self.tail_plans >= cfg.complete_unexplored_plans)
            and known_cells >= cfg.complete_min_known_cells
            and tick * self.tick_s >= cfg.complete_warmup_s
        ):
            self.complete = True
            self.complete_tick = tick
        return self.complete
