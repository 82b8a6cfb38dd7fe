"""The run folder: maps, grid, trajectories, time series, config, metrics and a short report."""

from __future__ import annotations

import csv
import logging
from pathlib import Path

import numpy as np

from schemas import messages as m
from services.common.config import SpacemapConfig
from services.launcher.monitor import Monitor
from services.launcher.outputs import write_grid, write_json, write_ply, write_tum

log = logging.getLogger(__name__)

CLOUD_TIMEOUT_S = 30.0


def fetch_cloud(monitor: Monitor) -> m.Cloud:
    """The merged cloud P* from the edge's `map/cloud` queryable."""
    reply = monitor.bus.query(
        monitor.bus.keys.map_cloud(), m.CloudRequest(), m.Cloud, timeout=CLOUD_TIMEOUT_S
    )
    assert isinstance(reply, m.Cloud)
    return reply


def write_run_folder(
    out_dir: Path, config: SpacemapConfig, monitor: Monitor, completed: bool, wall_s: float
) -> dict[str, object]:
    """Write every artefact of a run and return metrics.json's content."""
    cloud = fetch_cloud(monitor)
    monitor.trim_to_common_tick()
    write_ply(out_dir / "merged_map.ply", cloud.points_world, cloud.colors)
    for robot in range(config.sim.robots):
        mine = cloud.robot_ids == robot
        write_ply(out_dir / f"robot_{robot}_map.ply", cloud.points_world[mine], cloud.colors[mine])
    if monitor.grid is not None:
        write_grid(out_dir / "grid", monitor.grid)
    for robot, track in monitor.tracks.items():
        write_tum(out_dir / f"trajectory_{robot}_gt.tum", track.gt_stamps_ns, track.gt_xyyaw)
        write_tum(out_dir / f"trajectory_{robot}_est.tum", track.est_stamps_ns, track.est_xyyaw)
    _write_series(out_dir / "timeseries.csv", monitor)
    from services.launcher.scoring import score_run

    metrics = score_run(config, cloud, monitor, completed, wall_s)
    write_json(out_dir / "metrics.json", metrics)
    _write_report(out_dir / "report.md", metrics, monitor)
    log.info("run folder written: %s", out_dir)
    return metrics


def _write_series(path: Path, monitor: Monitor) -> None:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["sim_time_s", "known_area_m2", "frontiers"])
        res2 = monitor.grid.resolution_m**2 if monitor.grid else 0.0
        for row in monitor.series:
            writer.writerow(
                [f"{row.sim_time_s:.2f}", f"{row.known_cells * res2:.3f}", row.frontiers]
            )


def _write_report(path: Path, metrics: dict[str, object], monitor: Monitor) -> None:
    lines = ["# spacemap run", "", "| metric | value |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in metrics.items()]
    lines += ["", "| robot | goals assigned | reached | statuses |", "|---|---|---|---|"]
    for robot, t in monitor.tracks.items():
        statuses = ", ".join(f"{k}: {v}" for k, v in sorted(t.goal_statuses.items()))
        lines.append(f"| {robot} | {t.goals_assigned} | {t.goals_reached} | {statuses} |")
    path.write_text("\n".join(lines) + "\n")


def trajectory_length(xyyaw: list[tuple[float, float, float]]) -> float:
    if len(xyyaw) < 2:
        return 0.0
    xy = np.asarray(xyyaw)[:, :2]
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())
