"""2D truth: the reachable free space of a MuJoCo world at robot height.

Definition (SPEC §5, "reachable free cells"):
1. Obstacles = static (welded to the world body), collidable (contype or conaffinity ≠ 0)
   geoms of any type but plane/hfield. Each one's solid is clipped to the robot height band
   [z_lo, z_hi] and its footprint (the convex hull of the clipped solid, projected on xy) marks
   every 0.05 m cell it overlaps, even partly: thin walls can never leak. Meshes count as their
   convex hull, as MuJoCo's contacts do.
2. Centre cells: free cells whose centre lies ≥ robot_radius + res/2 from every obstacle cell
   centre (the robot disc fits), 4-connected components that hold a spawn point.
3. Reachable free cells: free cells within that same distance of a reachable centre cell, i.e.
   the floor the robot's body can sweep. Closets with no way in and space outside a sealed
   house are excluded; free cells in corners too tight for the body are excluded too.
"""

from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from services.common.grid import GridSpec

log = logging.getLogger(__name__)

_ROUND_SEGMENTS = 24
_G = mujoco.mjtGeom
# Plain ints: numpy ints and pybind enums do not compare equal inside `in`.
_BOX, _MESH, _CYLINDER = int(_G.mjGEOM_BOX), int(_G.mjGEOM_MESH), int(_G.mjGEOM_CYLINDER)
_SPHERE, _ELLIPSOID = int(_G.mjGEOM_SPHERE), int(_G.mjGEOM_ELLIPSOID)
_CAPSULE = int(_G.mjGEOM_CAPSULE)
_SKIPPED_TYPES = (int(_G.mjGEOM_PLANE), int(_G.mjGEOM_HFIELD))


@dataclass(frozen=True)
class FreeGrid:
    """The 2D truth on a world-aligned grid (row = y index, col = x index)."""

    spec: GridSpec
    occupied: np.ndarray  # (H, W) bool: an obstacle footprint overlaps the cell
    centres: np.ndarray  # (H, W) bool: reachable robot-centre cells
    free: np.ndarray  # (H, W) bool: reachable free cells (the 2D truth)

    @property
    def free_area_m2(self) -> float:
        return float(self.free.sum()) * self.spec.resolution_m**2


def static_geom_ids(model: mujoco.MjModel) -> np.ndarray:
    """Geoms welded to the world body (robots and free objects excluded)."""
    return np.flatnonzero(model.body_weldid[model.geom_bodyid] == 0)


def geom_vertices_local(model: mujoco.MjModel, gid: int) -> np.ndarray | None:
    """(K, 3) points whose convex hull contains the geom's solid, in the geom frame."""
    gtype, size = int(model.geom_type[gid]), model.geom_size[gid]
    if gtype == _BOX:
        return np.array(np.meshgrid(*[[-s, s] for s in size], indexing="ij")).reshape(3, -1).T
    if gtype == _MESH:
        mid = model.geom_dataid[gid]
        start, n = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
        return model.mesh_vert[start : start + n].astype(np.float64)
    # Round shapes: rings of a polygon circumscribing the circle.
    ang = np.linspace(0.0, 2 * np.pi, _ROUND_SEGMENTS, endpoint=False)
    ring = np.stack([np.cos(ang), np.sin(ang)], 1) / np.cos(np.pi / _ROUND_SEGMENTS)
    if gtype == _CYLINDER:
        r, h = size[0], size[1]
        return np.concatenate([np.c_[r * ring, np.full(len(ring), z)] for z in (-h, h)])
    if gtype in (_SPHERE, _ELLIPSOID, _CAPSULE):
        lat = np.linspace(-1.0, 1.0, 9)  # z levels of rings on the unit sphere, poles included
        pts = [np.c_[np.sqrt(1 - z * z) * ring, np.full(len(ring), z)] for z in lat]
        unit = np.concatenate(pts) / np.cos(np.pi / 16)  # 9 levels ≈ 22.5° apart
        if gtype == _SPHERE:
            return unit * size[0]
        if gtype == _ELLIPSOID:
            return unit * size[:3]
        shift = np.sign(unit[:, 2:3]) * np.array([0.0, 0.0, size[1]])
        return np.concatenate([unit * size[0] + shift, unit * size[0]])
    return None


def clip_to_band(points: np.ndarray, z_lo: float, z_hi: float) -> np.ndarray:
    """Points whose hull = hull(points) ∩ {z_lo ≤ z ≤ z_hi}.

    Every segment between two points lies in the hull, so the points inside the band plus the
    crossings of every segment with the two planes span exactly the clipped hull.
    """
    if len(points) > 16:
        with contextlib.suppress(QhullError):  # flat sets keep all their points
            points = points[ConvexHull(points).vertices]
    inside = points[(points[:, 2] >= z_lo) & (points[:, 2] <= z_hi)]
    i, j = np.triu_indices(len(points), k=1)
    a, b = points[i], points[j]
    out = [inside]
    for z in (z_lo, z_hi):
        dz = b[:, 2] - a[:, 2]
        cross = (a[:, 2] - z) * (b[:, 2] - z) < 0
        t = (z - a[cross, 2]) / dz[cross]
        out.append(a[cross] + t[:, None] * (b[cross] - a[cross]))
    return np.concatenate(out)


def rasterize_convex(occupied: np.ndarray, spec: GridSpec, xy: np.ndarray) -> None:
    """Mark every cell that the convex hull of xy overlaps (separating-axis test)."""
    res = spec.resolution_m
    lo = np.floor((xy.min(0) - (spec.origin_x, spec.origin_y)) / res).astype(int)
    hi = np.floor((xy.max(0) - (spec.origin_x, spec.origin_y)) / res).astype(int)
    lo, hi = np.maximum(lo, 0), np.minimum(hi, (spec.width - 1, spec.height - 1))
    if np.any(hi < lo):
        return
    cols, rows = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
    centres = spec.centre_of(np.stack([rows.ravel(), cols.ravel()], 1))
    try:
        poly = xy[ConvexHull(xy, qhull_options="QJ").vertices]
    except (QhullError, ValueError):
        poly = xy  # a point or too few points: the bbox test alone decides
    keep = np.ones(len(centres), dtype=bool)
    if len(poly) >= 3:
        edges = np.roll(poly, -1, axis=0) - poly
        length = np.linalg.norm(edges, axis=1)
        edges = edges[length > 1e-9] / length[length > 1e-9, None]  # QJ may repeat vertices
        normals = np.stack([-edges[:, 1], edges[:, 0]], 1)
        proj = poly @ normals.T  # (K, E)
        half = 0.5 * res * np.abs(normals).sum(1)  # the cell's half extent along each normal
        c = centres @ normals.T  # (M, E)
        eps = 1e-9  # a face lying on a cell border does not mark the neighbour
        keep = np.all((c + half > proj.min(0) + eps) & (c - half < proj.max(0) - eps), axis=1)
    occupied[rows.ravel()[keep], cols.ravel()[keep]] = True


def obstacle_grid(
    model: mujoco.MjModel, band: tuple[float, float], resolution_m: float, margin_m: float = 1.0
) -> tuple[GridSpec, np.ndarray]:
    """Grid covering the static world, with the obstacle footprints in the height band."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    solids = []
    for gid in static_geom_ids(model):
        if int(model.geom_type[gid]) in _SKIPPED_TYPES:
            continue
        local = geom_vertices_local(model, gid)
        if local is None:
            continue
        world = local @ data.geom_xmat[gid].reshape(3, 3).T + data.geom_xpos[gid]
        collides = model.geom_contype[gid] != 0 or model.geom_conaffinity[gid] != 0
        solids.append((world, collides))
    if not solids:
        raise ValueError("the model has no static geoms besides planes")
    allpts = np.concatenate([w for w, _ in solids])
    spec = GridSpec.covering(allpts[:, :2].min(0), allpts[:, :2].max(0), resolution_m, margin_m)
    occupied = np.zeros(spec.shape, dtype=bool)
    for world, collides in solids:
        if not collides:
            continue
        clipped = clip_to_band(world, *band)
        if len(clipped):
            rasterize_convex(occupied, spec, clipped[:, :2])
    return spec, occupied


def reachable_free_grid(
    model: mujoco.MjModel,
    spawn_xy: np.ndarray,
    resolution_m: float = 0.05,
    robot_radius_m: float = 0.17,
    band: tuple[float, float] = (0.03, 0.40),
) -> FreeGrid:
    """The reachable free cells (module docstring) from the robots' spawn points (N, 2)."""
    spec, occupied = obstacle_grid(model, band, resolution_m)
    clearance = robot_radius_m + 0.5 * resolution_m
    dist_m = ndimage.distance_transform_edt(~occupied) * resolution_m
    labels, _ = ndimage.label(dist_m >= clearance)
    spawn_rc = spec.cell_of(np.asarray(spawn_xy, dtype=np.float64).reshape(-1, 2))
    if not spec.contains(spawn_rc).all():
        raise ValueError(f"spawn points outside the world grid: {spawn_xy}")
    # A spawn cell too close to a wall joins its nearest centre component.
    _, (near_r, near_c) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    ids = np.unique(labels[near_r[tuple(spawn_rc.T)], near_c[tuple(spawn_rc.T)]])
    centres = np.isin(labels, ids[ids > 0])
    swept = ndimage.distance_transform_edt(~centres) * resolution_m <= clearance
    free = swept & ~occupied
    log.debug("reachable free area %.2f m² in %s", free.sum() * resolution_m**2, spec)
    return FreeGrid(spec=spec, occupied=occupied, centres=centres, free=free)
