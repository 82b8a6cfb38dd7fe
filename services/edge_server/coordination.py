"""Coordinated SPACE assignment (`--planner space`): the paper's quantities, costed in time.

The paper's revenue U = I_t·I_g / (κ·h) scores each region alone, by metres, and each robot
takes its maximum. The default `space` planner keeps I_t and I_g and changes what they are
weighed against (choices and evidence: docs/edge.md, "Coordinated space and the endgame"):

- **View information**: a goal f′ is worth the I_t·I_g of every region whose centroid lies
  within `view_radius_m` of it (one stop sees all of them), not of its own region alone.
- **Time, not metres**: h becomes the seconds to get there, path / v + the turn from the
  robot's heading to the goal's bearing / ω (a robot that just reached a goal faces away from
  the next one about as often as not).
- **Teammates' goals**: a region within `view_radius_m` of a goal another robot holds is about
  to be seen; its information counts `teammate_discount` times.
- **Joint assignment**: the revenue matrix is solved as an assignment problem (maximum total
  revenue, scipy's `linear_sum_assignment`) instead of each robot's greedy maximum.

Pure functions on arrays; the scorer object holds only config.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from services.edge_server.frontiers import FrontierSet


@dataclass(frozen=True)
class RobotStates:
    """Where the robots needing a score are, and the goals their teammates hold."""

    xy_world: np.ndarray  # (R, 2) float64, m, world frame, rows in the scorer's robot order
    yaw_world: np.ndarray  # (R,) float64, rad
    held_goals_xy: np.ndarray  # (G, 2) float64, m: goals kept by other robots this plan


def view_information(goal_xy: np.ndarray, centroid_xy: np.ndarray, info: np.ndarray,
                     radius_m: float) -> np.ndarray:
    """(F,) Σ info[j] over regions j whose centroid lies within `radius_m` of goal f′_i."""
    goal_xy = np.asarray(goal_xy, np.float64).reshape(-1, 2)
    centroid_xy = np.asarray(centroid_xy, np.float64).reshape(-1, 2)
    d2 = ((goal_xy[:, None, :] - centroid_xy[None, :, :]) ** 2).sum(axis=2)
    seen = d2 <= radius_m**2
    seen[np.arange(len(goal_xy)), np.arange(len(goal_xy))] = True  # a goal sees its own region
    return seen.astype(np.float64) @ np.asarray(info, np.float64)


def teammate_factor(centroid_xy: np.ndarray, held_goals_xy: np.ndarray, radius_m: float,
                    discount: float) -> np.ndarray:
    """(F,) `discount` for regions a teammate's held goal will see, 1 elsewhere."""
    centroid_xy = np.asarray(centroid_xy, np.float64).reshape(-1, 2)
    held = np.asarray(held_goals_xy, np.float64).reshape(-1, 2)
    if not len(held) or not len(centroid_xy):
        return np.ones(len(centroid_xy))
    d2 = ((centroid_xy[:, None, :] - held[None, :, :]) ** 2).sum(axis=2)
    return np.where((d2 <= radius_m**2).any(axis=1), discount, 1.0)


def partition_factor(goal_xy: np.ndarray, robots_xy: np.ndarray, held_goals_xy: np.ndarray,
                     discount: float) -> np.ndarray:
    """(R, F) `discount` where a teammate of robot r (another robot, or a goal a robot holds)
    is nearer f′ in a straight line than r is, 1 elsewhere: each robot's own part of the
    map (its Voronoi cell among the team) counts in full, so a team that starts together
    fans out instead of cleaning up one room together."""
    goal_xy = np.asarray(goal_xy, np.float64).reshape(-1, 2)
    robots_xy = np.asarray(robots_xy, np.float64).reshape(-1, 2)
    held = np.asarray(held_goals_xy, np.float64).reshape(-1, 2)
    R, F = len(robots_xy), len(goal_xy)
    if discount >= 1.0 or not F or R + len(held) < 2:
        return np.ones((R, F))
    own = np.hypot(*(goal_xy[None, :, :] - robots_xy[:, None, :]).transpose(2, 0, 1))
    if R > 1:
        order = np.sort(own, axis=0)  # per f′: the nearest robot's distance, the next one's
        other = np.where(own <= order[0][None, :], order[1][None, :], order[0][None, :])
    else:
        other = np.full((R, F), np.inf)
    if len(held):
        d_held = np.hypot(*(goal_xy[None, :, :] - held[:, None, :]).transpose(2, 0, 1))
        other = np.minimum(other, d_held.min(axis=0)[None, :])
    return np.where(other < own, discount, 1.0)


def travel_time_s(path_m: np.ndarray, robots_xy: np.ndarray, robots_yaw: np.ndarray,
                  goal_xy: np.ndarray, v_mps: float, omega_radps: float) -> np.ndarray:
    """(R, F) path / v + |bearing to f′ − heading| / ω; inf where the path is."""
    d = np.asarray(goal_xy, np.float64)[None, :, :] - np.asarray(robots_xy)[:, None, :]
    bearing = np.arctan2(d[..., 1], d[..., 0])
    turn = np.abs(np.remainder(bearing - np.asarray(robots_yaw)[:, None] + np.pi, 2 * np.pi)
                  - np.pi)
    return np.asarray(path_m, np.float64) / v_mps + turn / omega_radps


def joint_match(scores: np.ndarray) -> dict[int, int]:
    """Row → column pairs of maximum total score, each row and column once, −inf never used.

    Rows with no finite score get nothing. scipy's solver is deterministic.
    """
    scores = np.asarray(scores, np.float64)
    if not scores.size:
        return {}
    finite = np.isfinite(scores)
    rows = np.flatnonzero(finite.any(axis=1))
    cols = np.flatnonzero(finite.any(axis=0))
    if not len(rows):
        return {}
    sub = scores[np.ix_(rows, cols)]
    ok = np.isfinite(sub)
    # forbidden pairs cost more than any assignment of finite ones could gain
    big = (np.abs(sub[ok]).sum() + 1.0) * 2.0
    r, c = linear_sum_assignment(np.where(ok, sub, -big), maximize=True)
    return {int(rows[i]): int(cols[j]) for i, j in zip(r, c, strict=True) if ok[i, j]}


def coordinated_revenue(
    path_m: np.ndarray, frontiers: FrontierSet, robots: RobotStates, *, v_mps: float,
    omega_radps: float, view_radius_m: float, teammate_discount: float, min_time_s: float,
    grid_gain_per_m: float = 0.0, grid_view_m: float = 0.0, teammate_radius_m: float | None = None,
    size_exponent: float = 0.0, size_ref: float = 1.0, partition_discount: float = 1.0,
    time_exponent: float = 1.0, view_gain_per_m2: float = 0.0, view_range_m: float = 0.0,
) -> np.ndarray:
    """(R, F) view information (teammates' discounted) per second of travel; −inf unreachable.
    With `grid_gain_per_m`, a goal is also worth that much per metre of 2D grid frontier
    near it (`frontiers.grid_frontier_m`), discounted where a teammate's goal is as near.
    `teammate_radius_m` (default `view_radius_m`): how near a teammate's goal discounts.
    `size_exponent` > 0: each F_u region's information × max(1, its size / `size_ref`)^that.
    `partition_discount` < 1: a goal nearer a teammate than the robot counts that much
    (`partition_factor`). `view_gain_per_m2`: per m² of unknown floor in sight of f′
    (`frontiers.unknown_view_m2`), discounted near a teammate's goal. `time_exponent` < 1:
    the travel time counts less than in full."""
    if teammate_radius_m is None:
        teammate_radius_m = view_radius_m
    n = len(frontiers)
    gain = frontiers.gain if frontiers.gain is not None else np.ones(n)
    imp = frontiers.importance if frontiers.importance is not None else np.ones(n)
    info = imp * gain * teammate_factor(frontiers.centroid_xy, robots.held_goals_xy,
                                        teammate_radius_m, teammate_discount)
    if size_exponent > 0:
        factor = np.maximum(frontiers.sizes / size_ref, 1.0) ** size_exponent
        info = info * (factor if frontiers.weak is None else np.where(frontiers.weak, 1.0, factor))
    view = view_information(frontiers.goal_xy, frontiers.centroid_xy, info, view_radius_m)
    if grid_gain_per_m > 0 and frontiers.grid_frontier_m is not None:
        view = view + grid_gain_per_m * frontiers.grid_frontier_m * teammate_factor(
            frontiers.goal_xy, robots.held_goals_xy, grid_view_m, teammate_discount)
    if view_gain_per_m2 > 0 and frontiers.unknown_view_m2 is not None:
        view = view + view_gain_per_m2 * frontiers.unknown_view_m2 * teammate_factor(
            frontiers.goal_xy, robots.held_goals_xy, view_range_m, teammate_discount)
    t = travel_time_s(path_m, robots.xy_world, robots.yaw_world, frontiers.goal_xy, v_mps,
                      omega_radps)
    part = partition_factor(frontiers.goal_xy, robots.xy_world, robots.held_goals_xy,
                            partition_discount)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = view[None, :] * part / np.maximum(t, min_time_s) ** time_exponent
    return np.where(np.isfinite(path_m), u, -np.inf)
