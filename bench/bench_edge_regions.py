"""Which regions the edge could have given, and what each robot was offered: replay a
recording's plans (`bench_edge_replay.py`) and print, for every plan in a time window, the
usable regions of at least --min-voxels voxels with the revenue each robot needing a goal was
offered for them, and what each robot got.

    .venv/bin/python bench/bench_agent_replay.py record /tmp/agent_rec -- \\
        --world ../shared/worlds/aws_small_house/small_house.xml --robots 3 --seed 1 \\
        --sim-time 500 --sample-every 0
    .venv/bin/python bench/bench_edge_regions.py /tmp/agent_rec --from 37 --to 50 \\
        --min-voxels 500

The replay repeats the mission's plans (`bench_edge_replay.py --check`), so what it prints is
what the mission's edge saw. `--set KEY=VALUE` replays with another config (then the plans
are the open-loop answer to the same robots' paths, not another mission).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_edge_replay as edge_replay  # noqa: E402


def capture(plans: list[dict]) -> None:
    """Make the replay keep each plan's regions, usable mask, revenues and assignment."""
    instrument = edge_replay.instrument

    def keep(planner, timer) -> None:
        instrument(planner, timer)
        plan = planner.book.plan

        def kept_plan(tick, robots, fields, fs, spec, scorer, poses):
            usable = planner.book.allowed(fs, tick) & fields.reachable[fs.goal_rc[:, 0],
                                                                       fs.goal_rc[:, 1]]
            offered: dict[str, np.ndarray] = {}
            score = scorer.score

            def kept_score(*args, **kwargs):
                offered["scores"] = score(*args, **kwargs)
                return offered["scores"]

            scorer.score = kept_score
            try:
                result = plan(tick, robots, fields, fs, spec, scorer, poses)
            finally:
                scorer.score = score
            plans.append({"tick": tick, "robots": list(robots), "poses": np.array(poses),
                          "goal_xy": fs.goal_xy.copy(), "sizes": fs.sizes.copy(),
                          "usable": usable, "scores": offered.get("scores"),
                          "assigned": dict(result.assigned)})
            return result

        planner.book.plan = kept_plan

    edge_replay.instrument = keep


def show(plan: dict, tick_s: float, min_voxels: int) -> None:
    g, scores = plan["goal_xy"], plan["scores"]
    robots = " ".join(f"r{r} ({x:.1f}, {y:.1f})" for r, (x, y, _) in
                      zip(plan["robots"], plan["poses"], strict=True))
    got = ", ".join(f"r{r} → ({g[f, 0]:.1f}, {g[f, 1]:.1f}) {plan['sizes'][f]} vox"
                    for r, f in sorted(plan["assigned"].items()))
    print(f"t {plan['tick'] * tick_s:.1f} s: {robots}; {got or 'nothing assigned'}")
    for f in np.flatnonzero(plan["usable"] & (plan["sizes"] >= min_voxels)):
        offers = "" if scores is None else " ".join(
            f"r{r} {scores[i, f]:.3f}" for i, r in enumerate(plan["robots"])
            if np.isfinite(scores[i, f]))
        print(f"    region at ({g[f, 0]:.1f}, {g[f, 1]:.1f}) m, {plan['sizes'][f]} voxels; "
              f"offered: {offers or '-'}")
    if scores is not None:
        for i, r in enumerate(plan["robots"]):
            if r in plan["assigned"] and np.isfinite(scores[i]).any():
                f = plan["assigned"][r]
                print(f"    r{r} took {scores[i, f]:.3f} ({plan['sizes'][f]} voxels)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("recording", type=Path)
    ap.add_argument("--from", dest="t0", type=float, default=0.0, help="sim s")
    ap.add_argument("--to", dest="t1", type=float, default=float("inf"), help="sim s")
    ap.add_argument("--min-voxels", type=int, default=0)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    plans: list[dict] = []
    capture(plans)
    _, _, mismatches, planner = edge_replay.replay(
        args.recording, None, dict(s.split("=", 1) for s in args.set))
    for plan in plans:
        if args.t0 <= plan["tick"] * planner.tick_s <= args.t1:
            show(plan, planner.tick_s, args.min_voxels)
    print("outputs against the mission: " + ", ".join(f"{t} {v}" for t, v in mismatches.items()))


if __name__ == "__main__":
    main()
