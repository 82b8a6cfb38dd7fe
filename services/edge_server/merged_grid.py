"""The merged 2D grid: free floor cells of every placed submap, obstacles from P*.

Free = the free floor cells of all submaps placed by their poses; occupied = P* voxels whose
centre lies in the obstacle band (z between `obstacle_z_min_m` and `obstacle_z_max_m`), and
occupied wins over free; unknown otherwise. Bounds are fixed by `grid_bounds_m` or grow (never
shrink) in steps of `grid_chunk_m` to fit the data, so cell indices stay stable between plans.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.arrays import column_extremes, missing_rows_2, union_rows_2, unique_rows_2
from services.common.grid import GridSpec
from services.common.voxels import centres, unpack
from services.edge_server.cell_counts import CellCounts
from services.edge_server.config import EdgeConfig
from services.edge_server.merged_map import MergedMap
from services.edge_server.submap_store import StoredSubmap, SubmapKey, SubmapStore

Stamp = tuple[int, int, float]  # a submap's (version, pose_version, cell_m)

UNKNOWN, FREE, OCCUPIED = -1, 0, 100


@dataclass(frozen=True)
class GridSnapshot:
    """One merged grid: spec, int8 cells (-1/0/100) and boolean masks of the same shape."""

    spec: GridSpec
    cells: np.ndarray
    free: np.ndarray
    occupied: np.ndarray

    @property
    def known(self) -> np.ndarray:
        return self.free | self.occupied


# 2×2 samples per free cell: a rotated submap's cell centres alone leave holes in the world
# grid (spurious frontiers); samples c/2 apart hit every world cell a cell set covers
# (covering radius 0.35·c < the world cell's inner radius 0.5·c).
_SUBSAMPLES = np.array([[0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [0.75, 0.75]])


def free_cells_world(sm: StoredSubmap, free_cells: np.ndarray | None = None) -> np.ndarray:
    """(4M, 2) world xy sampling a submap's free cells (cell i covers [i·c, (i+1)·c)); of
    `free_cells` (some of them) when given."""
    cells = (sm.free_cells if free_cells is None else free_cells).astype(np.float64)
    xy_submap = ((cells[:, None, :] + _SUBSAMPLES[None]) * sm.cell_m).reshape(-1, 2)
    return xy_submap @ sm.T_world_submap[:2, :2].T + sm.T_world_submap[:2, 3]


def grow_bounds(
    old: tuple[float, float, float, float] | None, xy: np.ndarray, margin_m: float, chunk_m: float
) -> tuple[float, float, float, float] | None:
    """(xmin, ymin, xmax, ymax) covering `old` and `xy` plus a margin, snapped to `chunk_m`."""
    if xy.shape[0] == 0:
        return old
    lo = np.floor((xy.min(axis=0) - margin_m) / chunk_m) * chunk_m
    hi = np.ceil((xy.max(axis=0) + margin_m) / chunk_m) * chunk_m
    if old is not None:
        lo = np.minimum(lo, old[:2])
        hi = np.maximum(hi, old[2:])
    return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))


def world_cells(xy: np.ndarray, resolution_m: float) -> np.ndarray:
    """(K, 2) unique absolute (row, col) cells of a grid with its origin at (0, 0)."""
    rc = np.floor(xy[:, ::-1] / resolution_m).astype(np.int64)
    return unique_rows_2(rc)


def _mark(mask: np.ndarray, spec: GridSpec, abs_rc: np.ndarray) -> None:
    """Set absolute cells (origin (0, 0)) in a grid whose origin is a multiple of the cell."""
    offset = np.round(np.array([spec.origin_y, spec.origin_x]) / spec.resolution_m)
    rc = abs_rc - offset.astype(np.int64)
    rc = rc[spec.contains(rc)]
    mask[rc[:, 0], rc[:, 1]] = True


class MergedGrid:
    """Builds the merged grid from the store and P*, caching each submap's world free cells."""

    def __init__(self, config: EdgeConfig) -> None:
        self.config = config
        self.bounds = config.grid_bounds_m
        # per submap: (stamp, absolute free cells, the submap's free cells they came from)
        self._free_rc: dict[SubmapKey, tuple[Stamp, np.ndarray, np.ndarray]] = {}
        self._obstacle_rc: tuple[int, np.ndarray] = (-1, np.zeros((0, 2), np.int64))
        self._obstacle_counts = CellCounts()  # P*'s band voxels per cell
        # the stable submaps' free cells counted: each one's stamp and the cells it added
        self._stable: dict[SubmapKey, tuple[Stamp, np.ndarray]] = {}
        self._stable_counts = CellCounts()

    def _all_free_rc(self, store: SubmapStore) -> list[np.ndarray]:
        """Absolute world cells of each robot's newest submap's free cells, and all the
        others' counted in `_stable_counts` (those rarely change, and overlapping submaps
        repeat most cells); cached per submap version."""
        cells: dict[SubmapKey, np.ndarray] = {}
        stamps: dict[SubmapKey, Stamp] = {}
        for sm in store.ordered():
            stamp = (sm.version, sm.pose_version, sm.cell_m)
            cached = self._free_rc.get(sm.key)
            if cached is None or cached[0] != stamp:
                cached = (stamp, self._world_free(sm, cached), sm.free_cells)
                self._free_rc[sm.key] = cached
            cells[sm.key], stamps[sm.key] = cached[1], stamp
        newest = {robot: max(k for k in cells if k[0] == robot) for robot in {k[0] for k in cells}}
        stable = {k: stamps[k] for k in sorted(cells) if k not in newest.values()}
        self._count_stable(stable, cells)
        return [cells[k] for k in sorted(newest.values())]

    def _count_stable(self, stable: dict[SubmapKey, Stamp],
                      cells: dict[SubmapKey, np.ndarray]) -> None:
        """Bring the counts to the `stable` submaps' cells: a submap that left the set, moved
        or grew takes its old cells out, and one that joined, moved or grew puts its
        current cells in."""
        counts = self._stable_counts
        for key in sorted(self._stable):
            stamp, rc = self._stable[key]
            if stable.get(key) != stamp:
                counts.add(rc, -1)
                del self._stable[key]
        for key, stamp in stable.items():
            if key not in self._stable:
                counts.add(cells[key], +1)
                self._stable[key] = (stamp, cells[key])

    def _world_free(self, sm: StoredSubmap,
                    cached: tuple[Stamp, np.ndarray, np.ndarray] | None) -> np.ndarray:
        """A submap's free cells as absolute grid cells; where only its free cells grew
        since `cached` (same pose and cell size), only the new ones are converted."""
        res = self.config.grid_resolution_m
        if cached is None or cached[0][1:] != (sm.pose_version, sm.cell_m):
            return world_cells(free_cells_world(sm), res)
        new = missing_rows_2(sm.free_cells, cached[2])
        return union_rows_2(cached[1], world_cells(free_cells_world(sm, new), res))

    def _free_mask(self, spec: GridSpec, newest: list[np.ndarray]) -> np.ndarray:
        """The free cells of every submap on the grid `spec`: the stable ones' counts, then
        the newest submaps' cells."""
        free = np.zeros(spec.shape, bool)
        self._stable_counts.draw(free, spec)
        for rc in newest:
            _mark(free, spec, rc)
        return free

    @staticmethod
    def _extremes_xy(rc: np.ndarray, res: float) -> np.ndarray:
        """(2, 2) the lowest and highest cell-centre xy of absolute cells `rc`: the centre
        is monotone in the index, so these equal the extremes of every cell's centre."""
        if rc.shape[0] == 0:
            return np.zeros((0, 2))
        return (np.stack(column_extremes(rc))[:, ::-1] + 0.5) * res

    def _count_obstacles(self, merged: MergedMap) -> np.ndarray:
        """Absolute cells under P*'s voxels in the obstacle band, counted per voxel: after
        one update only the voxels it added and removed are counted in and out (P* is
        large), else all of them again."""
        res, counts = self.config.grid_resolution_m, self._obstacle_counts
        if 0 <= self._obstacle_rc[0] == merged.version - 1:
            for keys, sign in ((merged.removed_keys, -1), (merged.added_keys, +1)):
                xy = self._band_xy(centres(unpack(keys), merged.voxel_m))
                counts.add(np.floor(xy[:, ::-1] / res).astype(np.int64), sign)
        else:
            self._obstacle_counts = counts = CellCounts()
            xy = self._band_xy(merged.centres_world)
            counts.add(np.floor(xy[:, ::-1] / res).astype(np.int64), +1)
        return counts.held()

    def _band_xy(self, points_world: np.ndarray) -> np.ndarray:
        z = points_world[:, 2]
        band = (z >= self.config.obstacle_z_min_m) & (z <= self.config.obstacle_z_max_m)
        return points_world[band, :2]

    def spec(self) -> GridSpec | None:
        if self.bounds is None:
            return None
        res = self.config.grid_resolution_m
        lo = np.floor(np.array(self.bounds[:2]) / res) * res  # origin on a cell multiple
        hi = np.array(self.bounds[2:])
        width, height = np.maximum(np.ceil((hi - lo) / res - 1e-9).astype(int), 1)
        return GridSpec(float(lo[0]), float(lo[1]), res, int(height), int(width))

    def update(
        self, store: SubmapStore, merged: MergedMap, extra_xy: np.ndarray | None = None
    ) -> GridSnapshot | None:
        """The grid for the current data; `extra_xy` (e.g. robot positions) must fit too."""
        res = self.config.grid_resolution_m
        newest_rc = self._all_free_rc(store)
        if self._obstacle_rc[0] != merged.version:
            self._obstacle_rc = (merged.version, self._count_obstacles(merged))
        obstacle_rc = self._obstacle_rc[1]
        if self.config.grid_bounds_m is None:
            held = self._stable_counts.extremes()
            xy = [self._extremes_xy(rc, res) for rc in [held, *newest_rc, obstacle_rc]]
            xy += [extra_xy] if extra_xy is not None else []
            self.bounds = grow_bounds(
                self.bounds, np.concatenate(xy), self.config.grid_margin_m, self.config.grid_chunk_m
            )
        spec = self.spec()
        if spec is None:
            return None
        free = self._free_mask(spec, newest_rc)
        occupied = np.zeros(spec.shape, bool)
        _mark(occupied, spec, obstacle_rc)
        free &= ~occupied
        cells = np.full(spec.shape, UNKNOWN, np.int8)
        cells[free] = FREE
        cells[occupied] = OCCUPIED
        return GridSnapshot(spec, cells, free, occupied)
