"""Whole-mission wall time: `spacemap run` repeated, medians of wall time and key metrics,
and where the CPU went (each run's profile.json: CPU seconds per process).

    .venv/bin/python bench/bench_mission.py --robots 3 --sim-time 120 --repeats 3
    .venv/bin/python bench/bench_mission.py --sim-time 300 --sample-every 0 \
        --set sim.edge_pipeline_ticks=5
    .venv/bin/python bench/bench_mission.py --robots 3 --sim-time 120 --repeats 3 --tls both

`--tls both` alternates runs with mutual TLS (the default) and plain TCP (`bus.tls=false`),
in the order TLS, TCP, TCP, TLS, ... so that a load drift on a shared machine hits both
alike, and prints a table for each.
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


def run_once(out: Path, args: list[str]) -> tuple[dict, dict]:
    """(metrics.json, profile.json) of one `spacemap run`."""
    cmd = [sys.executable, "-m", "services", "run", "--out", str(out), *args]
    subprocess.run(cmd, cwd=REPO, check=True, capture_output=True)
    return (json.loads((out / "metrics.json").read_text()),
            json.loads((out / "profile.json").read_text()))


def cpu_rows(profiles: list[dict]) -> dict[str, list[float]]:
    """CPU seconds per process kind and run: agents summed, each other process alone."""
    rows: dict[str, list[float]] = {}
    for prof in profiles:
        kinds: dict[str, float] = {}
        for name, sec in prof["cpu_s"].items():
            kind = "agents (sum)" if name.startswith("agent") else name
            kinds[kind] = kinds.get(kind, 0.0) + sec
        kinds["total"] = prof["cpu_s_total"]
        for kind, sec in kinds.items():
            rows.setdefault(kind, []).append(sec)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--sim-time", type=float, default=120.0)
    parser.add_argument("--world", default="house")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--keep", type=Path, default=None,
                        help="write the run folders here (runN/) instead of a temporary one, "
                             "e.g. to compare metrics.json before and after a change")
    parser.add_argument("--sample-every", type=float, default=None,
                        help="spacemap run's live coverage period, sim s (0: final map only)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                        help="config override passed to spacemap run (repeatable)")
    parser.add_argument("--tls", choices=["on", "off", "both"], default="on",
                        help="links: mutual TLS (default), plain TCP, or alternate the two")
    opts = parser.parse_args()
    args = ["--robots", str(opts.robots), "--sim-time", str(opts.sim_time),
            "--world", opts.world, "--seed", str(opts.seed)]
    if opts.sample_every is not None:
        args += ["--sample-every", str(opts.sample_every)]
    for item in opts.set:
        args += ["--set", item]
    modes = {"on": [True], "off": [False], "both": [True, False]}[opts.tls]
    results: dict[bool, tuple[list[dict], list[dict]]] = {m: ([], []) for m in modes}
    with tempfile.TemporaryDirectory() as tmp:
        root = opts.keep or Path(tmp)
        for i in range(opts.repeats):
            for tls in modes if i % 2 == 0 else modes[::-1]:  # ABBA: fair to a load drift
                extra = [] if tls else ["--set", "bus.tls=false"]
                metrics, profile = run_once(root / f"run{i}{'' if tls else '-tcp'}",
                                            args + extra)
                results[tls][0].append(metrics)
                results[tls][1].append(profile)
    for tls, (runs, profiles) in results.items():
        link = "mutual TLS" if tls else "plain TCP (bus.tls=false)"
        print(f"## {link}\n\nspacemap run {' '.join(args)}; {opts.repeats} runs, medians\n")
        report(runs, profiles)
    if len(results) == 2:
        rtf = {t: statistics.median(float(p["real_time_factor"]) for p in results[t][1])
               for t in results}
        print(f"real-time factor, TLS / plain TCP (medians): {rtf[True] / rtf[False]:.3f}")
        same = all(_no_wall(a) == _no_wall(b) for a, b in zip(*(results[t][0] for t in results),
                                                              strict=True))
        print(f"metrics.json of each TLS run equal to its plain TCP run's: {same}")


def _no_wall(metrics: dict) -> dict:
    return {k: v for k, v in metrics.items() if k != "wall_time_s"}


def report(runs: list[dict], profiles: list[dict]) -> None:
    keys = ("wall_time_s", "sim_time_s", "mapping_time_s", "coverage_3d_pct",
            "coverage_2d_pct", "bounding_volume_pct", "total_distance_m")
    print("| measure | median | min | max |\n|---|---:|---:|---:|")
    for key in keys:
        _row(key, [float(r[key]) for r in runs if r.get(key) is not None])
    _row("real-time factor", [float(p["real_time_factor"]) for p in profiles])
    sampler = [float(p["sampler_core_pct"]) for p in profiles if p.get("sampler_core_pct")]
    if sampler:  # the live coverage sampler's thread, % of one core over the wall time
        _row("live sampler, % of a core", sampler)
        stages = [p.get("sampler_stage_cpu_s") or {} for p in profiles]
        for stage in sorted({k for st in stages for k in st}):
            _row(f"live sampler CPU s: {stage}", [float(st[stage]) for st in stages
                                                  if stage in st])
    print("\n| CPU s per process | median | min | max |\n|---|---:|---:|---:|")
    for kind, values in cpu_rows(profiles).items():
        _row(kind, values)
    completed = sum(bool(r["completed"]) for r in runs)
    print(f"\ncompleted before the cap: {completed}/{len(runs)}")
    # Lockstep promises the same metrics.json for the same seed, whatever the load.
    same = all({k: v for k, v in r.items() if k != "wall_time_s"}
               == {k: v for k, v in runs[0].items() if k != "wall_time_s"} for r in runs)
    print(f"metrics.json identical apart from wall_time_s: {same}\n")


def _row(name: str, values: list[float]) -> None:
    if values:
        print(f"| {name} | {statistics.median(values):.2f} | {min(values):.2f} | "
              f"{max(values):.2f} |")

if __name__ == "__main__":
    main()
