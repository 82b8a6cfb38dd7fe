"""Per-robot path-length fields on the traversable grid, computed only when a plan needs them.

Which cells a robot can reach needs no Dijkstra: moves are 8-connected without corner cutting,
so the reachable set is the robot's 4-connected component (planning.reachable). Path lengths
are only needed for robots that need a new goal; they are computed on the bounding window of
the robot's component (cells outside it are unreachable), robots sharing a component in one
Dijkstra. Most plans every robot keeps its goal and no field is computed at all.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from services.common.planning import distance_fields, inflate


def snap_start(traversable: np.ndarray, rc: tuple[int, int], snap_cells: float
               ) -> tuple[int, int] | None:
    """The traversable cell nearest `rc` within `snap_cells` (EDT on a window around it)."""
    H, W = traversable.shape
    r, c = rc
    if not (0 <= r < H and 0 <= c < W):
        return None
    k = int(np.ceil(snap_cells)) + 1
    r0, c0 = max(r - k, 0), max(c - k, 0)
    window = traversable[r0 : r + k + 1, c0 : c + k + 1]
    if not window.any():
        return None
    offset, nearest = ndimage.distance_transform_edt(~window, return_indices=True)
    if offset[r - r0, c - c0] > snap_cells:
        return None
    return int(nearest[0][r - r0, c - c0]) + r0, int(nearest[1][r - r0, c - c0]) + c0


class RobotFields:
    """Snapped starts, components and lazily computed distance fields (cells) per robot."""

    def __init__(self, traversable: np.ndarray, starts_rc: dict[int, np.ndarray],
                 snap_cells: float, island_cells: int = 0) -> None:
        """A start off the traversable grid snaps to the nearest traversable cell within
        `snap_cells` (the floor under a robot is never seen); farther, the robot reaches
        nothing. A start on an island of fewer than `island_cells` cells snaps, within the
        same distance, to a larger component: the robot drove in, so it can drive out, and
        the map's inflated obstacles merely pinch the way (0: islands are kept)."""
        self.traversable = traversable
        self.shape = traversable.shape
        self.labels, _ = ndimage.label(traversable)
        sizes = np.bincount(self.labels.ravel())
        sizes[0] = 0
        mainland: np.ndarray | None = None
        self.starts: dict[int, tuple[int, int]] = {}
        for robot, (r, c) in starts_rc.items():
            snapped = snap_start(traversable, (int(r), int(c)), snap_cells)
            if snapped is not None and sizes[self.labels[snapped]] < island_cells:
                if mainland is None:
                    mainland = sizes[self.labels] >= island_cells
                snapped = snap_start(mainland, (int(r), int(c)), snap_cells) or snapped
            if snapped is not None:
                self.starts[robot] = snapped
        self.component = {robot: int(self.labels[rc]) for robot, rc in self.starts.items()}
        self.reachable = np.isin(self.labels, sorted(set(self.component.values())))
        self.robots = sorted(starts_rc)
        self._fields: dict[int, np.ndarray] = {}

    def reaches(self, robot: int, rc: np.ndarray) -> np.ndarray:
        """(N,) bool: whether `robot` can reach the (N, 2) in-grid cells `rc`."""
        lab = self.component.get(robot)
        rc = np.asarray(rc).reshape(-1, 2)
        if lab is None:
            return np.zeros(len(rc), bool)
        return self.labels[rc[:, 0], rc[:, 1]] == lab

    def compute(self, robots: list[int]) -> None:
        """Compute the fields of `robots` (one Dijkstra per component and window)."""
        todo = [r for r in robots if r not in self._fields]
        for robot in todo:
            if robot not in self.starts:
                self._fields[robot] = np.full(self.shape, np.inf)
        for lab in sorted({self.component[r] for r in todo if r in self.starts}):
            group = [r for r in todo if self.component.get(r) == lab]
            mask = self.labels == lab
            rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
            r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
            stack = distance_fields(mask[r0:r1, c0:c1],
                                    [(self.starts[r][0] - r0, self.starts[r][1] - c0)
                                     for r in group])
            for robot, window in zip(group, stack, strict=True):
                full = np.full(self.shape, np.inf)
                full[r0:r1, c0:c1] = window
                self._fields[robot] = full

    def __getitem__(self, robot: int) -> np.ndarray:
        """(H, W) path length in cells from the robot's start; inf where unreachable."""
        self.compute([robot])
        return self._fields[robot]


class InflationCache:
    """`inflate(occupied, r)` kept between plans: while the grid keeps its shape and no cell
    stops being occupied, only the window around newly occupied cells is dilated again."""

    def __init__(self) -> None:
        self._occupied: np.ndarray | None = None
        self._inflated: np.ndarray | None = None
        self._radius = -1

    def __call__(self, occupied: np.ndarray, radius_cells: int) -> np.ndarray:
        old = self._occupied
        if (old is None or old.shape != occupied.shape or radius_cells != self._radius
                or (old & ~occupied).any()):
            inflated = inflate(occupied, radius_cells)
        else:
            inflated = self._inflated.copy()
            added = occupied & ~old
            if added.any():
                rows, cols = np.flatnonzero(added.any(axis=1)), np.flatnonzero(added.any(axis=0))
                H, W = occupied.shape
                # the dilation of cells in the window reaches at most r beyond it
                r0, r1 = max(rows[0] - radius_cells, 0), min(rows[-1] + radius_cells + 1, H)
                c0, c1 = max(cols[0] - radius_cells, 0), min(cols[-1] + radius_cells + 1, W)
                inflated[r0:r1, c0:c1] |= inflate(added[r0:r1, c0:c1], radius_cells)
        self._occupied, self._inflated, self._radius = occupied.copy(), inflated, radius_cells
        return inflated.copy()


def all_fields(
    traversable: np.ndarray, starts_rc: dict[int, np.ndarray], snap_cells: float
) -> dict[int, np.ndarray]:
    """Every robot's path-length field (cells), computed now (tests, benchmarks)."""
    fields = RobotFields(traversable, starts_rc, snap_cells)
    fields.compute(fields.robots)
    return {robot: fields[robot] for robot in fields.robots}
