"""RRT frontier detection in the style of rrt_exploration (Umari & Mukhopadhyay, IROS 2017).

A tree grows from every robot's start cell over the traversable part of the merged grid
(and, as rrt_exploration's global detector, from the nodes it kept from earlier plans, so
it reaches frontiers far from the robots that one plan's samples would miss):
sample a cell uniformly in the grid, steer from the nearest tree node by at most η, and walk
the segment. A segment that reaches an unknown cell yields a frontier point there (the tree
does not grow into it); one that hits a non-traversable known cell is dropped; otherwise the
new node joins the tree. Sampling uses a np.random.Generator seeded from (mission seed,
tick), so a lockstep mission repeats exactly. The frontier points become the mask that
`frontier_set` clusters and translates to goals.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from services.common.grid import GridSpec
from services.edge_server.config import EdgeConfig
from services.edge_server.frontiers import FrontierSet, GoalTransform, frontier_set


@dataclass(frozen=True)
class RrtMemory:
    """What the detector keeps from one plan to the next, in world (y, x) metres: the grid's
    origin moves as the map grows."""

    tree_yx: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (N, 2) nodes
    points_yx: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (M, 2) frontier
    # points not yet seen (rrt_exploration's filter keeps them until their cell is known)


def _walk(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(S, 2) int cells on the segment a → b (a excluded), sampled at ≤ half a cell."""
    n = max(int(np.ceil(2 * np.abs(b - a).max())), 1)
    t = np.arange(1, n + 1)[:, None] / n
    return np.round(a + t * (b - a)).astype(np.int64)


def rrt_frontier_mask(
    traversable: np.ndarray, known: np.ndarray, starts_rc: list[tuple[int, int]],
    iterations: int, step_cells: float, rng: np.random.Generator,
    tree_rc: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """((H, W) bool frontier points found by a multi-root RRT, (N, 2) float its nodes).
    `tree_rc`: nodes (row, col) kept from earlier plans; those now off the traversable grid
    are dropped."""
    H, W = traversable.shape
    mask = np.zeros((H, W), bool)
    if not starts_rc:
        return mask, np.zeros((0, 2))
    roots = np.asarray(starts_rc, np.float64).reshape(-1, 2)
    if tree_rc is not None and len(tree_rc):
        cell = np.round(tree_rc).astype(np.int64)
        inside = (cell[:, 0] >= 0) & (cell[:, 0] < H) & (cell[:, 1] >= 0) & (cell[:, 1] < W)
        kept = tree_rc[inside][traversable[cell[inside, 0], cell[inside, 1]]]
        roots = np.concatenate([roots, kept])
    nodes = np.zeros((len(roots) + iterations, 2))
    nodes[: len(roots)] = roots
    count = len(roots)
    samples = rng.uniform([0, 0], [H - 1, W - 1], size=(iterations, 2))
    for x in samples:
        d2 = ((nodes[:count] - x) ** 2).sum(axis=1)
        near = nodes[int(np.argmin(d2))]
        dist = float(np.sqrt(d2.min()))
        new = x if dist <= step_cells else near + (x - near) * (step_cells / dist)
        cells = _walk(near, new)
        unknown = ~known[cells[:, 0], cells[:, 1]]
        blocked = known[cells[:, 0], cells[:, 1]] & ~traversable[cells[:, 0], cells[:, 1]]
        first_unknown = int(np.argmax(unknown)) if unknown.any() else len(cells)
        first_blocked = int(np.argmax(blocked)) if blocked.any() else len(cells)
        if first_unknown < first_blocked:
            r, c = cells[first_unknown]
            mask[r, c] = True
        elif first_blocked == len(cells):
            nodes[count] = new
            count += 1
    return mask, nodes[len(starts_rc):count]


def kept_points(points_yx: np.ndarray, known: np.ndarray, spec: GridSpec) -> np.ndarray:
    """(H, W) bool: frontier points of earlier plans whose cell is still unknown."""
    mask = np.zeros(known.shape, bool)
    origin_yx = np.array([spec.origin_y, spec.origin_x])
    rc = np.floor((points_yx - origin_yx) / spec.resolution_m).astype(np.int64)
    rc = rc[spec.contains(rc)]
    mask[rc[:, 0], rc[:, 1]] = True
    return mask & ~known


def rrt_frontiers(
    traversable: np.ndarray, known: np.ndarray, starts_rc: list[tuple[int, int]],
    goal_ok: np.ndarray, spec: GridSpec, config: EdgeConfig, rng: np.random.Generator,
    memory: RrtMemory, goal_edt: GoalTransform | None = None,
) -> tuple[FrontierSet, RrtMemory]:
    """(frontier clusters with goals among `goal_ok` cells, what to keep for the next plan)
    on the grid `spec`; without `rrt_keep_tree` a fresh tree each plan and no points kept."""
    origin_yx = np.array([spec.origin_y, spec.origin_x])
    keep = config.rrt_keep_tree
    tree_rc = None
    if keep and len(memory.tree_yx):
        tree_rc = (memory.tree_yx - origin_yx) / spec.resolution_m - 0.5
    mask, tree = rrt_frontier_mask(traversable, known, starts_rc, config.rrt_iterations,
                                   config.rrt_step_m / spec.resolution_m, rng, tree_rc)
    if keep:
        mask |= kept_points(memory.points_yx, known, spec)
    points_yx = (np.argwhere(mask) + 0.5) * spec.resolution_m + origin_yx
    link = int(round(config.frontier_link_m / spec.resolution_m))
    mask = ndimage.binary_dilation(mask, np.ones((2 * link + 1,) * 2, bool)) & ~known
    return (frontier_set(mask, goal_ok, spec, 1, config.goal_max_offset_m, goal_edt),
            RrtMemory((tree + 0.5) * spec.resolution_m + origin_yx, points_yx))
