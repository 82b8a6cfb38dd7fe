"""Router, simulator, edge and two agents as separate OS processes over a real zenoh router."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
import yaml

from services.common.bus import connect
from services.config import load_config, write_config
from services.launcher.monitor import Monitor
from services.launcher.run import start_services
from services.processes import ProcessGroup, free_tcp_port, spacemap_command
from tests.conftest import REPO, processes_tagged

pytestmark = pytest.mark.multiprocess


def wait_for(condition: Callable[[], bool], monitor: Monitor, group: ProcessGroup,
             timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        monitor.pump(timeout=0.2)
        dead = group.dead()
        assert not dead, f"service died while waiting for {what}: {dead}"
        if condition():
            return
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


def test_two_robot_mission_over_the_bus(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    config = load_config(overrides={
        "bus.connect": endpoint, "sim.robots": 2, "sim.max_sim_time_s": 90.0, "sim.seed": 3,
    })
    write_config(config, tmp_path / "config.yaml")
    group = ProcessGroup(tmp_path / "logs")
    group.start("router", spacemap_command("router", "--listen", endpoint))
    try:
        with connect(config.bus) as bus:
            monitor = Monitor(bus, robots=2)
            start_services(group, tmp_path / "config.yaml", robots=2)
            wait_for(lambda: monitor.clock is not None and monitor.grid is not None,
                     monitor, group, 120, "the first tick and merged grid")
            first_known = int((monitor.grid.cells >= 0).sum())
            wait_for(lambda: all(t.goals_assigned for t in monitor.tracks.values()),
                     monitor, group, 240, "a goal for every robot")
            wait_for(lambda: any(t.goals_reached for t in monitor.tracks.values()),
                     monitor, group, 300, "a reached goal")
            wait_for(lambda: monitor.sim_time_s >= 30.0, monitor, group, 300, "30 s of sim time")
            assert int((monitor.grid.cells >= 0).sum()) > 2 * first_known, "the map did not grow"
            for robot, track in monitor.tracks.items():
                xy = np.asarray(track.gt_xyyaw)[:, :2]
                travelled = np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()
                assert travelled > 1.0, f"robot {robot} moved only {travelled:.2f} m"
            assert bus.dropped.total() == 0, f"monitor dropped messages: {bus.dropped}"
    finally:
        codes = group.stop(order=["sim", "edge", "agent0", "agent1", "router"])
    assert all(code == 0 for name, code in codes.items()), f"unclean exits: {codes}"
    assert processes_tagged(tmp_path / "logs") == [], "processes left behind"


def config_sensors(run_dir: Path) -> str:
    return yaml.safe_load((run_dir / "config.yaml").read_text())["sim"]["sensors"]


def _spacemap_run(out: Path, *args: str) -> dict:
    proc = subprocess.run(
        [sys.executable, "-m", "services", "run", "--out", str(out), *args],
        cwd=REPO, capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert processes_tagged(out / "logs") == [], "processes left behind"
    return json.loads((out / "metrics.json").read_text())


def test_spacemap_run_writes_a_run_folder_and_repeats_exactly(tmp_path: Path) -> None:
    args = ("--robots", "2", "--sim-time", "20", "--seed", "1")
    out = tmp_path / "run"
    metrics = _spacemap_run(out, *args)
    for key in ("coverage_3d_pct", "coverage_2d_pct", "total_distance_m", "robots", "world",
                "seed", "completed", "sim_time_s", "wall_time_s", "bytes_per_robot"):
        assert key in metrics
    assert metrics["robots"] == 2 and metrics["seed"] == 1
    assert metrics["sim_time_s"] >= 19.0
    assert metrics["coverage_3d_pct"] > 5.0 and metrics["total_distance_m"] > 1.0
    # default sensors are realistic (noisy depth with dropouts, odometry random walk): the
    # short mission's map must still be ghost-free to SPEC §8's worst-seed bound
    assert config_sensors(out) == "realistic"
    assert metrics["bounding_volume_pct"] <= 0.05, metrics["bounding_volume_pct"]
    assert metrics["ate_rmse_cm"] is not None and metrics["ate_rmse_cm"] < 5.0
    cloud = o3d.io.read_point_cloud(str(out / "merged_map.ply"))
    assert len(cloud.points) > 1000
    for name in ("grid.pgm", "grid.yaml", "config.yaml", "report.md", "timeseries.csv",
                 "trajectory_0_gt.tum", "robot_1_map.ply"):
        assert (out / name).exists(), name
    # Lockstep determinism (SPEC §8): same seed and world, identical metrics but wall time
    # (the default protocol: the fleet waits for every plan, L = 0).
    assert load_config(out / "config.yaml").sim.edge_lag_ticks == 0
    again = _spacemap_run(tmp_path / "again", *args)
    metrics.pop("wall_time_s"), again.pop("wall_time_s")
    assert again == metrics
    for robot in range(2):
        name = f"trajectory_{robot}_gt.tum"
        assert (out / name).read_text() == (tmp_path / "again" / name).read_text()
    # the goal/status/state log behind `spacemap eval --explain` is as deterministic
    events = (out / "events.jsonl").read_text()
    assert events == (tmp_path / "again" / "events.jsonl").read_text()
    assert '"kind": "goal"' in events and '"kind": "state"' in events


def test_pipelined_edge_repeats_exactly(tmp_path: Path) -> None:
    """sim.edge_pipeline_ticks = 9 (the edge's outputs of tick k apply at k + L + 1, the plan
    runs while the fleet goes on) repeats exactly too; the default, L = 0, is the run-folder
    test's above."""
    args = ("--robots", "2", "--sim-time", "12", "--seed", "2", "--sample-every", "0",
            "--set", "sim.edge_pipeline_ticks=9")
    first = _spacemap_run(tmp_path / "first", *args)
    assert yaml.safe_load((tmp_path / "first" / "config.yaml").read_text()
                          )["sim"]["edge_pipeline_ticks"] == 9
    assert first["total_distance_m"] > 1.0  # the robots followed the edge's goals
    again = _spacemap_run(tmp_path / "again", *args)
    first.pop("wall_time_s"), again.pop("wall_time_s")
    assert again == first
    for robot in range(2):
        name = f"trajectory_{robot}_gt.tum"
        assert (tmp_path / "first" / name).read_text() == (tmp_path / "again" / name).read_text()
