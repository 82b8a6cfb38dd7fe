"""metrics.json of a run: the evaluator's metrics against the world's ground truth."""

from __future__ import annotations

from schemas import messages as m
from services.common.config import SpacemapConfig
from services.launcher.monitor import Monitor


def score_run(
    config: SpacemapConfig, cloud: m.Cloud, monitor: Monitor, completed: bool, wall_s: float
) -> dict[str, object]:
    from services.launcher.report import trajectory_length

    return {
        "sim_time_s": monitor.sim_time_s,
        "wall_time_s": wall_s,
        "total_distance_m": sum(trajectory_length(t.gt_xyyaw) for t in monitor.tracks.values()),
        "robots": config.sim.robots, "world": config.sim.world, "seed": config.sim.seed,
        "completed": completed, "points": len(cloud.points_world),
    }
