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
        self._stable: tuple[dict[SubmapKey, Stamp], np.ndarray] = ({}, np.zeros((0, 2), np.int64))
        # the stable union drawn on a grid: (spec, mask), and the cells it gained since (None:
        # it lost some, draw it again)
        self._stable_mask: tuple[GridSpec | None, np.ndarray] = (None, np.zeros((0, 0), bool))
        self._stable_gained: list[np.ndarray] | None = None

    def _all_free_rc(self, store: SubmapStore) -> tuple[np.ndarray, list[np.ndarray]]:
        """Absolute world cells of every submap's free cells, cached per submap version: the
        deduplicated union of all but each robot's newest submap (those rarely change, and
        overlapping submaps repeat most cells), and the newest submaps' cells."""
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
        if stable != self._stable[0]:
            self._stable = (stable, self._stable_union(stable, cells))
        return self._stable[1], [cells[k] for k in sorted(newest.values())]

    def _world_free(self, sm: StoredSubmap,
                    cached: tuple[Stamp, np.ndarray, np.ndarray] | None) -> np.ndarray:
        """A submap's free cells as absolute grid cells; where only its free cells grew
        since `cached` (same pose and cell size), only the new ones are converted."""
        res = self.config.grid_resolution_m
        if cached is None or cached[0][1:] != (sm.pose_version, sm.cell_m):
            return world_cells(free_cells_world(sm), res)
        new = missing_rows_2(sm.free_cells, cached[2])
        return union_rows_2(cached[1], world_cells(free_cells_world(sm, new), res))

    def _stable_union(self, stable: dict[SubmapKey, Stamp],
                      cells: dict[SubmapKey, np.ndarray]) -> np.ndarray:
        """The deduplicated cells of the `stable` submaps. A submap's free cells only grow
        while its pose and cell size stay (SubmapStore.apply), so when no submap left the set
        or moved, the cached union only takes the changed submaps' cells in."""
        before, union = self._stable
        grown = before.keys() <= stable.keys() and all(
            stable[k][1:] == stamp[1:] for k, stamp in before.items())
        if not grown:
            self._stable_gained = None
            return (unique_rows_2(np.concatenate([cells[k] for k in stable])) if stable
                    else np.zeros((0, 2), np.int64))
        changed = np.concatenate([cells[k] for k, stamp in stable.items()
                                  if before.get(k) != stamp])
        if self._stable_gained is not None:
            self._stable_gained.append(changed)
        return union_rows_2(union, changed)

    def _free_mask(self, spec: GridSpec, newest: list[np.ndarray]) -> np.ndarray:
        """The free cells of every submap on the grid `spec`: the stable union's drawing
        (kept while the grid's geometry stays, with the cells it gained drawn in), then the
        newest submaps' cells."""
        drawn_spec, mask = self._stable_mask
        if drawn_spec != spec or self._stable_gained is None:
            mask = np.zeros(spec.shape, bool)
            _mark(mask, spec, self._stable[1])
        else:
            for rc in self._stable_gained:
                _mark(mask, spec, rc)
        self._stable_mask, self._stable_gained = (spec, mask), []
        free = mask.copy()
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
        stable_rc, newest_rc = self._all_free_rc(store)
        if self._obstacle_rc[0] != merged.version:
            added = getattr(merged, "added_keys", None)
            if self._obstacle_rc[0] == merged.version - 1 and added is not None:
                # one delta since the last grid: only the new voxels' band cells (P* is large)
                new_rc = world_cells(self._band_xy(centres(unpack(added), merged.voxel_m)), res)
                rc = union_rows_2(self._obstacle_rc[1], new_rc)
            else:
                rc = world_cells(self._band_xy(merged.centres_world), res)
            self._obstacle_rc = (merged.version, rc)
        obstacle_rc = self._obstacle_rc[1]
        if self.config.grid_bounds_m is None:
            xy = [self._extremes_xy(rc, res) for rc in [stable_rc, *newest_rc, obstacle_rc]]
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
