"""Floor the cameras never returned, inside space the grid already calls free.

A ToF camera 0.35 m above the floor gets no floor return beyond about 2 m (past 80° of
incidence the return is invalid), yet its rays to the walls carve the grid free up to its 5 m
range. A room crossed at a distance is then free on the grid, so it has no 2D frontier, and it
has no voxels at all, so Alg. 1's density finds nothing there either; its floor is still part of
what the evaluator counts as observable. Such patches become F_u regions of their own: the free
cells with no floor voxel nearby, without slivers along walls, in clusters of at least
`floor_unseen_min_m2`, each with the goal f′ nearest its anchor. A robot sent there sees the
floor ahead as it drives in; what stays unseen comes back as a smaller region with another anchor.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from services.common.grid import GridSpec
from services.common.voxels import xy_of, z_of
from services.edge_server.config import EdgeConfig
from services.edge_server.frontiers import FrontierSet, GoalTransform, frontier_set

# the largest −x log x, the entropy of a region whose voxels were never returned at all
FULL_ENTROPY = 1 / math.e


def floor_seen_cells(keys: np.ndarray, voxel_m: float, floor_z_m: float,
                     spec: GridSpec) -> np.ndarray:
    """(H, W) bool: cells holding a merged voxel whose centre is at most `floor_z_m` high."""
    seen = np.zeros(spec.shape, bool)
    low = keys[(z_of(keys) + 0.5) * voxel_m <= floor_z_m]
    if not low.size:
        return seen
    i, j = xy_of(low)
    col = np.floor(((i + 0.5) * voxel_m - spec.origin_x) / spec.resolution_m).astype(np.int64)
    row = np.floor(((j + 0.5) * voxel_m - spec.origin_y) / spec.resolution_m).astype(np.int64)
    inside = (row >= 0) & (row < spec.height) & (col >= 0) & (col < spec.width)
    seen[row[inside], col[inside]] = True
    return seen


def unseen_floor_mask(free: np.ndarray, seen: np.ndarray, spec: GridSpec,
                      config: EdgeConfig) -> np.ndarray:
    """(H, W) bool: free cells around which less than `floor_seen_min_fraction` of the free
    cells within `floor_seen_window_m` lie within `floor_seen_radius_m` of a returned floor
    voxel, eroded by `floor_unseen_erode_m`. The fraction, not the nearest return, because
    far floor gives a sparse scatter of noisy returns that covers little of it; the erosion
    because floor beside walls and furniture, where depth edges drop returns, is no patch."""
    near = max(int(round(config.floor_seen_radius_m / spec.resolution_m)), 0)
    if near:
        seen = ndimage.maximum_filter(seen.view(np.uint8), size=2 * near + 1).view(bool)
    window = 2 * max(int(round(config.floor_seen_window_m / 2 / spec.resolution_m)), 0) + 1
    if window > 1:
        covered = ndimage.uniform_filter((seen & free).astype(np.float32), window,
                                         mode="constant")
        room = ndimage.uniform_filter(free.astype(np.float32), window, mode="constant")
        seen = covered >= config.floor_seen_min_fraction * room
    unseen = free & ~seen
    erode = max(int(round(config.floor_unseen_erode_m / spec.resolution_m)), 0)
    if erode:
        # erosion = not (dilation of the complement); outside the grid counts as not unseen
        unseen &= ~ndimage.maximum_filter((~unseen).view(np.uint8), size=2 * erode + 1,
                                          mode="constant", cval=1).view(bool)
    return unseen


def unseen_floor_regions(
    keys: np.ndarray, voxel_m: float, free: np.ndarray, goal_ok: np.ndarray, spec: GridSpec,
    config: EdgeConfig, goal_edt: GoalTransform | None = None,
) -> FrontierSet:
    """Unseen floor patches as F_u regions: size in cells (one floor voxel each), the full
    entropy as I_g, importance 1, height 0, goals f′ among `goal_ok` cells."""
    seen = floor_seen_cells(keys, voxel_m, config.floor_z_m, spec)
    mask = unseen_floor_mask(free, seen, spec, config)
    min_cells = max(int(math.ceil(config.floor_unseen_min_m2 / spec.resolution_m**2)), 1)
    fs = frontier_set(mask, goal_ok, spec, min_cells, config.goal_max_offset_3d_m, goal_edt)
    n = len(fs)
    return FrontierSet(labels=fs.labels, sizes=fs.sizes, centroid_xy=fs.centroid_xy,
                       anchor_rc=fs.anchor_rc, anchor_xy=fs.anchor_xy, goal_rc=fs.goal_rc,
                       goal_xy=fs.goal_xy, dropped_unreachable=fs.dropped_unreachable,
                       weak=np.zeros(n, bool), gain=np.full(n, FULL_ENTROPY),
                       importance=np.ones(n), centroid_z=np.zeros(n), view=np.zeros(n, bool))
