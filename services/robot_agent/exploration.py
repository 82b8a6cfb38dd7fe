"""Local frontier goals, for exploring on the agent's own grid while the edge is away.

A frontier cell is a free cell with an unknown 8-neighbour; frontier cells group into 8-connected
clusters; the goal is the reachable cell (on the inflated grid, known free space only) of a
cluster of at least `min_cells` that is nearest by path length. Plain Yamauchi: the edge's 3D
frontiers and assignment take over again as soon as it is back.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from schemas.messages import Goal
from services.common.grid import GridSpec
from services.common.planning import distance_field
from services.robot_agent.config import AgentConfig
from services.robot_agent.local_grid import FREE, UNKNOWN, LocalGrid
from services.robot_agent.navigation import inflation_cells, snap_cell, traversable_of

LOCAL_GOAL_BASE = 1 << 30  # ids of the agent's own goals while the edge is away (never reported)

_MARGIN_CELLS = 4
_EIGHT = np.ones((3, 3), bool)


def frontier_cells(cells: np.ndarray) -> np.ndarray:
    """(H, W) bool: free cells with an unknown 8-neighbour."""
    return (cells == FREE) & ndimage.binary_dilation(cells == UNKNOWN, structure=_EIGHT)


def nearest_frontier(
    cells: np.ndarray, start_rc: tuple[int, int], radius_cells: int, min_cells: int,
    min_dist_cells: float = 0.0,
) -> tuple[int, int] | None:
    """(row, col) of the nearest reachable frontier cell in a big-enough cluster, or None.

    Cells closer than `min_dist_cells` (the goal tolerance) are skipped: reached at once.
    """
    trav = traversable_of(cells, radius_cells, through_unknown=False)
    if not trav[start_rc]:
        snapped = snap_cell(trav, start_rc, 10.0)
        if snapped is None:
            return None
        start_rc = snapped
    dist = distance_field(trav, start_rc)
    labels, n = ndimage.label(frontier_cells(cells), structure=_EIGHT)
    if n == 0:
        return None
    sizes = np.bincount(labels.reshape(-1), minlength=n + 1)
    big = sizes >= min_cells
    big[0] = False
    # A frontier cell is usually inside the inflation of the unknown-side wall: reach it by
    # its nearest reachable neighbour within the robot radius instead.
    reach = ndimage.grey_erosion(np.where(np.isfinite(dist), dist, np.inf),
                                 footprint=np.ones((2 * radius_cells + 1,) * 2, bool))
    cand = big[labels] & np.isfinite(reach) & (reach > min_dist_cells)
    if not cand.any():
        return None
    flat = np.where(cand, reach, np.inf).argmin()
    return int(flat // cells.shape[1]), int(flat % cells.shape[1])


def local_frontier_goal(
    grid: LocalGrid, xy: np.ndarray, radius_cells: int, min_cells: int, min_dist_m: float = 0.0
) -> np.ndarray | None:
    """World (x, y) of the nearest local frontier, or None when the local map has none."""
    spec = grid.spec
    rows, cols = grid.window(_MARGIN_CELLS, spec.cell_of(xy[None, :]))
    sub = GridSpec(
        spec.origin_x + cols.start * spec.resolution_m,
        spec.origin_y + rows.start * spec.resolution_m,
        spec.resolution_m, rows.stop - rows.start, cols.stop - cols.start,
    )
    rc = sub.cell_of(xy[None, :])[0]
    goal = nearest_frontier(grid.cells(rows, cols), (int(rc[0]), int(rc[1])), radius_cells,
                            min_cells, min_dist_m / spec.resolution_m)
    return None if goal is None else sub.centre_of(np.array([goal]))[0]


class LocalExplorer:
    """The agent's own frontier goals while the edge is away, one try per retry interval."""

    def __init__(self, config: AgentConfig, robot_id: int) -> None:
        self.config = config
        self.robot_id = robot_id
        self.n_goals = 0
        self.last_try_tick = -(10**9)

    def wants_goal(self, tick: int, edge_alive: bool, navigating: bool) -> bool:
        cfg = self.config
        return (not edge_alive and cfg.local_explore and not navigating
                and tick - self.last_try_tick >= cfg.local_goal_retry_ticks)

    def goal(self, grid: LocalGrid, pose_world: tuple[float, float, float],
             tick: int) -> Goal | None:
        """The nearest frontier of the agent's own grid, as a goal only this agent knows."""
        self.last_try_tick = tick
        cfg = self.config
        radius = inflation_cells(cfg, grid.spec.resolution_m)
        xy = local_frontier_goal(grid, np.array(pose_world[:2]), radius, cfg.frontier_min_cells,
                                 2 * cfg.goal_tolerance_m)
        if xy is None:
            return None
        self.n_goals += 1
        return Goal(robot_id=self.robot_id, tick=tick, goal_id=LOCAL_GOAL_BASE + self.n_goals,
                    x=float(xy[0]), y=float(xy[1]), frontier_class="unexplored", revenue=0.0)
