"""Successor goals (`space`): the next goal of a robot about to reach its current one.

A robot reaches a goal between plans and used to stand still until the next plan (every
`edge_every_ticks`): 0.2-1.1 s per goal, about 20 goals per robot in a house mission
(`spacemap eval RUN --explain`, "no goal"). A robot within `space_successor_m` of its goal
gets, ahead of time, the frontier the planner would give it once there: scored by the same
scorer from the goal (path lengths on a distance field from the goal's cell, heading = the
bearing it arrives on), with its own goal and its teammates' counted as held (what they will
see is discounted), among frontiers nobody holds or is queued for. The agent keeps it
(`Goal.queued`) and adopts it when its goal ends; the plan after that treats it like any
goal it holds.

Pure: arrays and the scorer in, robot → frontier index out.
"""

from __future__ import annotations

import numpy as np

from services.edge_server.assignment import Scorer
from services.edge_server.coordination import RobotStates
from services.edge_server.frontiers import FrontierSet
from services.edge_server.robot_fields import RobotFields


def successor_frontiers(
    near: dict[int, int], frontiers: FrontierSet, traversable: np.ndarray, cell_m: float,
    robots_xy: dict[int, np.ndarray], usable: np.ndarray, scorer: Scorer, snap_cells: float,
) -> dict[int, int]:
    """Robot → frontier index of its successor, for the robots in `near` (robot → the
    frontier index of the goal it is about to reach).

    `robots_xy`: robot → (2,) world xy now, m (it arrives on the bearing from there to the
    goal). `usable`: (F,) frontiers that may be assigned at all (others' goals excluded).
    """
    if not near or not len(frontiers):
        return {}
    goal_rc = frontiers.goal_rc
    robots = sorted(near)
    starts = {r: goal_rc[near[r]] for r in robots}
    fields = RobotFields(traversable, starts, snap_cells)
    fields.compute(robots)
    held_xy = frontiers.goal_xy[[near[r] for r in robots]]
    free = usable.copy()
    free[list(near.values())] = False
    out: dict[int, int] = {}
    for r in robots:  # one at a time: a successor taken is not another's
        if not free.any():
            break
        goal_xy = frontiers.goal_xy[near[r]]
        d = goal_xy - np.asarray(robots_xy[r], np.float64)
        yaw = float(np.arctan2(d[1], d[0]))
        path_m = fields[r][goal_rc[:, 0], goal_rc[:, 1]][None, :] * cell_m
        states = RobotStates(goal_xy[None, :], np.array([yaw]), held_xy)
        scores = scorer.score(path_m, frontiers, states)[0]
        scores[~free] = -np.inf
        best = int(np.argmax(scores))
        if np.isfinite(scores[best]):
            out[r] = best
            free[best] = False
    return out
