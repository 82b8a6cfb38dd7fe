"""Pluggable frontier scoring and a one-robot-per-frontier greedy assignment.

A `Scorer` turns path lengths (robots × frontiers) into scores, higher is better; a registry
keyed by `EdgeConfig.planner` picks one. Only "nearest" (Yamauchi: shortest path) exists so
far; "space", "utility" and "rrt" use it until their own scorers land.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

import numpy as np

from services.edge_server.frontiers import FrontierSet

log = logging.getLogger(__name__)


class Scorer(Protocol):
    name: str

    def score(self, path_m: np.ndarray, frontiers: FrontierSet) -> np.ndarray:
        """(R, F) scores from (R, F) path lengths in metres (inf = unreachable)."""
        ...


class NearestScorer:
    """Nearest frontier by path length (Yamauchi)."""

    name = "nearest"

    def score(self, path_m: np.ndarray, frontiers: FrontierSet) -> np.ndarray:
        return -path_m


SCORERS: dict[str, Callable[[], Scorer]] = {"nearest": NearestScorer}
PLACEHOLDERS = {"space": "nearest", "utility": "nearest", "rrt": "nearest"}


def make_scorer(planner: str) -> Scorer:
    """The scorer registered for `planner` (or its stand-in until it is implemented)."""
    if planner in SCORERS:
        return SCORERS[planner]()
    stand_in = PLACEHOLDERS[planner]
    log.info("planner %r not implemented yet: scoring with %r", planner, stand_in)
    return SCORERS[stand_in]()


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
