"""`spacemap eval`: recompute metrics.json from the files of a finished run folder."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from schemas import messages as m
from services.config import SpacemapConfig
from services.evaluator import run_files as rf
from services.evaluator.scoring import Probe, score
from services.evaluator.world_truth import eval_config_for, world_ground_truth
from services.simulator.config import SimConfig

log = logging.getLogger(__name__)


def probe_for(sim: SimConfig) -> Probe:
    """Ground truth (cached on disk) of the run's world and spawn poses."""
    return Probe(world_ground_truth(sim), eval_config_for(sim))


@dataclass(frozen=True)
class RunConfig:
    """The parts of a run's config.yaml the evaluator needs. Read leniently: a run folder
    stays evaluable when a service's config section gains or loses fields later."""

    sim: SimConfig
    planner: str
    drf: bool
    merge: bool = False  # the edge's map merger (`edge.merge`)

    @classmethod
    def of(cls, config: SpacemapConfig) -> RunConfig:
        return cls(config.sim, config.edge.planner, config.agent.drf, config.edge.merge)

    @classmethod
    def read(cls, path: Path) -> RunConfig:
        tree = yaml.safe_load(path.read_text()) or {}
        sim = {k: v for k, v in tree.get("sim", {}).items() if k in SimConfig.model_fields}
        edge = tree.get("edge", {})
        return cls(SimConfig.model_validate(sim), edge.get("planner", "space"),
                   bool(tree.get("agent", {}).get("drf", True)), bool(edge.get("merge", False)))

    def identity(self) -> dict[str, Any]:
        return {"robots": self.sim.robots, "world": self.sim.world, "planner": self.planner,
                "drf": self.drf, "merge": self.merge, "seed": self.sim.seed}


def load_tracks(
    run_dir: Path, robots: int, estimated: bool = False
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(stamps_s, xy) of each robot's ground-truth (or estimated) trajectory; a missing
    estimate file reads as an empty trajectory (it has no ATE, the run stays evaluable)."""
    out = []
    for robot in range(robots):
        path = (rf.est_trajectory_path if estimated else rf.gt_trajectory_path)(run_dir, robot)
        if estimated and not path.exists():
            out.append((np.zeros(0), np.zeros((0, 2))))
            continue
        stamps, xyyaw = rf.read_tum(path)
        out.append((stamps, xyyaw[:, :2]))
    return out


def _optional_grid(stem: Path) -> m.OccupancyGrid | None:
    return rf.read_grid(stem) if stem.with_suffix(".pgm").exists() else None


def _robot_grids(run_dir: Path, robots: int) -> list[m.OccupancyGrid] | None:
    grids = [_optional_grid(rf.robot_grid_stem(run_dir, r)) for r in range(robots)]
    return None if any(g is None for g in grids) else grids  # type: ignore[return-value]


def evaluate_run_folder(run_dir: Path, probe: Probe | None = None) -> dict[str, Any]:
    """metrics.json's content from the run folder's files (live-only keys from live.json)."""
    config = RunConfig.read(run_dir / "config.yaml")
    probe = probe or probe_for(config.sim)
    robots = config.sim.robots
    live = rf.read_json(run_dir / rf.LIVE)
    robot_points = None
    if live.get("robot_maps_ok", True):
        robot_points = [rf.read_ply(rf.robot_map_path(run_dir, r)) for r in range(robots)]
    series = rf.read_csv(run_dir / rf.TIMESERIES)
    return score(
        probe,
        rf.read_ply(run_dir / rf.MERGED_MAP),
        robot_points,
        _optional_grid(run_dir / rf.MERGED_GRID),
        _robot_grids(run_dir, robots),
        load_tracks(run_dir, robots),
        load_tracks(run_dir, robots, estimated=True),
        [r for r in series if r.get("coverage_3d_pct") is not None],
        live,
        config.identity(),
    )


def redraw_plots(run_dir: Path, metrics: dict[str, Any]) -> None:
    """coverage.png and map_top.png from the run folder's files."""
    from services.evaluator.plots import plot_coverage, plot_label, plot_map_top

    config = RunConfig.read(run_dir / "config.yaml")
    tracks = load_tracks(run_dir, config.sim.robots)
    frontiers = rf.read_json(run_dir / rf.FRONTIERS)["xy"] if (run_dir / rf.FRONTIERS).exists() \
        else []
    label = plot_label(metrics)
    plot_coverage(rf.read_csv(run_dir / rf.TIMESERIES), run_dir / "coverage.png", label)
    plot_map_top(rf.read_ply(run_dir / rf.MERGED_MAP), [xy for _, xy in tracks],
                 np.asarray(frontiers, dtype=np.float64), run_dir / "map_top.png", label)


def explain_run_folder(run_dir: Path, from_coverage_pct: float | None = None) -> str:
    """`spacemap eval --explain`: where each robot's time and distance went (markdown);
    with `from_coverage_pct`, only after the 3D coverage first reached it (ValueError: the
    run never did)."""
    from services.evaluator.explain import (
        coverage_tick,
        explain_events,
        markdown,
        revisits,
        turned_away,
    )

    path = run_dir / rf.EVENTS
    if not path.exists():
        raise FileNotFoundError(f"{path} missing: the run predates events.jsonl")
    config = RunConfig.read(run_dir / "config.yaml")
    live = rf.read_json(run_dir / rf.LIVE)
    tick_s = config.sim.tick_s
    end_tick = round(float(live["sim_time_s"]) / tick_s)
    tracks = load_tracks(run_dir, config.sim.robots)
    events = rf.read_events(path)
    if from_coverage_pct is not None:
        start = coverage_tick(rf.read_csv(run_dir / rf.TIMESERIES), from_coverage_pct, tick_s)
        if start is None:
            raise ValueError(f"{run_dir}: 3D coverage never reached {from_coverage_pct} % in "
                             f"{rf.TIMESERIES}")
        start = min(start, end_tick)
        head = (f"From 3D coverage {from_coverage_pct:g} % (first sampled at "
                f"{start * tick_s:.1f} s) to the end ({end_tick * tick_s:.1f} s)\n\n")
        return head + markdown(explain_events(events, tracks, end_tick, tick_s, start))
    per_robot = explain_events(events, tracks, end_tick, tick_s)
    again, reached = revisits(events)
    given, away = turned_away(events)
    return markdown(per_robot) + (
        f"\nReached goals at a place (0.5 m) reached before: {again} of {reached}\n"
        f"Goals replaced by one 1 m or more away: {away}, of which {given} had their place "
        "(0.75 m) given out again later (a robot turned away from a region nobody had seen)\n")

