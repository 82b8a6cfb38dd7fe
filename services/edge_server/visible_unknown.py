"""Unknown floor a robot at a cell would see: the 2D view gain of a goal.

Only unknown floor that exploring can still reach counts ("live"): the unknown components of
the grid that border a free/unknown frontier cluster of at least `min_frontier_cells`. The
inside of a cabinet, or the world behind a wall seen whole, is unknown for good and counts
nothing; once the grid has no long frontier left the term is zero everywhere and the 3D
regions alone decide. From each goal cell, `n_rays` rays run out to `range_m`; each sample
stands for the area r·Δθ·Δr of its annulus sector and counts while it is live unknown and no
occupied cell came before it on its ray (a wall hides what is behind it; unknown space does
not). A door to an unmapped room is then worth the room within range, a speck under a chair
nothing. The grid is padded by the range with unknown cells, which join the unknown around it.

Pure functions on grids and arrays.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from services.common.grid import GridSpec
from services.edge_server.frontiers import EIGHT, frontier_cells


def live_unknown(free: np.ndarray, known: np.ndarray, min_frontier_cells: int) -> np.ndarray:
    """(H, W) bool: unknown cells 8-connected to a frontier cluster of that many cells."""
    unknown = ~known
    labels, n = ndimage.label(unknown, structure=EIGHT)
    front, count = ndimage.label(frontier_cells(free, known), structure=EIGHT)
    sizes = np.bincount(front.ravel(), minlength=count + 1)
    long_front = (sizes >= min_frontier_cells)[front] & (front > 0)
    touching = ndimage.binary_dilation(long_front, structure=EIGHT) & unknown
    keep = np.zeros(n + 1, bool)
    keep[np.unique(labels[touching])] = True
    keep[0] = False
    return keep[labels]


def visible_unknown_m2(occupied: np.ndarray, target: np.ndarray, cells_rc: np.ndarray,
                       spec: GridSpec, range_m: float, n_rays: int = 48) -> np.ndarray:
    """(N,) m² of `target` cells (live unknown) in line of sight within `range_m` of each
    (row, col) cell; off the grid counts as target where the grid's edge is."""
    n = len(cells_rc)
    steps = int(np.ceil(range_m / spec.resolution_m))
    if not n or steps <= 0:
        return np.zeros(n)
    # off the grid: live where live unknown reaches the grid's edge
    at_edge = bool(target[0].any() or target[-1].any() or target[:, 0].any()
                   or target[:, -1].any())
    pad_target = np.pad(target, steps, constant_values=at_edge)
    pad_occ = np.pad(occupied, steps)
    dr = spec.resolution_m
    r_m = (np.arange(steps) + 0.5) * dr  # (J,)
    theta = (np.arange(n_rays) + 0.5) * (2 * np.pi / n_rays)
    d_row = np.rint(np.sin(theta)[:, None] * r_m[None, :] / dr).astype(np.int64)  # (K, J)
    d_col = np.rint(np.cos(theta)[:, None] * r_m[None, :] / dr).astype(np.int64)
    rows = cells_rc[:, 0, None, None] + steps + d_row[None]  # (N, K, J); rows are y
    cols = cells_rc[:, 1, None, None] + steps + d_col[None]
    open_ray = np.cumsum(pad_occ[rows, cols], axis=2) == 0  # until the first wall
    weight = r_m * (2 * np.pi / n_rays) * dr  # (J,)
    return ((pad_target[rows, cols] & open_ray) * weight).sum(axis=(1, 2))

