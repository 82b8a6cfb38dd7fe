"""The observable truth points bucketed in cells a bit larger than the coverage radius: every
truth point within the radius of a point lies in that point's cell or one of its 26
neighbours, so a change to a map only looks at the truth around it.

Cells are numbered in a dense box one cell larger than the truth's on every side (a table of
cell → bucket), so a neighbourhood is 27 look-ups and no sort; a point outside the box is
clamped to its border cell, which gives a superset, never less. A box too large for the table
(`MAX_TABLE_CELLS`) falls back to sorted packed keys.
"""

from __future__ import annotations

import numpy as np

from services.common import voxels
from services.common.arrays import unique_sorted

MAX_TABLE_CELLS = 1 << 25  # 128 MB of int32: a 400 m × 400 m × 12 m world at 12.5 cm cells


def _offsets(strides: tuple[int, int, int]) -> np.ndarray:
    """Cell-number offsets of a cell's 3×3×3 neighbourhood."""
    d = np.array([-1, 0, 1], np.int64)
    dx, dy, dz = np.meshgrid(d, d, d, indexing="ij")
    return (dx * strides[0] + dy * strides[1] + dz * strides[2]).ravel()


class TruthIndex:
    """Truth points by cell: `cells_of` numbers cells, `around` lists the truth near points,
    `near_cells` tells which cells neighbour some truth points' cells."""

    def __init__(self, points: np.ndarray, radius_m: float) -> None:
        self.points, self.radius_m = points, radius_m
        self.cell_m = radius_m * (1 + 1e-6)  # the margin keeps float rounding off the bound
        # a point in a truth point's own cell of side radius/2 lies within 0.87·radius of it
        self.fine_m = radius_m / 2
        self.fine = self.fine_cells_of(points)
        self.fine_shifted = self.fine_cells_of(points, shifted=True)
        idx = voxels.voxel_indices(points, self.cell_m).reshape(-1, 3)
        self.lo = idx.min(axis=0) - 1 if len(idx) else np.zeros(3, np.int64)
        self.shape = (idx.max(axis=0) + 2 - self.lo) if len(idx) else np.full(3, 3, np.int64)
        self.dense = int(np.prod(self.shape)) <= MAX_TABLE_CELLS
        if self.dense:
            self.strides = (int(self.shape[1] * self.shape[2]), int(self.shape[2]), 1)
        else:  # packed keys: fields do not overflow, indices stay far inside ±2^20
            self.strides = (1 << 42, 1 << 21, 1)
        self.offsets = _offsets(self.strides)
        cells = self.cells_of(points)
        self.order = np.argsort(cells, kind="stable")
        self.buckets, self.starts, self.counts = np.unique(
            cells[self.order], return_index=True, return_counts=True)
        if self.dense:
            self.slot = np.full(int(np.prod(self.shape)), -1, np.int32)
            self.slot[self.buckets] = np.arange(self.buckets.size, dtype=np.int32)

    def __len__(self) -> int:
        return len(self.points)

    def fine_cells_of(self, pts: np.ndarray, shifted: bool = False) -> np.ndarray:
        """(N,) int64 packed key of each point's cell of side radius/2, in the grid shifted
        by half a cell on every axis when `shifted` (a second chance at sharing a cell)."""
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
        if shifted:
            pts = pts + self.fine_m / 2
        return voxels.pack(voxels.voxel_indices(pts, self.fine_m).reshape(-1, 3))

    def cells_of(self, pts: np.ndarray) -> np.ndarray:
        """(N,) int64 cell number of each point."""
        idx = voxels.voxel_indices(pts, self.cell_m).reshape(-1, 3)
        if not self.dense:
            return voxels.pack(idx)
        idx = np.clip(idx - self.lo, 1, self.shape - 2)
        return idx[:, 0] * self.strides[0] + idx[:, 1] * self.strides[1] + idx[:, 2]

    def _neighbourhood(self, cells: np.ndarray) -> np.ndarray:
        """Cell numbers around the given cells (with repeats)."""
        return (unique_sorted(cells)[:, None] + self.offsets[None, :]).ravel()

    def around(self, pts: np.ndarray) -> np.ndarray:
        """Indices of the truth points in the cells around `pts` (a superset of those
        within the radius of one of them)."""
        return self.around_cells(self.cells_of(pts) if len(pts) else np.zeros(0, np.int64))

    def around_cells(self, cells: np.ndarray) -> np.ndarray:
        """`around` of points whose `cells_of` is known."""
        if cells.size == 0 or self.buckets.size == 0:
            return np.zeros(0, np.int64)
        near = self._neighbourhood(cells)
        if self.dense:
            slots = self.slot[near]
            mark = np.zeros(self.buckets.size, bool)
            mark[slots[slots >= 0]] = True
            which = np.flatnonzero(mark)
        else:
            near = unique_sorted(near)
            pos = np.minimum(np.searchsorted(self.buckets, near), self.buckets.size - 1)
            which = pos[self.buckets[pos] == near]
        lens = self.counts[which]
        idx = np.repeat(self.starts[which] - np.cumsum(lens) + lens, lens)
        return self.order[idx + np.arange(idx.size)]

    def near_cells(self, point_cells: np.ndarray, truth_idx: np.ndarray) -> np.ndarray:
        """(N,) bool per point cell (`cells_of`): among the cells around the truth points
        `truth_idx`, where every point within the radius of one of them lies."""
        near = self._neighbourhood(self.cells_of(self.points[truth_idx]))
        if self.dense:
            mark = np.zeros(self.slot.size, bool)
            mark[near] = True
            return mark[point_cells]
        return np.isin(point_cells, near)
