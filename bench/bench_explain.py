"""Where the robots' time went over many runs: `spacemap eval --explain` summed over run folders.

For each run folder under DIR (any depth, one with events.jsonl), the robots' seconds by goal
outcome and by navigation state, optionally only after the 3D coverage first reached
`--from-coverage` % (the tail: runs that never reached it are left out and counted). Prints
means per run over the runs kept, the window's mean length, and the share of goals replaced.

    .venv/bin/python bench/bench_explain.py RUNS_DIR [--from-coverage 95] [--glob 'aws_*']
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from services.evaluator import run_files as rf  # noqa: E402
from services.evaluator.evaluate import RunConfig, load_tracks  # noqa: E402
from services.evaluator.explain import OUTCOMES, coverage_tick, explain_events  # noqa: E402


def summarize(run: Path, from_pct: float | None) -> tuple[float, Counter, Counter, Counter] | None:
    """(window s, robot-s by outcome, robot-s by state, goals by outcome) of one run; None
    when its coverage never reached `from_pct`."""
    config = RunConfig.read(run / "config.yaml")
    tick_s = config.sim.tick_s
    end = round(float(rf.read_json(run / rf.LIVE)["sim_time_s"]) / tick_s)
    start = 0
    if from_pct is not None:
        start = coverage_tick(rf.read_csv(run / rf.TIMESERIES), from_pct, tick_s)
        if start is None:
            return None
        start = min(start, end)
    per_robot = explain_events(rf.read_events(run / rf.EVENTS),
                               load_tracks(run, config.sim.robots), end, tick_s, start)
    time, states, goals = Counter(), Counter(), Counter()
    for r in per_robot.values():
        time.update(r.time_s)
        states.update(r.state_time_s)
        goals.update(r.goals)
    return (end - start) * tick_s, time, states, goals


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path)
    ap.add_argument("--from-coverage", type=float, default=None)
    ap.add_argument("--glob", default="*", help="run folder names to take (default all)")
    args = ap.parse_args()
    runs = sorted(p.parent for p in args.runs.rglob(rf.EVENTS) if p.parent.match(args.glob))
    if not runs:
        sys.exit(f"no run folder with {rf.EVENTS} under {args.runs}")
    kept, window, time, states, goals = 0, 0.0, Counter(), Counter(), Counter()
    for run in runs:
        out = summarize(run, args.from_coverage)
        if out is None:
            continue
        kept += 1
        window += out[0]
        time.update(out[1])
        states.update(out[2])
        goals.update(out[3])
    where = ("the whole mission" if args.from_coverage is None
             else f"after 3D coverage first reached {args.from_coverage:g} %")
    print(f"{kept} of {len(runs)} runs, {where}: window {window / max(kept, 1):.1f} s per run")
    if not kept:
        return
    print("robot-seconds per run by goal outcome: " + ", ".join(
        f"{k} {time[k] / kept:.1f}" for k in (*OUTCOMES, "no goal") if time[k]))
    print("robot-seconds per run by state: " + ", ".join(
        f"{k} {v / kept:.1f}" for k, v in sorted(states.items())))
    total = sum(goals.values())
    print(f"goals per run {total / kept:.1f}: " + ", ".join(
        f"{k} {goals[k] / kept:.1f}" for k in OUTCOMES if goals[k])
        + f" (replaced {100.0 * goals['replaced'] / max(total, 1):.0f} %)")


if __name__ == "__main__":
    main()
