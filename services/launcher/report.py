"""The run folder: maps, grids, trajectories, time series, config, metrics, plots, report.

Metrics are computed by `spacemap eval`'s own code from the files just written, so a run's
metrics.json and `spacemap eval RUN_DIR` agree by construction.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from schemas import messages as m
from services.config import SpacemapConfig
from services.evaluator import run_files as rf
from services.evaluator.evaluate import evaluate_run_folder, explain_run_folder, load_tracks
from services.evaluator.plots import plot_coverage, plot_label, plot_map_top
from services.evaluator.scoring import Probe, distance_at
from services.launcher.monitor import Monitor
from services.launcher.recorders import Recorders
from services.launcher.sampler import SPLIT_MAPS, CoverageSampler, fetch_robot_grid, robot_clouds

log = logging.getLogger(__name__)

SERIES_COLUMNS = [
    "sim_time_s", "coverage_3d_pct", "coverage_2d_pct", "overlap_3d_pct",
    "bounding_volume_pct", "ghost_volume_m3", "distance_m", "known_area_m2", "frontiers",
    "map_points",
]


def mission_end_stamp_ns(config: SpacemapConfig, live: dict[str, Any]) -> int:
    """The stamp of the mission's last tick (completion or the cap): tracks end there,
    whatever the clock did while the launcher shut the mission down."""
    tick_ns = round(config.sim.tick_s * 1e9)
    return round(float(live["sim_time_s"]) / config.sim.tick_s) * tick_ns


def write_run_folder(
    out_dir: Path, config: SpacemapConfig, monitor: Monitor, sampler: CoverageSampler,
    final_cloud: m.Cloud, live: dict[str, Any], probe: Probe, recorders: Recorders | None = None,
) -> dict[str, Any]:
    """Write every artefact of a run and return metrics.json's content; `recorders` get the
    final maps and trimmed tracks, the same the PLY/PGM/TUM files hold."""
    robots = config.sim.robots
    per_robot, live["robot_maps_source"] = robot_clouds(monitor.bus, final_cloud, robots)
    if SPLIT_MAPS in live["robot_maps_source"]:
        log.warning("per-robot clouds: some from the merged map split by robot_ids")
    # the series ends at the final map, scored on the very robot maps metrics.json reads
    sampler.add(final_cloud, per_robot)
    monitor.trim_to_common_tick(mission_end_stamp_ns(config, live))
    if recorders is not None:
        recorders.finish(final_cloud, per_robot, monitor.grid, monitor.tracks)
    _write_maps(out_dir, monitor, final_cloud, per_robot, robots, live)
    for robot, track in monitor.tracks.items():
        rf.write_tum(rf.gt_trajectory_path(out_dir, robot), track.gt_stamps_ns, track.gt_xyyaw)
        rf.write_tum(rf.est_trajectory_path(out_dir, robot), track.est_stamps_ns,
                     track.est_xyyaw)
    tracks = load_tracks(out_dir, robots)
    rows = _with_distance(sampler.rows, tracks)
    rf.write_csv(out_dir / rf.TIMESERIES, rows, SERIES_COLUMNS)
    frontiers_xy = _frontiers_xy(monitor.frontiers)
    rf.write_json(out_dir / rf.FRONTIERS, {"xy": frontiers_xy.tolist()})
    rf.write_json(out_dir / rf.LIVE, live)
    end_tick = round(float(live["sim_time_s"]) / config.sim.tick_s)
    rf.write_events(out_dir / rf.EVENTS, ordered_events(monitor, end_tick))
    metrics = evaluate_run_folder(out_dir, probe)
    rf.write_json(out_dir / rf.METRICS, metrics)
    write_plots(out_dir, final_cloud.points_world, tracks, frontiers_xy, rows, metrics)
    _write_report(out_dir / "report.md", metrics, monitor, live)
    with (out_dir / "report.md").open("a") as report:
        report.write("\n## Where the time went\n\n" + explain_run_folder(out_dir))
    log.info("run folder written: %s", out_dir)
    return metrics


_KIND_ORDER = {"status": 0, "goal": 1, "state": 2}


def ordered_events(monitor: Monitor, end_tick: int) -> list[dict[str, Any]]:
    """Every robot's events up to the mission's last tick, in an order that does not depend
    on arrival: by robot, tick, then a goal's end before the next goal of the same tick."""
    events = [{"robot": robot, **e} for robot, t in monitor.tracks.items() for e in t.events
              if e["tick"] <= end_tick]
    return sorted(events, key=lambda e: (e["robot"], e["tick"], _KIND_ORDER[e["kind"]],
                                         e.get("goal_id", -1)))


def _write_maps(
    out_dir: Path, monitor: Monitor, cloud: m.Cloud, per_robot: list[np.ndarray], robots: int,
    live: dict[str, Any],
) -> None:
    rf.write_ply(out_dir / rf.MERGED_MAP, cloud.points_world, cloud.colors)
    for robot, points in enumerate(per_robot):
        rf.write_ply(rf.robot_map_path(out_dir, robot), points)
    if monitor.grid is not None:
        rf.write_grid(out_dir / rf.MERGED_GRID, monitor.grid)
    grids = [fetch_robot_grid(monitor.bus, r) for r in range(robots)]
    live["robot_grids_ok"] = all(g is not None for g in grids)
    for robot, grid in enumerate(grids):
        if grid is not None:
            rf.write_grid(rf.robot_grid_stem(out_dir, robot), grid)


def _with_distance(
    rows: list[dict[str, Any]], tracks: list[tuple[np.ndarray, np.ndarray]]
) -> list[dict[str, Any]]:
    times = np.array([r["sim_time_s"] for r in rows], dtype=np.float64)
    return [{**r, "distance_m": d} for r, d in zip(rows, distance_at(times, tracks), strict=True)]


def _frontiers_xy(frontiers: m.Frontiers | None) -> np.ndarray:
    if frontiers is None or not frontiers.frontiers:
        return np.zeros((0, 2))
    return np.array([f.goal_xy for f in frontiers.frontiers], dtype=np.float64)


def write_plots(
    out_dir: Path, points_world: np.ndarray, tracks: list[tuple[np.ndarray, np.ndarray]],
    frontiers_xy: np.ndarray, rows: list[dict[str, Any]], metrics: dict[str, Any],
) -> None:
    """coverage.png and map_top.png (also rebuilt by `spacemap eval --plots`)."""
    label = plot_label(metrics)
    plot_coverage(rows, out_dir / "coverage.png", f"coverage over time ({label})")
    plot_map_top(points_world, [xy for _, xy in tracks], frontiers_xy, out_dir / "map_top.png",
                 f"merged map from above ({label})")


def _fmt(value: Any) -> str:
    if isinstance(value, list):  # per-robot figures (ate_rmse_cm_per_robot)
        return ", ".join(_fmt(v) for v in value)
    return f"{value:.3f}" if isinstance(value, float) else str(value)


def _write_report(
    path: Path, metrics: dict[str, Any], monitor: Monitor, live: dict[str, Any]
) -> None:
    lines = ["# spacemap run", "", "| metric | value |", "|---|---|"]
    lines += [f"| {k} | {_fmt(v)} |" for k, v in metrics.items() if k != "bytes_per_robot"]
    for robot, b in (metrics.get("bytes_per_robot") or {}).items():
        lines.append(f"| bytes robot {robot} | {b['total']} ({b['per_sim_s']:.0f} B/sim s) |")
    lines += ["", f"Per-robot maps: {live.get('robot_maps_source')}; per-robot grids: "
              f"{'from the edge' if live.get('robot_grids_ok') else 'missing (no 2D overlap)'}.",
              "", "![coverage](coverage.png)", "", "![map](map_top.png)", ""]
    lines += ["| robot | goals assigned | reached | statuses |", "|---|---|---|---|"]
    for robot, t in monitor.tracks.items():
        statuses = ", ".join(f"{k}: {v}" for k, v in sorted(t.goal_statuses.items()))
        lines.append(f"| {robot} | {t.goals_assigned} | {t.goals_reached} | {statuses} |")
    path.write_text("\n".join(lines) + "\n")
