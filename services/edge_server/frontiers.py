"""Frontier regions on the merged 2D grid and their translated goals f′.

Used as is by the classic baselines ("nearest", "utility"); the SPACE and RRT detectors build
their own frontier masks and reuse `frontier_set` for clustering and goal translation.

Frontier cells are free cells 8-adjacent to unknown cells. They are clustered with 8-connected
labelling, clusters under `frontier_min_cells` are dropped, and each cluster is translated to a
goal f′: take the cluster cell nearest to its centroid (the anchor; the centroid of a curved
cluster may lie off it) and the allowed goal cell nearest to that anchor. A cluster whose f′
would lie more than `goal_max_offset_m` from its anchor is unreachable and dropped. All steps
are whole-array operations.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from schemas.messages import Frontier, Frontiers
from services.common.grid import GridSpec
from services.edge_server.config import EdgeConfig

EIGHT = np.ones((3, 3), bool)


@dataclass(frozen=True)
class FrontierSet:
    """Kept frontier clusters, index i ↔ cluster label i + 1 in `labels`."""

    labels: np.ndarray  # (H, W) int32: 1 + cluster index on its frontier cells, 0 elsewhere
    sizes: np.ndarray  # (F,) int64 cells per cluster
    centroid_xy: np.ndarray  # (F, 2) world
    anchor_rc: np.ndarray  # (F, 2) frontier cell nearest the centroid
    anchor_xy: np.ndarray  # (F, 2) world centre of the anchor cell
    goal_rc: np.ndarray  # (F, 2) translated goal f′ cell
    goal_xy: np.ndarray  # (F, 2) world centre of the goal cell
    dropped_unreachable: int = 0
    weak: np.ndarray | None = None  # (F,) bool: F_w (True) or F_u (False); None = all F_u
    gain: np.ndarray | None = None  # (F,) I_g(f); None = size in metres
    importance: np.ndarray | None = None  # (F,) I_t(f); None = 1
    centroid_z: np.ndarray | None = None  # (F,) mean height of V_f (3D frontiers)
    grid_frontier_m: np.ndarray | None = None  # (F,) m of 2D grid frontier near f′ (space)
    unknown_view_m2: np.ndarray | None = None  # (F,) m² of unknown floor in sight of f′ (space)
    view: np.ndarray | None = None  # (F,) bool: f′ is a far view; the robot faces the region

    def __len__(self) -> int:
        return int(self.sizes.size)


def empty_frontiers(shape: tuple[int, int]) -> FrontierSet:
    z2 = np.zeros((0, 2))
    return FrontierSet(np.zeros(shape, np.int32), np.zeros(0, np.int64), z2,
                       z2.astype(np.int64), z2, z2.astype(np.int64), z2)


def frontier_cells(free: np.ndarray, known: np.ndarray) -> np.ndarray:
    """(H, W) bool: free cells with an unknown 8-neighbour."""
    return free & ndimage.binary_dilation(~known, structure=EIGHT)


def _clusters(mask: np.ndarray, min_cells: int) -> tuple[np.ndarray, np.ndarray]:
    """8-connected labels renumbered 1..F over clusters of at least `min_cells`, and sizes."""
    labels, n = ndimage.label(mask, structure=EIGHT)
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    keep = sizes >= min_cells
    keep[0] = False
    renumber = np.zeros(n + 1, np.int32)
    renumber[keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    return renumber[labels], sizes[keep]


def _anchors(labels: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, 2) float centroid (row, col) and (n, 2) int anchor cell of each cluster."""
    rc = np.argwhere(labels > 0)
    lab = labels[rc[:, 0], rc[:, 1]] - 1
    counts = np.bincount(lab, minlength=n)
    centroid = np.stack(
        [np.bincount(lab, weights=rc[:, d], minlength=n) for d in (0, 1)], axis=1
    ) / counts[:, None]
    d2 = ((rc - centroid[lab]) ** 2).sum(axis=1)
    # per cluster the nearest cell, the first in row-major order on a tie (what a stable
    # sort by (cluster, d2) puts first), by two scatter-minima instead of a sort
    nearest = np.full(n, np.inf)
    np.minimum.at(nearest, lab, d2)
    tied = np.flatnonzero(d2 == nearest[lab])
    first = np.full(n, rc.shape[0])
    np.minimum.at(first, lab[tied], tied)
    return centroid, rc[first]


def detect_frontiers(
    free: np.ndarray, known: np.ndarray, goal_ok: np.ndarray, spec: GridSpec, config: EdgeConfig,
    goal_edt: GoalTransform | None = None,
) -> FrontierSet:
    """Frontier clusters of a grid and their goals f′, chosen among `goal_ok` cells."""
    return frontier_set(frontier_cells(free, known), goal_ok, spec, config.frontier_min_cells,
                        config.goal_max_offset_m, goal_edt)


@functools.cache
def _window_offsets(half: int) -> tuple[np.ndarray, np.ndarray]:
    """(K, 2) (row, col) offsets of a square of half-side `half` and their squared lengths,
    in the order scipy's feature transform prefers among them: nearest first, then the
    smallest column, then the smallest row (checked against it in tests)."""
    dr, dc = np.mgrid[-half:half + 1, -half:half + 1]
    dr, dc = dr.ravel(), dc.ravel()
    d2 = dr * dr + dc * dc
    order = np.lexsort((dr, dc, d2))
    return np.stack([dr[order], dc[order]], 1), d2[order]


# offsets tried per round: most anchors have an allowed cell within a few cells
_ROUNDS = (25, 121, 441)


class GoalTransform:
    """The allowed goal cell nearest a cell, and its distance in cells, for the few cells asked
    (the regions' anchors): the same answer as `ndimage.distance_transform_edt(~goal_ok,
    return_indices=True)` at those cells wherever it lies within the asked distance, without
    transforming the whole grid (3 ms a plan in the AWS house)."""

    def __init__(self, goal_ok: np.ndarray) -> None:
        self.goal_ok = np.asarray(goal_ok, bool)

    def nearest(self, rc: np.ndarray, max_cells: float) -> tuple[np.ndarray, np.ndarray]:
        """(N,) distance in cells (inf: none within `max_cells`) and (N, 2) int64 goal cell
        (the cell itself where none) of cells `rc` (N, 2)."""
        rc = np.asarray(rc, np.int64).reshape(-1, 2)
        offsets, d2 = _window_offsets(int(np.floor(max_cells)) + 1)
        dist = np.full(len(rc), np.inf)
        goal = rc.copy()
        todo = np.arange(len(rc))
        bounds = [0, *(b for b in _ROUNDS if b < len(offsets)), len(offsets)]
        H, W = self.goal_ok.shape
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            if not todo.size:
                break
            cells = rc[todo, None, :] + offsets[None, lo:hi, :]  # (n, k, 2)
            inside = ((cells[..., 0] >= 0) & (cells[..., 0] < H)
                      & (cells[..., 1] >= 0) & (cells[..., 1] < W))
            hit = np.zeros(inside.shape, bool)
            hit[inside] = self.goal_ok[cells[..., 0][inside], cells[..., 1][inside]]
            found = hit.any(axis=1)
            first = hit.argmax(axis=1)[found]
            done = todo[found]
            dist[done] = np.sqrt(d2[lo:hi][first].astype(np.float64))
            goal[done] = cells[found, first]
            todo = todo[~found]
        return dist, goal


def goal_transform(goal_ok: np.ndarray) -> GoalTransform:
    """Nearest allowed goal cells of `goal_ok`, looked up on demand (`GoalTransform`)."""
    return GoalTransform(goal_ok)


def frontier_set(
    mask: np.ndarray, goal_ok: np.ndarray, spec: GridSpec, min_cells: int, max_offset_m: float,
    goal_edt: GoalTransform | None = None,
) -> FrontierSet:
    """8-connected clusters of `mask` (≥ min_cells) with goals f′ among `goal_ok` cells
    (`goal_edt`: `goal_transform(goal_ok)` when the caller already has it)."""
    labels, sizes = _clusters(mask, min_cells)
    n = int(sizes.size)
    if n == 0 or not goal_ok.any():
        return empty_frontiers(mask.shape)
    centroid_rc, anchor_rc = _anchors(labels, n)
    lookup = goal_edt if goal_edt is not None else goal_transform(goal_ok)
    offset, goal_rc = lookup.nearest(anchor_rc, max_offset_m / spec.resolution_m)
    ok = offset * spec.resolution_m <= max_offset_m
    renumber = np.zeros(n + 1, np.int32)
    renumber[1:][ok] = np.arange(1, int(ok.sum()) + 1, dtype=np.int32)
    centroid_xy = spec.centre_of(centroid_rc[ok])  # centre_of takes fractional (row, col) too
    return FrontierSet(
        labels=renumber[labels],
        sizes=sizes[ok],
        centroid_xy=centroid_xy,
        anchor_rc=anchor_rc[ok],
        anchor_xy=spec.centre_of(anchor_rc[ok]),
        goal_rc=goal_rc[ok].astype(np.int64),
        goal_xy=spec.centre_of(goal_rc[ok]),
        dropped_unreachable=int((~ok).sum()),
    )


def frontier_length_near(free: np.ndarray, known: np.ndarray, cells_rc: np.ndarray,
                         spec: GridSpec, radius_m: float, min_cells: int) -> np.ndarray:
    """(N,) metres of free/unknown border (clusters of ≥ `min_cells`) within a square of
    half-side `radius_m` around each cell: how much unknown floor a robot there looks into.
    Unknown space behind walls has no free border, so it counts nothing."""
    if not len(cells_rc):
        return np.zeros(0)
    labels, _ = _clusters(frontier_cells(free, known), min_cells)
    k = max(int(round(radius_m / spec.resolution_m)), 0)
    near = ndimage.uniform_filter((labels > 0).astype(np.float32), size=2 * k + 1,
                                  mode="constant")
    return near[cells_rc[:, 0], cells_rc[:, 1]].astype(np.float64) * (2 * k + 1) ** 2 \
        * spec.resolution_m


def frontiers_message(tick: int, fs: FrontierSet, complete: bool, assigned: dict[int, int],
                      resolution_m: float) -> Frontiers:
    n = len(fs)
    weak = fs.weak if fs.weak is not None else np.zeros(n, bool)
    gain = fs.gain if fs.gain is not None else fs.sizes * resolution_m
    imp = fs.importance if fs.importance is not None else np.ones(n)
    z = fs.centroid_z if fs.centroid_z is not None else np.zeros(n)
    items = [
        Frontier(
            frontier_id=i, frontier_class="weak" if weak[i] else "unexplored",
            centroid=(float(fs.centroid_xy[i, 0]), float(fs.centroid_xy[i, 1]), float(z[i])),
            goal_xy=(float(fs.goal_xy[i, 0]), float(fs.goal_xy[i, 1])),
            size=int(fs.sizes[i]), gain=float(gain[i]), importance=float(imp[i]),
        )
        for i in range(n)
    ]
    return Frontiers(tick=tick, frontiers=items, complete=complete, assigned=assigned)
