"""Whole-mission wall time: `spacemap run` repeated, medians of wall time and key metrics,
and where the CPU went (each run's profile.json: CPU seconds per process).

    .venv/bin/python bench/bench_mission.py --robots 3 --sim-time 120 --repeats 3
    .venv/bin/python bench/bench_mission.py --sim-time 300 --sample-every 0 \
        --set sim.edge_pipeline_ticks=5
    .venv/bin/python bench/bench_mission.py --robots 3 --sim-time 120 --repeats 3 --tls both

`--tls both` alternates runs with mutual TLS (the default) and plain TCP (`bus.tls=false`),
in the order TLS, TCP, TCP, TLS, ... so that a load drift on a shared machine hits both
alike, and prints a table for each. `--baseline DIR` does the same between the code of
another checkout (say `git worktree add /tmp/before HEAD~1`) and this one, with this
interpreter, for a speed change that must leave every result alone:

    .venv/bin/python bench/bench_mission.py --robots 3 --sim-time 1 --repeats 8 \
        --baseline /tmp/before
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def run_once(out: Path, args: list[str], code: Path = REPO) -> tuple[dict, dict]:
    """(metrics.json, profile.json) of one `spacemap run` of the checkout at `code`."""
    cmd = [sys.executable, "-m", "services", "run", "--out", str(out), *args]
    subprocess.run(cmd, cwd=code, check=True, capture_output=True)
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
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another checkout: alternate its runs with this one's (ABBA)")
    opts = parser.parse_args()
    if opts.baseline is not None and opts.tls == "both":
        parser.error("--baseline and --tls both each compare two settings: choose one")
    args = ["--robots", str(opts.robots), "--sim-time", str(opts.sim_time),
            "--world", opts.world, "--seed", str(opts.seed)]
    if opts.sample_every is not None:
        args += ["--sample-every", str(opts.sample_every)]
    for item in opts.set:
        args += ["--set", item]
    variants = _variants(opts.tls, opts.baseline)
    results: dict[str, tuple[list[dict], list[dict]]] = {v.label: ([], []) for v in variants}
    with tempfile.TemporaryDirectory() as tmp:
        root = opts.keep or Path(tmp)
        for i in range(opts.repeats):
            for v in variants if i % 2 == 0 else variants[::-1]:  # ABBA: fair to a load drift
                metrics, profile = run_once(root / f"run{i}{v.suffix}", args + v.extra, v.code)
                results[v.label][0].append(metrics)
                results[v.label][1].append(profile)
    for label, (runs, profiles) in results.items():
        print(f"## {label}\n\nspacemap run {' '.join(args)}; {opts.repeats} runs, medians\n")
        report(runs, profiles)
    if len(results) == 2:
        (a, (runs_a, prof_a)), (b, (runs_b, prof_b)) = results.items()
        rtf_a, rtf_b = (statistics.median(float(p["real_time_factor"]) for p in prof)
                        for prof in (prof_a, prof_b))
        wall_a, wall_b = (statistics.median(float(p["wall_time_s"]) for p in prof)
                          for prof in (prof_a, prof_b))
        print(f"real-time factor, {a} / {b} (medians): {rtf_a / rtf_b:.3f}; wall time s "
              f"{wall_a:.2f} against {wall_b:.2f}")
        same = all(_no_wall(x) == _no_wall(y) for x, y in zip(runs_a, runs_b, strict=True))
        print(f"metrics.json of each {a} run equal to its {b} run's: {same}")


@dataclass(frozen=True)
class Variant:
    label: str
    code: Path  # the checkout that runs
    extra: list[str]  # more `spacemap run` arguments
    suffix: str  # of the run folders


def _variants(tls: str, baseline: Path | None) -> list[Variant]:
    if baseline is not None:
        return [Variant(f"this checkout ({REPO})", REPO, [], ""),
                Variant(f"baseline ({baseline})", baseline.resolve(), [], "-baseline")]
    on = Variant("mutual TLS", REPO, [], "")
    off = Variant("plain TCP (bus.tls=false)", REPO, ["--set", "bus.tls=false"], "-tcp")
    return {"on": [on], "off": [off], "both": [on, off]}[tls]


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
