"""Pluggable frontier scoring and a one-robot-per-frontier greedy assignment.

A `Scorer` turns path lengths (robots × frontiers) into scores, higher is better; a registry
keyed by `EdgeConfig.planner` picks one: "nearest" (Yamauchi: shortest path), "utility"
(explore_lite: gain_scale·size − potential_scale·path, greedy), "rrt" (rrt_exploration's
frontiers, scored like "utility"), "space-paper" (the paper as written: revenue
U = I_t·I_g / (κ·h), each robot its maximum) and "space" (the same quantities coordinated and
costed in time: coordination.py). Each scorer also names its matcher: greedy or joint.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

import numpy as np

from services.edge_server.config import EdgeConfig
from services.edge_server.coordination import RobotStates, coordinated_revenue, joint_match
from services.edge_server.frontiers import FrontierSet
from services.edge_server.importance import revenue

log = logging.getLogger(__name__)


class Scorer(Protocol):
    name: str

    def score(self, path_m: np.ndarray, frontiers: FrontierSet, robots: RobotStates
              ) -> np.ndarray:
        """(R, F) scores from (R, F) path lengths in metres (inf = unreachable)."""
        ...

    def match(self, scores: np.ndarray) -> dict[int, int]:
        """Row (robot) → column (frontier) pairs from the (R, F) scores."""
        ...


class _Greedy:
    """Each robot its maximum, best first (every planner of the paper's comparison)."""

    @staticmethod
    def match(scores: np.ndarray) -> dict[int, int]:
        return greedy_match(scores)


class NearestScorer(_Greedy):
    """Nearest frontier by path length (Yamauchi)."""

    name = "nearest"

    def score(self, path_m: np.ndarray, frontiers: FrontierSet, robots: RobotStates
              ) -> np.ndarray:
        return -path_m


class UtilityScorer(_Greedy):
    """explore_lite's greedy cost, negated: gain_scale·frontier size (m) − potential·path (m)."""

    name = "utility"

    def __init__(self, config: EdgeConfig) -> None:
        self.gain_scale = config.utility_gain_scale
        self.potential_scale = config.utility_potential_scale
        self.resolution_m = config.grid_resolution_m

    def score(self, path_m: np.ndarray, frontiers: FrontierSet, robots: RobotStates
              ) -> np.ndarray:
        size_m = frontiers.sizes * self.resolution_m
        return self.gain_scale * size_m[None, :] - self.potential_scale * path_m


class SpacePaperScorer(_Greedy):
    """The paper's revenue U(r_i, f′) = I_t(f)·I_g(f) / (κ·h(p_i, p_f′)), as written."""

    name = "space-paper"

    def __init__(self, config: EdgeConfig) -> None:
        self.kappa = config.revenue_kappa
        self.min_path_m = config.revenue_min_path_m

    def score(self, path_m: np.ndarray, frontiers: FrontierSet, robots: RobotStates
              ) -> np.ndarray:
        n = len(frontiers)
        gain = frontiers.gain if frontiers.gain is not None else np.ones(n)
        imp = frontiers.importance if frontiers.importance is not None else np.ones(n)
        return revenue(imp, gain, path_m, self.kappa, self.min_path_m)


class SpaceScorer:
    """SPACE's I_t and I_g per second of travel, teammates' views discounted, solved jointly."""

    name = "space"

    def __init__(self, config: EdgeConfig) -> None:
        self.config = config

    def score(self, path_m: np.ndarray, frontiers: FrontierSet, robots: RobotStates
              ) -> np.ndarray:
        c = self.config
        return coordinated_revenue(
            path_m, frontiers, robots, v_mps=c.nav_v_mps, omega_radps=c.nav_omega_radps,
            view_radius_m=c.space_view_radius_m, teammate_discount=c.space_teammate_discount,
            min_time_s=c.revenue_min_path_m / c.nav_v_mps, grid_gain_per_m=c.space_grid_gain_per_m,
            grid_view_m=c.space_grid_view_m,
            teammate_radius_m=c.space_teammate_radius_m or c.space_view_radius_m,
            size_exponent=c.space_size_exponent,
            size_ref=float(c.space_size_ref_voxels or c.unexplored_min_voxels),
            partition_discount=c.space_partition_discount, time_exponent=c.space_time_exponent,
            view_gain_per_m2=c.space_view_gain_per_m2, view_range_m=c.space_view_range_m)

    def match(self, scores: np.ndarray) -> dict[int, int]:
        return joint_match(scores) if self.config.space_joint else greedy_match(scores)


SCORERS: dict[str, Callable[[EdgeConfig], Scorer]] = {
    "nearest": lambda _config: NearestScorer(),
    "utility": UtilityScorer,
    "rrt": UtilityScorer,
    "space-paper": SpacePaperScorer,
    "space": SpaceScorer,
}


def make_scorer(planner: str, config: EdgeConfig | None = None) -> Scorer:
    """The scorer registered for `planner`."""
    return SCORERS[planner](config or EdgeConfig())


def greedy_match(scores: np.ndarray) -> dict[int, int]:
    """Row → column pairs, best score first, each row and column used once; -inf never used.

    Ties go to the lowest (row, column), so the result is deterministic.
    """
    scores = np.array(scores, dtype=np.float64)
    pairs: dict[int, int] = {}
    for _ in range(min(scores.shape) if scores.size else 0):
        flat = int(np.argmax(scores))  # first maximum in row-major order
        r, f = divmod(flat, scores.shape[1])
        if not np.isfinite(scores[r, f]):
            break
        pairs[r] = f
        scores[r, :] = -np.inf
        scores[:, f] = -np.inf
    return pairs
