"""Observable surface: the samples a camera at robot height in reachable free space can see.

A sample s is observable when some viewpoint v (camera height, above a reachable robot-centre
cell of the 2D truth) has ‖s − v‖ ≤ γ, sees it within the camera's vertical half-FoV (a level
camera that can turn in place: |elevation| ≤ max_elevation, any azimuth), and the segment v→s
hits no sensed geom before s (mj_multiRay on the real mesh triangles, 1 cm tolerance). With the
samples' surface normals and a maximum incidence (the simulated ToF camera returns nothing where
the ray meets the surface more than that far off its normal: sensor_model.py), v must also see s
within it, or the camera could never return s from anywhere the robot can stand.

Testing every (sample, viewpoint) pair is far too slow, so the search is randomized: viewpoints
sit on a lattice (viewpoint_spacing) of centre cells, and in each round every still-unseen
sample tries one viewpoint: the lattice point nearest to a random spot at a random azimuth in
the annulus of allowed horizontal distances (nearer distances favoured). After R rounds a sample
visible from a fraction q of its candidate spots is missed with probability (1 − q)^R; samples
visible only through a keyhole can be missed, which lowers the truth (in the robots' favour) by
a measured fraction of a percent (see tests and bench).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial import cKDTree

from services.evaluator.free_space import FreeGrid
from services.evaluator.surfaces import sensed_groups

log = logging.getLogger(__name__)

_HIT_TOLERANCE_M = 0.01
_SHARE_RADIUS_M = 0.05


def _search_shared(
    samples: np.ndarray, triangle_ids: np.ndarray, stride: int,
    search: Callable[[np.ndarray], np.ndarray], rng: np.random.Generator,
) -> np.ndarray:
    """Ray-test a 1/stride subset (search takes sample indices); the rest copy the nearest
    tested sample on their triangle."""
    tested = np.zeros(len(samples), dtype=bool)
    tested[rng.permutation(len(samples))[:: stride]] = True
    seen = np.zeros(len(samples), dtype=bool)
    seen[tested] = search(np.flatnonzero(tested))
    # A 4th coordinate far apart per triangle keeps nearest neighbours on the same triangle.
    key = triangle_ids.astype(np.float64)[:, None] * 1e3
    tree = cKDTree(np.c_[samples[tested], key[tested]])
    rest = np.flatnonzero(~tested)
    dist, nearest = tree.query(
        np.c_[samples[rest], key[rest]], distance_upper_bound=_SHARE_RADIUS_M
    )
    shared = np.isfinite(dist)
    seen[rest[shared]] = seen[np.flatnonzero(tested)[nearest[shared]]]
    alone = rest[~shared]
    seen[alone] = search(alone)
    return seen


def viewpoints(free_grid: FreeGrid, camera_height_m: float, spacing_m: float) -> np.ndarray:
    """(V, 3) camera positions above a lattice of reachable robot-centre cells."""
    step = max(int(round(spacing_m / free_grid.spec.resolution_m)), 1)
    rows, cols = np.nonzero(free_grid.centres)
    on_lattice = (rows % step == 0) & (cols % step == 0)
    xy = free_grid.spec.centre_of(np.stack([rows[on_lattice], cols[on_lattice]], 1))
    return np.c_[xy, np.full(len(xy), camera_height_m)]


def _visible_along_rays(
    model: mujoco.MjModel, data: mujoco.MjData, origin: np.ndarray, targets: np.ndarray,
    geomgroup: np.ndarray, cutoff_m: float,
) -> np.ndarray:
    """(K,) bool: the ray origin→target reaches the target (within tolerance)."""
    vec = np.ascontiguousarray(targets - origin)  # unnormalised: distances in units of ‖vec‖
    n = len(vec)
    geomid = np.empty(n, dtype=np.int32)
    dist = np.empty(n, dtype=np.float64)
    mujoco.mj_multiRay(
        model, data, origin, vec.ravel(), geomgroup, 1, -1, geomid, dist, None, n, cutoff_m
    )
    length = np.linalg.norm(vec, axis=1)
    return (geomid < 0) | (dist * length >= length - _HIT_TOLERANCE_M)


@dataclass(frozen=True)
class Incidence:
    """The samples' unit surface normals (N, 3) and the largest angle (deg) between a ray and
    the normal at which the camera still returns the point (either side of the surface)."""

    normals: np.ndarray
    max_deg: float


def _candidate_spots(
    samples: np.ndarray, camera_height_m: float, range_m: float,
    max_elevation_deg: float | None, rng: np.random.Generator,
    normals: np.ndarray | None = None, max_incidence_deg: float = 90.0,
) -> tuple[np.ndarray, np.ndarray]:
    """A random allowed camera xy per sample, and whether any such spot exists. With normals,
    the azimuth lies within the incidence limit of the normal's horizontal part (either side)
    and a level surface's spot within the distance at which the ray is still steep enough."""
    dz = np.abs(samples[:, 2] - camera_height_m)
    d_max = np.sqrt(np.maximum(range_m**2 - dz**2, 0.0))
    d_min = np.zeros_like(dz) if max_elevation_deg is None else (
        dz / np.tan(np.radians(max_elevation_deg))
    )
    near = rng.random(len(samples)) ** 2  # favour near spots
    azimuth = rng.uniform(0.0, 2 * np.pi, len(samples))
    if normals is not None:
        # Necessary conditions only (the exact test is `_allowed`): a ray within L of a normal
        # tilted t from the horizontal lies within L + t of it in azimuth, and within L + t'
        # of the vertical for a normal t' from it.
        limit = np.radians(max_incidence_deg)
        nz = np.clip(np.abs(normals[:, 2]), 0.0, 1.0)
        level = nz > np.cos(np.radians(5.0))
        steep = np.minimum(limit + np.arccos(nz), np.radians(89.9))
        d_max = np.where(level, np.minimum(d_max, dz * np.tan(steep)), d_max)
        side = np.where(rng.random(len(samples)) < 0.5, 0.0, np.pi)
        spread = np.minimum(limit + np.arcsin(nz), np.pi)
        toward = (np.arctan2(normals[:, 1], normals[:, 0]) + side
                  + spread * rng.uniform(-1.0, 1.0, len(samples)))
        azimuth = np.where(level, azimuth, toward)
    possible = d_max > d_min
    radius = d_min + (d_max - d_min) * near
    spots = samples[:, :2] + radius[:, None] * np.c_[np.cos(azimuth), np.sin(azimuth)]
    return spots, possible


def _allowed(
    samples: np.ndarray, views: np.ndarray, range_m: float, max_elevation_deg: float | None,
    normals: np.ndarray | None = None, max_incidence_deg: float = 90.0,
) -> np.ndarray:
    """(K,) bool: each (sample, viewpoint) pair respects range, vertical FoV and incidence."""
    delta = samples - views
    dist = np.linalg.norm(delta, axis=1)
    ok = dist <= range_m
    if max_elevation_deg is not None:
        horizontal = np.linalg.norm(delta[:, :2], axis=1)
        elevation = np.degrees(np.arctan2(np.abs(delta[:, 2]), horizontal))
        ok &= elevation <= max_elevation_deg
    if normals is not None:
        cos = np.abs(np.einsum("ij,ij->i", delta, normals)) / np.maximum(dist, 1e-12)
        ok &= cos >= np.cos(np.radians(max_incidence_deg))
    return ok


def _search(
    model: mujoco.MjModel, samples: np.ndarray, views: np.ndarray, camera_height_m: float,
    range_m: float, max_elevation_deg: float | None, rounds: int, geomgroup: np.ndarray,
    rng: np.random.Generator, incidence: Incidence | None = None,
) -> np.ndarray:
    """The randomized viewpoint search of the module docstring; (N,) bool."""
    seen = np.zeros(len(samples), dtype=bool)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    tree = cKDTree(views[:, :2])
    todo = np.arange(len(samples))
    for _ in range(rounds):
        normals = None if incidence is None else incidence.normals[todo]
        max_inc = 90.0 if incidence is None else incidence.max_deg
        spots, possible = _candidate_spots(
            samples[todo], camera_height_m, range_m, max_elevation_deg, rng, normals, max_inc
        )
        todo = todo[possible]
        _, vidx = tree.query(spots[possible])
        ok = _allowed(samples[todo], views[vidx], range_m, max_elevation_deg,
                      None if normals is None else normals[possible], max_inc)
        order = np.argsort(vidx[ok], kind="stable")
        tried, tried_v = todo[ok][order], vidx[ok][order]
        bounds = np.flatnonzero(np.diff(tried_v)) + 1
        for chunk, vchunk in zip(np.split(tried, bounds), np.split(tried_v, bounds), strict=True):
            if len(chunk):
                seen[chunk] = _visible_along_rays(
                    model, data, views[vchunk[0]], samples[chunk], geomgroup, range_m + 0.1
                )
        todo = todo[~seen[todo]]
        if len(todo) == 0:
            break
    return seen


def observable_surface(
    model: mujoco.MjModel,
    samples: np.ndarray,
    free_grid: FreeGrid,
    camera_height_m: float = 0.35,
    range_m: float = 5.0,
    max_elevation_deg: float | None = 34.08,
    viewpoint_spacing_m: float = 0.25,
    rounds: int = 16,
    groups: tuple[int, ...] | None = None,
    seed: int = 0,
    triangle_ids: np.ndarray | None = None,
    test_stride: int = 4,
    incidence: Incidence | None = None,
) -> np.ndarray:
    """(N,) bool: which samples are observable (module docstring); with `incidence`, within
    its limit of their normals.

    With triangle_ids, only one sample in test_stride is ray-tested; every other sample copies
    the verdict of the nearest tested sample on the same triangle when one lies within
    _SHARE_RADIUS_M (same plane, same side: the verdict differs only along shadow edges), and
    is tested itself otherwise.
    """
    samples = np.asarray(samples, dtype=np.float64)
    views = viewpoints(free_grid, camera_height_m, viewpoint_spacing_m)
    seen = np.zeros(len(samples), dtype=bool)
    if len(views) == 0 or len(samples) == 0:
        return seen
    groups = sensed_groups(model) if groups is None else groups
    geomgroup = np.array([g in groups for g in range(6)], dtype=np.uint8)
    rng = np.random.default_rng(seed)
    def search(index: np.ndarray) -> np.ndarray:
        sub = None if incidence is None else Incidence(incidence.normals[index],
                                                       incidence.max_deg)
        return _search(
            model, samples[index], views, camera_height_m, range_m, max_elevation_deg, rounds,
            geomgroup, rng, sub,
        )

    if triangle_ids is None or test_stride <= 1:
        seen = search(np.arange(len(samples)))
    else:
        seen = _search_shared(samples, np.asarray(triangle_ids), test_stride, search, rng)
    log.debug("observable %d / %d samples from %d viewpoints", seen.sum(), len(seen), len(views))
    return seen
