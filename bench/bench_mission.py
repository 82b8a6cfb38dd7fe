"""Whole-mission wall time: `spacemap run` repeated, medians of wall time and key metrics.

    .venv/bin/python bench/bench_mission.py --robots 3 --sim-time 120 --repeats 3
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def run_once(out: Path, args: list[str]) -> dict:
    cmd = [sys.executable, "-m", "services", "run", "--out", str(out), *args]
    subprocess.run(cmd, cwd=REPO, check=True, capture_output=True)
    return json.loads((out / "metrics.json").read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--sim-time", type=float, default=120.0)
    parser.add_argument("--world", default="house")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    opts = parser.parse_args()
    args = ["--robots", str(opts.robots), "--sim-time", str(opts.sim_time),
            "--world", opts.world, "--seed", str(opts.seed)]
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(opts.repeats):
            runs.append(run_once(Path(tmp) / f"run{i}", args))
    keys = ("wall_time_s", "sim_time_s", "coverage_3d_pct", "coverage_2d_pct",
            "bounding_volume_pct", "total_distance_m")
    print(f"spacemap run {' '.join(args)}; {opts.repeats} runs, medians\n")
    print("| measure | median | min | max |\n|---|---:|---:|---:|")
    for key in keys:
        values = [float(r[key]) for r in runs if r.get(key) is not None]
        if values:
            print(f"| {key} | {statistics.median(values):.2f} | {min(values):.2f} | "
                  f"{max(values):.2f} |")
    completed = sum(bool(r["completed"]) for r in runs)
    print(f"\ncompleted before the cap: {completed}/{opts.repeats}")


if __name__ == "__main__":
    main()
