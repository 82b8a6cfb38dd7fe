"""The agent's local 2D occupancy grid (world frame), from depth rays and the edge's grid.

Each frame, cells along the 2D projection of every depth ray up to its hit are seen free and
cells holding points in the obstacle height band are hit; a clamped log-odds per cell fuses
frames, so a low obstacle that rays pass over stays occupied (hits outweigh misses) while a
teammate that drove away is cleared after a few frames. The agent plans on its own grid where
it has seen a cell and on the edge's merged grid elsewhere: its own fresh view wins.
"""

from __future__ import annotations

import numpy as np

from schemas.messages import OccupancyGrid
from services.common.arrays import column_extremes
from services.common.grid import GridSpec

UNKNOWN, FREE, OCCUPIED = -1, 0, 100
_HIT, _MISS, _LO, _HI = 0.9, -0.4, -2.0, 3.5


def ray_samples(
    origin_xy: np.ndarray, hits_xy: np.ndarray, step_m: float, stop_m: float
) -> np.ndarray:
    """(M, 2) points every `step_m` along the segments origin → hit, ending `stop_m` short."""
    d = hits_xy - origin_xy[None, :]
    length = np.hypot(d[:, 0], d[:, 1])
    n = np.maximum(np.floor((length - stop_m) / step_m).astype(np.int64) + 1, 0)
    total = int(n.sum())
    if total == 0:
        return np.empty((0, 2))
    ray = np.repeat(np.arange(len(n)), n)
    first = np.repeat(np.cumsum(n) - n, n)
    t = (np.arange(total) - first) * step_m
    unit = d[ray] / np.maximum(length[ray], 1e-9)[:, None]
    return origin_xy[None, :] + unit * t[:, None]


def floor_rays(
    points_base: np.ndarray, cam_xy_base: np.ndarray, z_min: float, z_max: float,
    cell_m: float, bin_rad: float,
) -> np.ndarray:
    """Free floor samples (base-frame xy) from a depth frame seen as a 2D laser scan.

    Points are binned by bearing from the camera; in each bin the free ray runs to one cell
    short of the nearest obstacle-band hit (z_min < z ≤ z_max), or, when the bin has none, to
    its farthest floor hit (z ≤ z_min). One ray per bin instead of one per pixel: ~150 rays
    at 160×120 whatever the resolution.
    """
    rel = points_base[:, :2] - cam_xy_base[None, :]
    z = points_base[:, 2]
    bins = np.floor((np.arctan2(rel[:, 1], rel[:, 0]) + np.pi) / bin_rad).astype(np.int64)
    n_bins = int(np.ceil(2 * np.pi / bin_rad)) + 1
    r = np.hypot(rel[:, 0], rel[:, 1])
    obstacle, floor = (z > z_min) & (z <= z_max), z <= z_min
    obst_r = np.full(n_bins, np.inf)
    np.minimum.at(obst_r, bins[obstacle], r[obstacle])
    floor_r = np.zeros(n_bins)
    np.maximum.at(floor_r, bins[floor], r[floor])
    length = np.where(np.isfinite(obst_r), obst_r - cell_m, floor_r)
    used = np.nonzero(length > 0)[0]
    bearing = (used + 0.5) * bin_rad - np.pi
    ends = cam_xy_base[None, :] + length[used, None] * np.stack(
        [np.cos(bearing), np.sin(bearing)], 1
    )
    return ray_samples(cam_xy_base, ends, step_m=cell_m * 0.5, stop_m=0.0)


class LocalGrid:
    """World grid made around the spawn, grown when a goal lies beyond it: own log-odds layer
    over the edge's merged grid."""

    def __init__(self, spec: GridSpec) -> None:
        self.spec = spec
        self.logodds = np.zeros(spec.shape, np.float32)
        self.seen = np.zeros(spec.shape, bool)
        self.edge = np.full(spec.shape, UNKNOWN, np.int8)
        self.row_lo, self.row_hi = spec.height, -1  # bounding box of known cells
        self.col_lo, self.col_hi = spec.width, -1

    @staticmethod
    def centred(x: float, y: float, half_size_m: float, cell_m: float) -> LocalGrid:
        lo, hi = np.array([x, y]) - half_size_m, np.array([x, y]) + half_size_m
        return LocalGrid(GridSpec.covering(lo, hi, cell_m))

    def cover(self, xy_world: np.ndarray, margin_m: float) -> bool:
        """When a (N, 2) point lies outside the grid, grow it (whole cells, same alignment)
        to hold every point with `margin_m` around it; True when it grew. A world larger than
        the grid made at spawn (the warehouse is 40 m long) otherwise has goals "outside the
        local grid"."""
        spec, cell = self.spec, self.spec.resolution_m
        xy = np.asarray(xy_world, np.float64).reshape(-1, 2)
        if spec.contains(spec.cell_of(xy)).all():
            return False
        xy_lo, xy_hi = column_extremes(xy)
        lo = np.floor((xy_lo - margin_m - [spec.origin_x, spec.origin_y]) / cell)
        hi = np.ceil((xy_hi + margin_m - [spec.origin_x, spec.origin_y]) / cell)
        before = np.maximum(-lo, 0).astype(int)  # cells to add below (x, y)
        after = np.maximum(hi - [spec.width, spec.height], 0).astype(int)
        if not (before.any() or after.any()):
            return False
        pad = ((before[1], after[1]), (before[0], after[0]))  # (rows = y, cols = x)
        self.logodds = np.pad(self.logodds, pad)
        self.seen = np.pad(self.seen, pad)
        self.edge = np.pad(self.edge, pad, constant_values=UNKNOWN)
        self.spec = GridSpec(spec.origin_x - before[0] * cell, spec.origin_y - before[1] * cell,
                             cell, *self.logodds.shape)
        if self.row_hi >= self.row_lo:  # the known box moves with the origin
            self.row_lo, self.row_hi = self.row_lo + before[1], self.row_hi + before[1]
            self.col_lo, self.col_hi = self.col_lo + before[0], self.col_hi + before[0]
        else:
            self.row_lo, self.col_lo = self.spec.height, self.spec.width
        return True

    def _flat(self, xy_world: np.ndarray) -> np.ndarray:
        rc = self.spec.cell_of(xy_world)
        inside = self.spec.contains(rc)
        if not inside.all():  # rare (50 m grid): skip the copy
            rc = rc[inside]
        self._extend(rc)
        return rc[:, 0] * self.spec.width + rc[:, 1]  # duplicates are fine: a[i] += x adds once

    def _extend(self, rc: np.ndarray) -> None:
        if rc.shape[0]:
            lo, hi = column_extremes(rc)
            self.row_lo, self.row_hi = min(self.row_lo, int(lo[0])), max(self.row_hi, int(hi[0]))
            self.col_lo, self.col_hi = min(self.col_lo, int(lo[1])), max(self.col_hi, int(hi[1]))

    def update(self, free_xy_world: np.ndarray, occupied_xy_world: np.ndarray) -> None:
        """Fuse one frame: free samples and obstacle points, both (N, 2) world xy."""
        lo, seen = self.logodds.reshape(-1), self.seen.reshape(-1)
        free, occ = self._flat(free_xy_world), self._flat(occupied_xy_world)
        lo[free] += _MISS
        lo[occ] += _HIT
        touched = np.concatenate([free, occ])  # clipping is idempotent: one pass for both
        lo[touched] = np.clip(lo[touched], _LO, _HI)
        seen[touched] = True

    def merge_edge(self, grid: OccupancyGrid) -> None:
        """Replace the edge layer with the edge's latest merged grid."""
        src = GridSpec(grid.origin_x, grid.origin_y, grid.resolution_m, *grid.cells.shape)
        self.edge[:] = UNKNOWN
        off = np.array([src.origin_y - self.spec.origin_y, src.origin_x - self.spec.origin_x])
        off_cells = off / self.spec.resolution_m
        aligned = abs(src.resolution_m - self.spec.resolution_m) < 1e-9 and np.allclose(
            off_cells, np.round(off_cells), atol=1e-6
        )
        window = (slice(0, 0), slice(0, 0))
        if aligned:
            window = self._paste(grid.cells, np.round(off_cells).astype(np.int64))
        else:  # resample by cell centres (nearest)
            rc_src = np.argwhere(grid.cells != UNKNOWN)
            rc = self.spec.cell_of(src.centre_of(rc_src))
            ok = self.spec.contains(rc)
            self.edge[rc[ok, 0], rc[ok, 1]] = grid.cells[rc_src[ok, 0], rc_src[ok, 1]]
            window = (slice(0, self.spec.height), slice(0, self.spec.width))
        self._extend_known(*window)

    def _extend_known(self, rows: slice, cols: slice) -> None:
        """Grow the known box by the edge layer's known cells, all inside rows × cols (the
        pasted window: scanning the whole 50 m grid cost more than the paste)."""
        known = self.edge[rows, cols] != UNKNOWN
        r, c = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
        if r.size:
            r0, c0 = rows.start, cols.start
            self._extend(np.array([[r0 + r[0], c0 + c[0]], [r0 + r[-1], c0 + c[-1]]]))

    def _paste(self, cells: np.ndarray, off_rc: np.ndarray) -> tuple[slice, slice]:
        """Copy `cells` in at row/col offset `off_rc`; the window of the grid written."""
        h, w = cells.shape
        r0, c0 = int(off_rc[0]), int(off_rc[1])
        dr0, dc0 = max(0, r0), max(0, c0)
        dr1, dc1 = min(self.spec.height, r0 + h), min(self.spec.width, c0 + w)
        if dr1 > dr0 and dc1 > dc0:
            self.edge[dr0:dr1, dc0:dc1] = cells[dr0 - r0 : dr1 - r0, dc0 - c0 : dc1 - c0]
            return slice(dr0, dr1), slice(dc0, dc1)
        return slice(0, 0), slice(0, 0)

    def cells(self, rows: slice = slice(None), cols: slice = slice(None)) -> np.ndarray:
        """(H, W) int8 combined grid (or a window of it): -1 unknown, 0 free, 100 occupied."""
        own = np.where(self.logodds[rows, cols] > 0, OCCUPIED, FREE).astype(np.int8)
        return np.where(self.seen[rows, cols], own, self.edge[rows, cols])

    def values_at(self, rc: np.ndarray) -> np.ndarray:
        """(N,) int8 combined values at in-bounds (row, col) cells."""
        r, c = rc[:, 0], rc[:, 1]
        own = np.where(self.logodds[r, c] > 0, OCCUPIED, FREE).astype(np.int8)
        return np.where(self.seen[r, c], own, self.edge[r, c])

    def window(self, margin_cells: int, extra_rc: np.ndarray | None = None) -> tuple[slice, slice]:
        """Row/col slices covering every known cell (and `extra_rc`) plus a margin."""
        r_lo, r_hi, c_lo, c_hi = self.row_lo, self.row_hi, self.col_lo, self.col_hi
        if extra_rc is not None and extra_rc.size:
            r_lo, r_hi = min(r_lo, extra_rc[:, 0].min()), max(r_hi, extra_rc[:, 0].max())
            c_lo, c_hi = min(c_lo, extra_rc[:, 1].min()), max(c_hi, extra_rc[:, 1].max())
        if r_hi < r_lo:
            return slice(0, 0), slice(0, 0)
        H, W = self.spec.shape
        return (
            slice(max(0, int(r_lo) - margin_cells), min(H, int(r_hi) + margin_cells + 1)),
            slice(max(0, int(c_lo) - margin_cells), min(W, int(c_hi) + margin_cells + 1)),
        )
