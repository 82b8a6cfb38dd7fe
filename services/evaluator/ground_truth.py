"""The evaluator's ground truth of a world: 2D reachable free grid + observable surface samples.

Built from the MjModel alone (free_space, surfaces, observable) and cached on disk as .npz,
keyed by a hash of the model's static geometry, the spawn points and the EvalConfig.
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from services.common.grid import GridSpec
from services.evaluator.config import EvalConfig
from services.evaluator.free_space import FreeGrid, reachable_free_grid
from services.evaluator.observable import Incidence, observable_surface
from services.evaluator.surfaces import surface_samples

log = logging.getLogger(__name__)

_CACHE_VERSION = "2"
_MODEL_FIELDS = (
    "geom_type", "geom_size", "geom_group", "geom_contype", "geom_conaffinity", "geom_pos",
    "geom_quat", "geom_bodyid", "geom_dataid", "body_pos", "body_quat", "body_parentid",
    "body_weldid", "mesh_vert", "mesh_face", "mesh_vertadr", "mesh_faceadr",
)


@dataclass(frozen=True)
class GroundTruth:
    """2D truth (free grid) and 3D truth (all surface samples, which are observable, and
    which are in sight at all, whatever the camera's incidence limit)."""

    free_grid: FreeGrid
    surface_points_world: np.ndarray  # (N, 3) every sampled static surface point
    observable: np.ndarray  # (N,) bool: in sight, and within the incidence limit
    in_sight: np.ndarray  # (N,) bool: some reachable viewpoint sees it (observable ⊆ in_sight)

    @property
    def observable_points_world(self) -> np.ndarray:
        return self.surface_points_world[self.observable]


def default_cache_dir() -> Path:
    """$SPACEMAP_CACHE, else ~/.cache/spacemap."""
    return Path(os.environ.get("SPACEMAP_CACHE", Path.home() / ".cache" / "spacemap"))


def cache_key(model: mujoco.MjModel, spawn_xy: np.ndarray, config: EvalConfig) -> str:
    """sha256 over the model's geometry arrays, the spawn points and the config."""
    h = hashlib.sha256(_CACHE_VERSION.encode())
    for name in _MODEL_FIELDS:
        h.update(name.encode())
        h.update(np.ascontiguousarray(getattr(model, name)).tobytes())
    h.update(np.asarray(spawn_xy, dtype=np.float64).round(6).tobytes())
    h.update(config.model_dump_json().encode())
    return h.hexdigest()[:24]


def compute_ground_truth(
    model: mujoco.MjModel, spawn_xy: np.ndarray, config: EvalConfig
) -> GroundTruth:
    """Build the ground truth from scratch (seconds for the AWS house)."""
    free_grid = reachable_free_grid(
        model, spawn_xy, config.resolution_m, config.robot_radius_m, config.band_z_m
    )
    points, tri_ids, normals = surface_samples(model, config.density_per_m2, seed=config.seed)
    def search(index: np.ndarray, incidence: Incidence | None) -> np.ndarray:
        return observable_surface(
            model, points[index], free_grid, config.camera_height_m, config.range_m,
            config.max_elevation_deg, config.viewpoint_spacing_m, config.visibility_rounds,
            seed=config.seed, triangle_ids=tri_ids[index], incidence=incidence,
        )

    in_sight = search(np.arange(len(points)), None)
    observable = in_sight.copy()
    if config.max_incidence_deg is not None and config.max_incidence_deg < 90:
        sighted = np.flatnonzero(in_sight)
        observable[sighted] = search(sighted, Incidence(normals[sighted],
                                                        config.max_incidence_deg))
    return GroundTruth(free_grid, points, observable, in_sight)


def _save(path: Path, gt: GroundTruth) -> None:
    spec = gt.free_grid.spec
    # a unique temporary name: two missions of one world may fill the cache at once
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=path.stem + ".", suffix=".tmp.npz")
    os.close(fd)
    tmp = Path(name)
    np.savez_compressed(
        tmp, spec=np.array([spec.origin_x, spec.origin_y, spec.resolution_m]),
        occupied=gt.free_grid.occupied, centres=gt.free_grid.centres, free=gt.free_grid.free,
        points=gt.surface_points_world.astype(np.float32), observable=gt.observable,
        in_sight=gt.in_sight,
    )
    tmp.replace(path)  # atomic: a concurrent reader never sees half a file


def _load(path: Path) -> GroundTruth:
    with np.load(path) as z:
        ox, oy, res = z["spec"]
        free = z["free"]
        spec = GridSpec(float(ox), float(oy), float(res), free.shape[0], free.shape[1])
        grid = FreeGrid(spec, z["occupied"], z["centres"], free)
        return GroundTruth(grid, z["points"].astype(np.float64), z["observable"],
                           z["in_sight"])


def ground_truth(
    model: mujoco.MjModel,
    spawn_xy: np.ndarray,
    config: EvalConfig | None = None,
    cache_dir: Path | None = None,
) -> GroundTruth:
    """Cached ground truth: loads `<cache_dir>/gt-<key>.npz` or computes and stores it.

    Points are cached as float32 (µm rounding), so a cached result equals the fresh one to
    1e-6 m; every load of one cache file returns identical arrays.
    """
    config = config or EvalConfig()
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = cache_dir / f"gt-{cache_key(model, spawn_xy, config)}.npz"
    if path.exists():
        log.debug("ground truth from cache %s", path)
        return _load(path)
    gt = compute_ground_truth(model, spawn_xy, config)
    cache_dir.mkdir(parents=True, exist_ok=True)
    _save(path, gt)
    return _load(path)  # the same arrays a later cached call will return
