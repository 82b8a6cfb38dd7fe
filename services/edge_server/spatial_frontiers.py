"""SPACE frontier regions: Alg. 1 point masks → regions with I_g(f) and reachable goals f′.

Per class, the frontier voxels are projected onto the merged grid, dilated by
`frontier_link_m` (voxels that close belong to one region) and clustered; each region gets
its voxels V_f, I_g(f) = mean point entropy over V_f, a 3D centroid, and the translated goal
f′: the reachable grid cell nearest the region's anchor within `goal_max_offset_3d_m`.
Regions smaller than the class minimum are dropped, as are F_u regions farther than
`unexplored_unknown_m` from unknown space (the top rim of what a ground camera ever sees is
low-density forever; it is not an unexplored region a robot can go and see).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage

from services.common.arrays import column_extremes
from services.common.grid import GridSpec
from services.common.planning import dilate_disk
from services.common.voxels import unpack
from services.edge_server.config import EdgeConfig
from services.edge_server.frontiers import (
    FrontierSet,
    GoalTransform,
    empty_frontiers,
    frontier_set,
)
from services.edge_server.frontiers3d import (
    PointFrontiers,
    detect_point_frontiers,
    lattice_frontiers,
    point_entropy,
)
from services.edge_server.merged_map import MergedMap
from services.edge_server.view_goals import ViewGeometry, region_top_z, view_goals


def subset(fs: FrontierSet, keep: np.ndarray) -> FrontierSet:
    """The regions where `keep` is True, renumbered (labels included)."""
    renumber = np.zeros(len(fs) + 1, np.int32)
    renumber[1:][keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    pick = {name: (getattr(fs, name)[keep] if getattr(fs, name) is not None else None)
            for name in ("sizes", "centroid_xy", "anchor_rc", "anchor_xy", "goal_rc", "goal_xy",
                         "weak", "gain", "importance", "centroid_z", "grid_frontier_m",
                         "unknown_view_m2", "view")}
    return FrontierSet(labels=renumber[fs.labels], dropped_unreachable=fs.dropped_unreachable,
                       **pick)


def concat(a: FrontierSet, b: FrontierSet) -> FrontierSet:
    """Regions of a, then of b (b's labels win where both cover a cell)."""
    labels = np.where(b.labels > 0, b.labels + len(a), a.labels).astype(np.int32)
    fields = {}
    for name in ("sizes", "centroid_xy", "anchor_rc", "anchor_xy", "goal_rc", "goal_xy",
                 "weak", "gain", "importance", "centroid_z", "view"):
        fields[name] = np.concatenate([_or_zeros(a, name), _or_zeros(b, name)])
    return FrontierSet(labels=labels, dropped_unreachable=a.dropped_unreachable
                       + b.dropped_unreachable, **fields)


def _or_zeros(fs: FrontierSet, name: str) -> np.ndarray:
    value = getattr(fs, name)
    return np.zeros(len(fs), bool) if value is None and name == "view" else value


def class_regions(
    pf: PointFrontiers, weak: bool, goal_ok: np.ndarray, spec: GridSpec, config: EdgeConfig,
    goal_edt: GoalTransform | None = None, see_through: np.ndarray | None = None,
) -> FrontierSet:
    """Regions of one class with |V_f|, I_g, 3D centroid and goals f′. F_u regions too high
    to see from beside them get a far view when `see_through` (the known free cells) is given
    and `space_view_goals` is on; with `space_view_split` the F_u voxels at or above
    `space_view_min_z_m` form regions of their own, kept only where a far view exists."""
    z = pf.points_world[:, 2]
    mask = (pf.weak if weak else pf.unexplored) & (z <= config.frontier_z_max_m)
    views = (see_through is not None and not weak and config.space_view_goals
             and config.planner == "space")  # space-paper: the paper's f′
    if not views:
        return _regions(pf, mask, weak, goal_ok, spec, config, goal_edt)
    assert see_through is not None
    if not config.space_view_split:
        return _regions(pf, mask, weak, goal_ok, spec, config, goal_edt, see_through)
    high = z >= config.space_view_min_z_m
    low_fs = _regions(pf, mask & ~high, weak, goal_ok, spec, config, goal_edt)
    high_fs = _regions(pf, mask & high, weak, goal_ok, spec, config, goal_edt, see_through)
    assert high_fs.view is not None
    return concat(low_fs, subset(high_fs, high_fs.view))


def _regions(
    pf: PointFrontiers, mask: np.ndarray, weak: bool, goal_ok: np.ndarray, spec: GridSpec,
    config: EdgeConfig, goal_edt: GoalTransform | None, see_through: np.ndarray | None = None,
) -> FrontierSet:
    """Regions of the voxels in `mask` (far views where `see_through` is given)."""
    sel = np.flatnonzero(mask)
    rc = spec.cell_of(pf.points_world[sel, :2])
    inside = spec.contains(rc)
    sel, rc = sel[inside], rc[inside]
    cells = np.zeros(spec.shape, bool)
    cells[rc[:, 0], rc[:, 1]] = True
    r = int(round(config.frontier_link_m / spec.resolution_m))
    if r > 0 and sel.size:
        # square dilation = separable max filter (binary_dilation iterates the whole square)
        cells = ndimage.maximum_filter(cells.view(np.uint8), size=2 * r + 1).view(bool)
    fs = frontier_set(cells, goal_ok, spec, 1, config.goal_max_offset_3d_m, goal_edt)
    n = len(fs)
    lab = fs.labels[rc[:, 0], rc[:, 1]] - 1
    ok = lab >= 0
    sel, lab = sel[ok], lab[ok]
    count = np.bincount(lab, minlength=n)
    denom = np.maximum(count, 1)
    gain = np.bincount(lab, point_entropy(pf, weak, sel), n) / denom
    z = np.bincount(lab, pf.points_world[sel, 2], n) / denom
    xy = np.stack([np.bincount(lab, pf.points_world[sel, d], n) for d in (0, 1)], 1)
    goal_rc, view = fs.goal_rc, np.zeros(n, bool)
    if see_through is not None and n:
        top = region_top_z(lab, pf.points_world[sel, 2], n, config.space_view_quantile)
        top = np.where(top >= config.space_view_min_z_m, top, np.nan)
        goal_rc, view = view_goals(fs.anchor_rc, fs.goal_rc, top, see_through, goal_ok, spec,
                                   view_geometry(config))
    fs = FrontierSet(labels=fs.labels, sizes=count, centroid_xy=xy / denom[:, None],
                     anchor_rc=fs.anchor_rc, anchor_xy=fs.anchor_xy, goal_rc=goal_rc,
                     goal_xy=spec.centre_of(goal_rc), dropped_unreachable=fs.dropped_unreachable,
                     weak=np.full(n, weak), gain=gain, importance=np.ones(n), centroid_z=z,
                     view=view)
    min_voxels = config.weak_min_voxels if weak else config.unexplored_min_voxels
    return subset(fs, count >= min_voxels)


def view_geometry(config: EdgeConfig) -> ViewGeometry:
    return ViewGeometry(config.camera_height_m, np.radians(config.camera_half_vfov_deg),
                        config.camera_range_m, config.space_view_margin_m)


def near_unknown(fs: FrontierSet, known: np.ndarray, spec: GridSpec, max_m: float) -> np.ndarray:
    """(F,) bool: regions with a label cell within `max_m` of an unknown grid cell."""
    if not len(fs):
        return np.zeros(0, bool)
    # the transform of a window around the regions, padded past max_m: an unknown cell
    # within max_m of a region lies inside it, so the distances that pass are the same
    rc = np.argwhere(fs.labels > 0)
    pad = int(np.ceil(max_m / spec.resolution_m)) + 1
    rc_lo, rc_hi = column_extremes(rc)
    lo = np.maximum(rc_lo - pad, 0)
    hi = np.minimum(rc_hi + pad + 1, known.shape)
    window = known[lo[0]:hi[0], lo[1]:hi[1]]
    if window.all():  # no unknown cell within reach of any region
        return np.zeros(len(fs), bool)
    # cells within max_m of an unknown one: the unknown cells grown by the disk of the
    # offsets whose length passes the distance transform's own test (√d² · res ≤ max_m, so
    # ties at max_m fall the same way), 1.5 ms a plan less than transforming the window
    d2 = np.arange((pad + 1) ** 2)
    r2 = int(d2[np.sqrt(d2.astype(np.float64)) * spec.resolution_m <= max_m].max())
    labels = fs.labels[lo[0]:hi[0], lo[1]:hi[1]]
    close = (labels > 0) & dilate_disk(~window, r2)
    return np.bincount(labels[close] - 1, minlength=len(fs)) > 0


def detect_spatial_frontiers(
    merged: MergedMap, known: np.ndarray, goal_ok: np.ndarray, spec: GridSpec,
    config: EdgeConfig, pf: PointFrontiers | None = None, goal_edt: GoalTransform | None = None,
    see_through: np.ndarray | None = None,
) -> tuple[FrontierSet, PointFrontiers]:
    """F_u regions then F_w regions of P*, with gains and goals (importance still 1).
    `pf`: Alg. 1's output when the caller keeps it incrementally (frontier_cache.py);
    `see_through`: the known free cells, for far views of high F_u regions."""
    args = (config.frontier_voxel_m, config.search_radius_m, config.density_threshold,
            config.variance_threshold_m2)
    if pf is None and np.isclose(merged.voxel_m, config.frontier_voxel_m):  # on the ϱ lattice
        pf = lattice_frontiers(unpack(merged.keys), *args)
    elif pf is None:
        pf = detect_point_frontiers(merged.points_world, *args)
    if not len(pf.rho) or not goal_ok.any():
        return _typed_empty(spec), pf
    unexplored = class_regions(pf, False, goal_ok, spec, config, goal_edt, see_through)
    keep = near_unknown(unexplored, known, spec, config.unexplored_unknown_m)
    if config.floor_rim_z_m is not None and len(unexplored):
        # the rim of the floor the cameras returned: a ToF camera at 0.35 m gets no floor
        # beyond ~2 m (grazing), yet the grid calls it free up to the walls it saw
        assert unexplored.centroid_z is not None
        keep |= unexplored.centroid_z <= config.floor_rim_z_m
    unexplored = subset(unexplored, keep)
    weak = class_regions(pf, True, goal_ok, spec, config, goal_edt)
    return concat(unexplored, weak), pf


def _typed_empty(spec: GridSpec) -> FrontierSet:
    e = empty_frontiers(spec.shape)
    z = np.zeros(0)
    return FrontierSet(e.labels, e.sizes, e.centroid_xy, e.anchor_rc, e.anchor_xy, e.goal_rc,
                       e.goal_xy, 0, np.zeros(0, bool), z, z, z)


def grid_as_unexplored(fs: FrontierSet) -> FrontierSet:
    """2D grid frontier clusters as F_u regions for the SPACE scorers: unit gain and
    importance (they only ever compete among themselves), at floor height."""
    n = len(fs)
    return replace(fs, weak=np.zeros(n, bool), gain=np.ones(n), importance=np.ones(n),
                   centroid_z=np.zeros(n))
