"""Tours over the frontier regions (`edge.space_tour`): which robot visits which, in what order.

The revenue assignment gives a robot that needs a goal the region of most information per
second, one robot and one region at a time. Three robots that start in one room each find a
region of that room best and clean it up together while the doors wait (AWS house, seed 0:
all three in the dining room for the first 70 s). A tour looks past the next goal: every
usable region goes into one open route per robot, the routes built so that the last of them
ends as early as possible (min-max, since the mission ends with the last robot) without
detours on the others, by farthest insertion and 2-opt; a robot that needs a goal takes the
first stop of its route. A robot keeping its goal starts its route at that goal, after the
time it takes to get there.

Travel times between regions come from one Dijkstra per region on a coarse copy of the
traversable grid (a coarse cell is traversable where any of its cells is); the time from a
robot that needs a goal to each region is the revenue's (its own fine path field and turn).
Pure functions on arrays.
"""

from __future__ import annotations

import numpy as np

from services.common.planning import distance_fields
from services.edge_server.robot_fields import snap_start


def coarse_traversable(traversable: np.ndarray, factor: int) -> np.ndarray:
    """(ceil(H/k), ceil(W/k)) bool: blocks of k×k cells with any traversable cell."""
    H, W = traversable.shape
    Hc, Wc = -(-H // factor), -(-W // factor)
    padded = np.zeros((Hc * factor, Wc * factor), bool)
    padded[:H, :W] = traversable
    return padded.reshape(Hc, factor, Wc, factor).any(axis=(1, 3))


def coarse_paths_m(traversable: np.ndarray, sources_rc: np.ndarray, targets_rc: np.ndarray,
                   factor: int, resolution_m: float) -> np.ndarray:
    """(S, T) path length in metres from each source cell to each target cell (fine-grid
    row, col) on the coarse grid; inf where a cell has no traversable block within two
    blocks, or the two are not connected."""
    coarse = coarse_traversable(traversable, factor)
    sources_rc = np.asarray(sources_rc, np.int64).reshape(-1, 2)
    targets_rc = np.asarray(targets_rc, np.int64).reshape(-1, 2)
    out = np.full((len(sources_rc), len(targets_rc)), np.inf)

    def snapped(rc: np.ndarray) -> list[tuple[int, int] | None]:
        return [snap_start(coarse, (int(r) // factor, int(c) // factor), 2.0) for r, c in rc]

    starts, ends = snapped(sources_rc), snapped(targets_rc)
    valid = [i for i, s in enumerate(starts) if s is not None]
    known = [j for j, e in enumerate(ends) if e is not None]
    if not valid or not known:
        return out
    fields = distance_fields(coarse, [starts[i] for i in valid])
    er = np.array([ends[j] for j in known])
    out[np.ix_(valid, known)] = fields[:, er[:, 0], er[:, 1]] * factor * resolution_m
    return out


def _insertion(route: list[int], start_s: np.ndarray, leg_s: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """(F,) the least added time of putting each region into `route`, and (F,) where (the
    index it would take)."""
    if not route:
        return start_s.copy(), np.zeros(len(start_s), np.int64)
    nodes = np.asarray(route)
    with np.errstate(invalid="ignore"):
        first = start_s + leg_s[:, nodes[0]] - start_s[nodes[0]]
        a, b = nodes[:-1], nodes[1:]
        middle = leg_s[a, :] + leg_s[:, b].T - leg_s[a, b][:, None]
        options = np.vstack([first[None, :], middle, leg_s[nodes[-1], :][None, :]])
    options = np.where(np.isnan(options), np.inf, options)
    where = np.argmin(options, axis=0)
    return options[where, np.arange(options.shape[1])], where


def min_max_routes(start_s: np.ndarray, offset_s: np.ndarray, leg_s: np.ndarray,
                   stop_s: float, sum_weight: float = 0.0) -> list[list[int]]:
    """One open route per robot over the regions, so that the longest ends early.

    start_s: (R, F) seconds from robot r (or the goal it keeps) to region f, inf if it cannot;
    offset_s: (R,) seconds before robot r's route starts (the way to a kept goal);
    leg_s: (F, F) seconds from region i to region j; stop_s: seconds spent at each region.
    Each insertion costs what it adds to the longest route plus `sum_weight` times the mean
    it adds per route (with 0, routes off the critical one may detour freely: crossing trips).
    Farthest insertion: the region whose best insertion costs most goes first, into the route
    where it costs least. Regions no robot can get to are left out.
    """
    start_s = np.asarray(start_s, np.float64)
    R, F = start_s.shape
    leg_s = np.asarray(leg_s, np.float64).reshape(F, F)
    routes: list[list[int]] = [[] for _ in range(R)]
    length = np.asarray(offset_s, np.float64).reshape(R).copy()
    todo = np.ones(F, bool)
    while todo.any():
        makespan = float(length.max())
        best_cost = np.full(F, np.inf)
        best_robot = np.zeros(F, np.int64)
        best_at = np.zeros(F, np.int64)
        best_end = np.zeros(F)
        for r in range(R):
            added, at = _insertion(routes[r], start_s[r], leg_s)
            end = length[r] + added + stop_s
            with np.errstate(invalid="ignore"):
                cost = np.maximum(end - makespan, 0.0) + sum_weight * (added + stop_s) / R
            better = cost < best_cost
            best_cost[better], best_robot[better] = cost[better], r
            best_at[better], best_end[better] = at[better], end[better]
        candidates = todo & np.isfinite(best_cost)
        if not candidates.any():
            break
        f = int(np.flatnonzero(candidates)[np.argmax(best_cost[candidates])])
        r = int(best_robot[f])
        routes[r].insert(int(best_at[f]), f)
        length[r] = best_end[f]
        todo[f] = False
    return [two_opt(route, start_s[r], leg_s) for r, route in enumerate(routes)]


def two_opt(route: list[int], start_s: np.ndarray, leg_s: np.ndarray) -> list[int]:
    """The route with segments reversed while that shortens it (its start fixed, its end
    free)."""
    def cost(rt: list[int]) -> float:
        return float(start_s[rt[0]] + sum(leg_s[a, b] for a, b in zip(rt[:-1], rt[1:],
                                                                      strict=True)))

    best, best_cost = list(route), cost(route) if route else 0.0
    improved = len(route) > 1
    while improved:
        improved = False
        for i in range(len(best) - 1):
            for j in range(i + 1, len(best)):
                trial = best[:i] + best[i:j + 1][::-1] + best[j + 1:]
                c = cost(trial)
                if c < best_cost - 1e-9:
                    best, best_cost, improved = trial, c, True
    return best


def route_length_s(route: list[int], start_s: np.ndarray, offset_s: float, leg_s: np.ndarray,
                   stop_s: float) -> float:
    """Seconds until a route's last stop ends (inf for an impossible leg)."""
    if not route:
        return float(offset_s)
    legs = [start_s[route[0]]] + [leg_s[a, b] for a, b in zip(route[:-1], route[1:], strict=True)]
    return float(offset_s + sum(legs) + stop_s * len(route))
