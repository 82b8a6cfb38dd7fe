"""metrics.json of a run: the evaluator's metrics against the world's ground truth."""

from __future__ import annotations

import logging

import numpy as np

from schemas import messages as m
from services.common.config import SpacemapConfig
from services.common.grid import GridSpec
from services.evaluator import metrics as mx
from services.evaluator.world_truth import eval_config_for, world_ground_truth
from services.launcher.monitor import Monitor

log = logging.getLogger(__name__)


def grid_spec(grid: m.OccupancyGrid) -> GridSpec:
    H, W = grid.cells.shape
    return GridSpec(grid.origin_x, grid.origin_y, grid.resolution_m, H, W)


def score_run(
    config: SpacemapConfig, cloud: m.Cloud, monitor: Monitor, completed: bool, wall_s: float
) -> dict[str, object]:
    """Every SPEC §7 key; those this version cannot measure yet are null."""
    sim = config.sim
    gt = world_ground_truth(sim)
    ev = eval_config_for(sim)
    points = cloud.points_world.astype(np.float64)
    ghost_keys, ghost = mx.ghost_voxels(
        points, gt.surface_points_world, ev.voxel_m, ev.ghost_dist_m
    )
    point_ghost = _point_ghost_mask(points, ev.voxel_m, ghost_keys, ghost)
    coverage_2d = None
    if monitor.grid is not None:
        known = monitor.grid.cells >= 0
        coverage_2d = mx.coverage_2d(
            known, grid_spec(monitor.grid), gt.free_grid.free, gt.free_grid.spec
        )
    bytes_total = monitor.bytes_per_robot()
    sim_s = max(monitor.sim_time_s, 1e-9)
    return mx.assemble_metrics(
        coverage_3d_pct=mx.coverage_3d(
            points, gt.observable_points_world, ev.coverage_radius_m, ghost_mask=point_ghost
        ),
        coverage_2d_pct=coverage_2d,
        rmse_3d_cm=mx.rmse_3d_cm(points, gt.surface_points_world),
        bounding_volume_pct=mx.bounding_volume_pct(
            points, gt.surface_points_world, ev.voxel_m, ev.ghost_dist_m
        ),
        mapping_time_s=monitor.sim_time_s if completed else None,
        total_distance_m=sum(
            mx.path_length(np.asarray(t.gt_xyyaw)[:, :2]) if t.gt_xyyaw else 0.0
            for t in monitor.tracks.values()
        ),
        bytes_per_robot={
            str(r): {"total": b, "per_sim_s": b / sim_s} for r, b in bytes_total.items()
        },
        sim_time_s=monitor.sim_time_s,
        wall_time_s=wall_s,
        robots=sim.robots,
        world=sim.world,
        planner=config.edge.planner,
        drf=config.agent.drf,
        seed=sim.seed,
        completed=completed,
    )


def _point_ghost_mask(
    points: np.ndarray, voxel_m: float, keys: np.ndarray, ghost: np.ndarray
) -> np.ndarray:
    from services.common import voxels

    point_keys = voxels.pack(voxels.voxel_indices(points, voxel_m))
    return ghost[np.searchsorted(keys, point_keys)]
