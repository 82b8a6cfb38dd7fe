"""Bench tables and figures from synthetic records and time series (no processes)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from services.config import SpacemapConfig
from services.evaluator import tables as tb
from services.evaluator.plots import (
    plot_coverage,
    plot_map_top,
    plot_methods_coverage,
    top_heights,
)
from services.launcher.bench import mission_config


def _records() -> list[dict]:
    out = []
    for method, cov, bv in (("standalone", (60.0, 70.0), (2.0, 4.0)),
                            ("space", (80.0, 90.0), (0.0, 0.02))):
        for seed, (c, b) in enumerate(zip(cov, bv, strict=True)):
            out.append({"world_label": "house", "robots": 3, "method": method, "seed": seed,
                        "coverage_3d_pct": c, "bounding_volume_pct": b, "rmse_3d_cm": 3.0,
                        "ate_rmse_cm": 2.0 + seed if method == "space" else 4.0,
                        "overlap_3d_pct": None if seed else 40.0, "completed": seed == 0})
    return out


def test_mean_std_uses_sample_std_and_skips_nulls() -> None:
    assert tb.mean_std([1.0, 3.0, None]) == (2.0, np.sqrt(2.0), 2)
    assert tb.mean_std([None]) == (None, None, 0)
    assert tb.mean_std([True, False]) == (0.5, np.sqrt(0.5), 2)


def test_table_markdown_has_mean_pm_std_per_method() -> None:
    md = tb.table_markdown(_records(), tb.TABLE1_METHODS, tb.TABLE1_METRICS, "Table I")
    assert "| metric | standalone | space |" in md
    assert "| 3D coverage (%) | 65.0 ± 7.1 | 85.0 ± 7.1 |" in md
    assert "| 3D RMSE (cm) | 3.0 ± 0.0 | 3.0 ± 0.0 |\n| ATE (cm) | 4.0 ± 0.0 | 2.5 ± 0.7 |" in md
    assert "(n=1/2)" in md  # a null overlap is counted, not averaged in
    assert "2D coverage (%) | n/a | n/a" in md
    md2 = tb.table_markdown(_records(), ("space",), {"completed": "completed runs"}, "II")
    assert "| completed runs | 1/2 |" in md2


def test_table_csv_long_format(tmp_path: Path) -> None:
    tb.write_table_csv(tmp_path / "t.csv", _records(), tb.TABLE1_METHODS, tb.TABLE1_METRICS)
    rows = list(csv.DictReader((tmp_path / "t.csv").open()))
    cov = [r for r in rows if r["metric"] == "coverage_3d_pct" and r["method"] == "space"]
    assert len(cov) == 1 and float(cov[0]["mean"]) == 85.0 and cov[0]["n"] == "2"


def test_bv_ratio_reports_standalone_over_space() -> None:
    (line,) = tb.bv_ratio_lines(_records())
    assert "300.0×" in line


def test_table1_sets_the_merger_off_beside_space() -> None:
    recs = _records() + [{**r, "method": "space-no-merger", "mapping_time_s": 100.0}
                         for r in _records() if r["method"] == "space"]
    md = tb.table_markdown(recs, tb.TABLE1_METHODS, tb.TABLE1_METRICS, "Table I")
    assert "| metric | standalone | space-no-merger | space |" in md
    assert "| mapping time (s) | n/a | 100.0 ± 0.0 | n/a |" in md


def test_bench_methods_set_the_merger_only_where_named() -> None:
    base = SpacemapConfig()
    assert base.edge.merge is True
    off = mission_config(base, "house", 3, "space-no-merger", 1, 60.0)
    assert (off.edge.merge, off.edge.planner, off.agent.drf) == (False, "space", True)
    assert mission_config(base, "house", 3, "space", 1, 60.0).edge.merge is True
    no = SpacemapConfig.model_validate({"edge": {"merge": False}})
    for method in ("space", "standalone", "rrt"):  # the base config's choice stands
        assert mission_config(no, "house", 3, method, 1, 60.0).edge.merge is False
    assert mission_config(no, "house", 3, "space-merger", 1, 60.0).edge.merge is True
    alone = mission_config(base, "bookstore", 6, "standalone", 2, 60.0)
    assert (alone.agent.drf, alone.sim.robots, alone.sim.seed) == (False, 6, 2)


def _png_ok(path: Path) -> None:
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 10_000, "a near-empty figure"


def test_plots_are_written(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 60.0, 5.0)
    rows = [{"sim_time_s": s, "coverage_3d_pct": s, "coverage_2d_pct": s + 5,
             "overlap_3d_pct": 30.0, "bounding_volume_pct": 0.1} for s in t]
    plot_coverage(rows, tmp_path / "cov.png")
    plot_map_top(rng.uniform(0, 5, (5000, 3)), [rng.uniform(0, 5, (50, 2))],
                 rng.uniform(0, 5, (4, 2)), tmp_path / "map.png")
    plot_methods_coverage({"space": [(t, t), (t, t + 5)], "nearest": [(t, t / 2)]},
                          tmp_path / "fig5.png")
    for name in ("cov.png", "map.png", "fig5.png"):
        _png_ok(tmp_path / name)


def test_the_map_from_above_keeps_each_columns_highest_point() -> None:
    points = np.array([[0.01, 0.01, 0.2], [0.02, 0.03, 1.5], [0.04, 0.02, 0.7],
                       [0.26, 0.11, 0.3], [-0.04, 0.12, 2.0]])
    top, extent = top_heights(points, 0.05)
    assert extent == pytest.approx((-0.05, 0.30, 0.0, 0.15))
    assert top.shape == (3, 7)
    assert top[0, 1] == 1.5  # three points in one column: the highest
    assert top[2, 6] == 0.3 and top[2, 0] == 2.0
    assert np.isnan(top).sum() == top.size - 3


def test_a_run_folder_names_its_bench_method() -> None:
    assert tb.method_name("space", True, True) == "space"  # the merger is on by default
    assert tb.method_name("space", True) == "space"
    assert tb.method_name("space", True, False) == "space-no-merger"
    assert tb.method_name("space", False) == "standalone"
    assert tb.method_name("space", False, False) == "standalone"
    assert tb.method_name("rrt", True) == "rrt"
    assert tb.method_name("rrt", True, False) == "rrt"  # no bench method: the planner's name
