"""A tiny bench (2 methods × 1 seed, 2 robots, 10 s) over real processes: run folders,
`spacemap eval` reproducing each run's metrics.json, and the tables and figures."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from services.cli import app
from services.config import load_config
from services.evaluator import run_files as rf
from services.evaluator.evaluate import evaluate_run_folder
from services.evaluator.metrics import METRICS_KEYS
from services.evaluator.scoring import LIVE_KEYS
from services.launcher.bench import BenchSpec, run_bench

pytestmark = pytest.mark.multiprocess


@pytest.fixture(scope="module")
def bench_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bench")
    spec = BenchSpec(worlds=("house",), robots=(2,), methods=("standalone", "space"),
                     seeds=(0,), sim_time_s=10.0, sample_every_s=3.0)
    records = run_bench(spec, load_config(environ={}), out)
    assert [r.get("failed") for r in records] == [None, None]
    return out


def _run_dirs(bench_dir: Path) -> list[Path]:
    return sorted((bench_dir / "runs").iterdir())


def test_run_folder_has_every_metric_and_artefact(bench_dir: Path) -> None:
    for run in _run_dirs(bench_dir):
        metrics = json.loads((run / "metrics.json").read_text())
        assert list(metrics) == list(METRICS_KEYS)
        assert metrics["coverage_3d_pct"] > 0 and metrics["total_distance_m"] > 0
        assert metrics["overlap_3d_pct"] is not None and metrics["sim_time_s"] == 10.0
        # estimates are published every tick, in the world frame: every robot has an ATE
        assert len(metrics["ate_rmse_cm_per_robot"]) == 2
        assert all(0.0 <= a < 50.0 for a in metrics["ate_rmse_cm_per_robot"])
        assert metrics["ate_rmse_cm"] == pytest.approx(sum(metrics["ate_rmse_cm_per_robot"]) / 2)
        for name in ("merged_map.ply", "robot_0_map.ply", "robot_1_map.ply", "grid.pgm",
                     "trajectory_0_gt.tum", "timeseries.csv", "report.md", "live.json"):
            assert (run / name).stat().st_size > 0, name
        for name in ("coverage.png", "map_top.png"):
            assert (run / name).stat().st_size > 10_000, name
        lines = (run / "timeseries.csv").read_text().splitlines()
        assert len(lines) >= 4, "expected samples at 3, 6, 9 s and the final map"
        # one overlap definition: the series ends at metrics.json's figure (4 decimals in CSV)
        last = rf.read_csv(run / "timeseries.csv")[-1]
        assert last["overlap_3d_pct"] == pytest.approx(metrics["overlap_3d_pct"], abs=1e-4)
        # where the CPU went: every service process and the launcher, all of them busy
        profile = json.loads((run / "profile.json").read_text())
        assert set(profile["cpu_s"]) == {"router", "edge", "agent0", "agent1", "sim", "launcher"}
        assert all(sec > 0 for sec in profile["cpu_s"].values())
        assert profile["cpu_s_total"] == pytest.approx(sum(profile["cpu_s"].values()), abs=0.1)
        assert profile["real_time_factor"] == pytest.approx(
            metrics["sim_time_s"] / profile["wall_time_s"], rel=1e-2)
    drf = {json.loads((r / "metrics.json").read_text())["drf"] for r in _run_dirs(bench_dir)}
    assert drf == {True, False}


def test_eval_recomputes_run_metrics(bench_dir: Path) -> None:
    for run in _run_dirs(bench_dir):
        recorded = json.loads((run / "metrics.json").read_text())
        again = evaluate_run_folder(run)
        assert json.loads(json.dumps(again)) == recorded
        assert set(LIVE_KEYS) < set(recorded)
    result = CliRunner().invoke(app, ["eval", str(run)])
    assert result.exit_code == 0, result.output
    assert "(metrics.json:" not in result.output
    assert (run / "metrics_eval.json").exists()
    explained = CliRunner().invoke(app, ["eval", str(run), "--explain"])
    assert explained.exit_code == 0, explained.output
    rows = [line for line in explained.output.splitlines() if line.startswith("| 1 |")]
    assert "| robot | reached | invalid |" in explained.output and len(rows) == 2
    # the tail's window: from the first sample at the series' own first coverage
    first = rf.read_csv(run / "timeseries.csv")[0]
    tail = CliRunner().invoke(app, ["eval", str(run), "--explain", "--from-coverage",
                                    str(float(first["coverage_3d_pct"]))])
    assert tail.exit_code == 0, tail.output
    assert f"first sampled at {float(first['sim_time_s']):.1f} s" in tail.output
    never = CliRunner().invoke(app, ["eval", str(run), "--explain", "--from-coverage", "100"])
    assert never.exit_code != 0 and "never reached 100" in never.output
    alone = CliRunner().invoke(app, ["eval", str(run), "--from-coverage", "50"])
    assert alone.exit_code != 0 and "goes with --explain" in alone.output


def test_eval_notices_a_changed_map(bench_dir: Path) -> None:
    """The recomputed fields really come from the files: copy robot 0's map and estimated
    trajectory over robot 1's."""
    run = _run_dirs(bench_dir)[0]
    recorded = json.loads((run / "metrics.json").read_text())
    tampered = run.parent.parent / "tampered"
    shutil.copytree(run, tampered)
    (tampered / "robot_1_map.ply").write_bytes((tampered / "robot_0_map.ply").read_bytes())
    (tampered / "trajectory_1_est.tum").write_bytes(
        (tampered / "trajectory_0_est.tum").read_bytes())
    again = evaluate_run_folder(tampered)
    assert again["overlap_3d_pct"] != recorded["overlap_3d_pct"]
    # robot 0's path is ≥ 0.34 m (two robot radii) from robot 1's at every instant
    assert again["ate_rmse_cm_per_robot"][1] > recorded["ate_rmse_cm_per_robot"][1] + 20.0


def test_tables_and_figures(bench_dir: Path) -> None:
    t1 = (bench_dir / "table1.md").read_text()
    assert "| metric | standalone | space |" in t1 and " ± " in t1
    assert "house, 2 robots" in (bench_dir / "tables.md").read_text()
    assert "coverage_3d_pct" in (bench_dir / "table2.csv").read_text()
    assert "| ATE (cm) |" in t1
    fig = bench_dir / "fig5_house_2r.png"
    assert fig.stat().st_size > 10_000
