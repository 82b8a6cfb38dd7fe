"""The agents' A* on the searches of a recorded mission: every robot's replay
(`bench_agent_replay.py`) collects each (traversable grid, start, goal) its navigator searched
and the path it found, then `planning.astar` runs them all again, timed (process CPU, median
of the passes), and must find the paths the replay found.

    .venv/bin/python bench/bench_agent_replay.py record /tmp/agent_rec -- \
        --robots 3 --sim-time 90 --seed 0 --sample-every 0
    .venv/bin/python bench/bench_astar.py /tmp/agent_rec --repeats 3
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_agent_replay as replay_mod  # noqa: E402

from services.common import planning  # noqa: E402
from services.config import load_config  # noqa: E402
from services.robot_agent import navigation as nav_mod  # noqa: E402

Search = tuple[np.ndarray, tuple[int, int], tuple[int, int], np.ndarray | None]


def collect(rec: Path, robot: int) -> list[Search]:
    """Every search robot `robot`'s navigator made in the replay, with the path it got."""
    searches: list[Search] = []
    instrument = replay_mod.instrument

    def capture(core, timer) -> None:  # after the replay's own timers: record, then search
        instrument(core, timer)
        timed = nav_mod.astar

        def astar(trav, start, goal):
            path = timed(trav, start, goal)
            searches.append((trav.copy(), start, goal, path))
            return path

        nav_mod.astar = astar

    replay_mod.instrument = capture
    try:
        replay_mod.replay(rec, robot, None)
    finally:
        replay_mod.instrument = instrument
    return searches


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rec", type=Path)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    robots = load_config(args.rec / "run" / "config.yaml", {}).sim.robots
    searches = [s for robot in range(robots) for s in collect(args.rec, robot)]
    passes, per_search = [], []
    for _ in range(args.repeats):
        t_pass = time.process_time()
        for trav, start, goal, expected in searches:
            t0 = time.process_time()
            path = planning.astar(trav, start, goal)
            per_search.append(time.process_time() - t0)
            same = (path is None and expected is None) or (
                path is not None and expected is not None and np.array_equal(path, expected))
            if not same:
                raise SystemExit(f"A* found another path than the replay: {start} -> {goal}")
        passes.append(time.process_time() - t_pass)
    ms = np.array(per_search) * 1e3
    print(f"{len(searches)} searches of {robots} robots, the same paths found again")
    print(f"CPU s per pass: median {statistics.median(passes):.2f} "
          f"(min {min(passes):.2f}, max {max(passes):.2f}); per search ms: median "
          f"{np.median(ms):.2f}, p90 {np.percentile(ms, 90):.1f}, max {ms.max():.1f}")


if __name__ == "__main__":
    main()
