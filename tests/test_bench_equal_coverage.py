"""bench/bench_equal_coverage.py: each planner's time, distance and overlap at the level the
reference planner stopped at, read from run folders."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def write_run(folder: Path, planner: str, seed: int, final: float, rows: list[tuple]) -> None:
    run = folder / f"house_3r_{planner}_s{seed}"
    run.mkdir(parents=True)
    (run / "metrics.json").write_text(json.dumps({
        "world": "house", "robots": 3, "planner": planner, "seed": seed,
        "coverage_3d_pct": final, "mapping_time_s": rows[-1][0]}))
    with (run / "timeseries.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sim_time_s", "coverage_3d_pct", "overlap_3d_pct", "distance_m"])
        w.writerows(rows)


def test_times_at_the_reference_level(tmp_path: Path) -> None:
    # rrt stops at 96.123456 % (its last CSV row rounds it down); space passes it at 20 s
    write_run(tmp_path, "rrt", 0, 96.123456, [(10, 80.0, 70.0, 10.0), (30, 96.1235, 75.0, 30.0)])
    write_run(tmp_path, "space", 0, 99.0, [(10, 90.0, 60.0, 12.0), (20, 96.2, 65.0, 22.0),
                                           (40, 99.0, 70.0, 41.0)])
    write_run(tmp_path, "rrt", 1, 99.5, [(10, 99.5, 50.0, 9.0)])
    write_run(tmp_path, "space", 1, 98.0, [(10, 98.0, 50.0, 9.0)])  # never reaches 99.5
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_equal_coverage.py"),
                          str(tmp_path)], capture_output=True, text=True, check=True).stdout
    assert "| house | 3 | 0 | 96.12 | 30 | 30 / 30.0 / 75.0 | 20 / 22.0 / 65.0 |" in out
    assert "| house | 3 | 1 | 99.50 | 10 | 10 / 9.0 / 50.0 | never |" in out
    # the paired means use seed 0 only: seed 1's space run never reached the level
    assert "| house | 3 | 1 | 30.0 | 30.0 | 20.0 | 22.0 |" in out
    # and as a change against rrt, with its interval (one seed: no spread)
    assert "| house | 3 | 1 | -33.3 % (-33.3 to -33.3) | -26.7 % (-26.7 to -26.7) |" in out
