"""3D truth: points sampled uniformly on the surfaces a camera sees.

Which geoms: static ones (welded to the world body) in the "sensed" groups. By default that is
group 1 when the world has static group-1 geoms (the AWS worlds keep their exact meshes there,
and the simulator's cameras and rays see them), otherwise group 0. Every geom becomes triangles:
meshes as they are, boxes exactly, round shapes as fine polyhedra (< 1 % area error). A plane
is infinite, so it is sampled only over the xy bounds of the other sampled geoms (the world's
footprint); floor outside the walls is then dropped by the observability test, not here.
"""

from __future__ import annotations

import mujoco
import numpy as np

from services.evaluator.free_space import static_geom_ids

_G = mujoco.mjtGeom
_BOX, _MESH, _PLANE = int(_G.mjGEOM_BOX), int(_G.mjGEOM_MESH), int(_G.mjGEOM_PLANE)
_SPHERE, _ELLIPSOID = int(_G.mjGEOM_SPHERE), int(_G.mjGEOM_ELLIPSOID)
_CAPSULE, _CYLINDER = int(_G.mjGEOM_CAPSULE), int(_G.mjGEOM_CYLINDER)
_SEGMENTS = 48


def sensed_groups(model: mujoco.MjModel) -> tuple[int, ...]:
    """(1,) when the world has static group-1 geoms, else (0,)."""
    groups = model.geom_group[static_geom_ids(model)]
    return (1,) if np.any(groups == 1) else (0,)


def _grid_triangles(pts: np.ndarray) -> np.ndarray:
    """Triangles of a (R, C, 3) lattice of points, rows and columns in order; (T, 3, 3)."""
    a, b, c, d = pts[:-1, :-1], pts[:-1, 1:], pts[1:, :-1], pts[1:, 1:]
    return np.concatenate([np.stack([a, b, d], -2), np.stack([a, d, c], -2)]).reshape(-1, 3, 3)


def _box_triangles(half: np.ndarray) -> np.ndarray:
    tris = []
    for axis in range(3):
        u, v = [i for i in range(3) if i != axis]
        for sign in (-1.0, 1.0):
            corners = np.zeros((2, 2, 3))
            for i, su in enumerate((-1.0, 1.0)):
                for j, sv in enumerate((-1.0, 1.0)):
                    corners[i, j, axis] = sign * half[axis]
                    corners[i, j, u], corners[i, j, v] = su * half[u], sv * half[v]
            tris.append(_grid_triangles(corners))
    return np.concatenate(tris)


def _revolution_triangles(profile_rz: np.ndarray) -> np.ndarray:
    """Surface of revolution about z of a (K, 2) (radius, z) profile."""
    ang = np.linspace(0.0, 2 * np.pi, _SEGMENTS + 1)
    r, z = profile_rz[:, 0:1], profile_rz[:, 1:2]
    pts = np.stack([r * np.cos(ang), r * np.sin(ang), np.broadcast_to(z, (len(r), len(ang)))], -1)
    return _grid_triangles(pts)


def _round_triangles(gtype: int, size: np.ndarray) -> np.ndarray:
    if gtype == _CYLINDER:
        r, h = size[0], size[1]
        profile = np.array([[0.0, -h], [r, -h], [r, h], [0.0, h]])
        return _revolution_triangles(profile)
    polar = np.linspace(-np.pi / 2, np.pi / 2, _SEGMENTS // 2 + 1)
    unit = np.stack([np.cos(polar), np.sin(polar)], 1)
    if gtype == _SPHERE:
        return _revolution_triangles(unit * size[0])
    if gtype == _ELLIPSOID:
        return _revolution_triangles(unit) * size[:3]
    # Capsule: the sphere's lower half shifted down, the upper half up.
    profile = unit * size[0] + np.where(unit[:, 1:2] < 0, -1.0, 1.0) * [0.0, size[1]]
    return _revolution_triangles(profile)


def geom_triangles_local(model: mujoco.MjModel, gid: int) -> np.ndarray | None:
    """(T, 3, 3) triangles of a geom's surface in its own frame; None for planes/hfields."""
    gtype, size = int(model.geom_type[gid]), model.geom_size[gid]
    if gtype == _MESH:
        mid = model.geom_dataid[gid]
        v0, f0 = model.mesh_vertadr[mid], model.mesh_faceadr[mid]
        verts = model.mesh_vert[v0 : v0 + model.mesh_vertnum[mid]]
        faces = model.mesh_face[f0 : f0 + model.mesh_facenum[mid]]
        return verts[faces].astype(np.float64)
    if gtype == _BOX:
        return _box_triangles(size)
    if gtype in (_SPHERE, _ELLIPSOID, _CAPSULE, _CYLINDER):
        return _round_triangles(gtype, size)
    return None


def world_triangles(model: mujoco.MjModel, groups: tuple[int, ...] | None = None) -> np.ndarray:
    """(T, 3, 3) world-frame triangles of the static geoms in `groups` (default: sensed)."""
    groups = sensed_groups(model) if groups is None else groups
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    tris, planes = [], []
    for gid in static_geom_ids(model):
        if model.geom_group[gid] not in groups:
            continue
        if int(model.geom_type[gid]) == _PLANE:
            planes.append(gid)
            continue
        local = geom_triangles_local(model, gid)
        if local is not None:
            tris.append(local @ data.geom_xmat[gid].reshape(3, 3).T + data.geom_xpos[gid])
    tris_world = np.concatenate(tris) if tris else np.zeros((0, 3, 3))
    if planes and len(tris_world):
        tris_world = np.concatenate([tris_world, _plane_triangles(data, planes, tris_world)])
    return tris_world


def _plane_triangles(data: mujoco.MjData, planes: list[int], tris: np.ndarray) -> np.ndarray:
    """Each plane as a square over the xy bounds of the other geoms, in the plane's frame."""
    pts = tris.reshape(-1, 3)
    out = []
    for gid in planes:
        R, p = data.geom_xmat[gid].reshape(3, 3), data.geom_xpos[gid]
        local = (pts - p) @ R  # bounds measured in the plane's own frame
        lo, hi = local[:, :2].min(0), local[:, :2].max(0)
        corners = np.array(
            [[[lo[0], lo[1], 0], [lo[0], hi[1], 0]], [[hi[0], lo[1], 0], [hi[0], hi[1], 0]]]
        )
        out.append(_grid_triangles(corners) @ R.T + p)
    return np.concatenate(out)


def sample_triangles(
    tris: np.ndarray, density_per_m2: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """round(area·density) points uniform over the triangles' total area: (N, 3) points and
    (N,) the index of the triangle each lies on."""
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    n = int(round(area.sum() * density_per_m2))
    if n == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    idx = rng.choice(len(tris), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1.0  # fold the square's far half back into the triangle
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    return a[idx] + u[:, None] * (b[idx] - a[idx]) + v[:, None] * (c[idx] - a[idx]), idx


def triangle_normals(tris: np.ndarray) -> np.ndarray:
    """(T, 3) unit normals of (T, 3, 3) triangles (their winding's sign; zero for slivers)."""
    normal = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    return normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)


def surface_samples(
    model: mujoco.MjModel,
    density_per_m2: float = 1000.0,
    groups: tuple[int, ...] | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points uniform on the sensed static surfaces (module docstring).

    Returns (N, 3) points_world, (N,) triangle ids (samples on one triangle share a plane
    and a side, which lets the observability test share work between them) and (N, 3) the
    unit normal of each sample's triangle (world frame, either sign).
    """
    rng = np.random.default_rng(seed)
    tris = world_triangles(model, groups)
    points, ids = sample_triangles(tris, density_per_m2, rng)
    return points, ids, triangle_normals(tris)[ids] if len(tris) else np.zeros((0, 3))
