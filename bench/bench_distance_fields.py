"""The edge's Dijkstra distance fields on a recorded mission's grids: the edge is replayed
(`bench_edge_replay.py`) and every `planning.distance_fields` call it makes (the goal book's
robot fields, the tours' coarse fields) is captured, then run again, timed (process CPU,
median of the repeats per call), two ways: `planning.distance_fields` (the compiled bucket
queue, `grid_search`) and `planning.scipy_distance_fields` (scipy's Dijkstra on the move
graph built as CSR, what the planner ran before). The two must give the same fields to the
last bit.

    .venv/bin/python bench/bench_agent_replay.py record /tmp/rec_w -- --world warehouse \
        --robots 24 --sim-time 60 --seed 0 --sample-every 0
    .venv/bin/python bench/bench_distance_fields.py /tmp/rec_w --limit 40
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from bench_edge_replay import replay  # noqa: E402

from services.common import planning  # noqa: E402
from services.edge_server import robot_fields, tours  # noqa: E402

Call = tuple[np.ndarray, list[tuple[int, int]]]


def capture(rec: Path, limit: int | None) -> list[Call]:
    """(traversable, starts) of every distance_fields call the edge's replay makes."""
    calls: list[Call] = []
    original = planning.distance_fields

    def recording(traversable: np.ndarray, starts_rc: list[tuple[int, int]]) -> np.ndarray:
        calls.append((np.array(traversable, dtype=bool), list(starts_rc)))
        return original(traversable, starts_rc)

    robot_fields.distance_fields = tours.distance_fields = recording
    try:
        replay(rec, limit)
    finally:
        robot_fields.distance_fields = tours.distance_fields = original
    return calls


def timed(fn, call: Call, repeats: int) -> tuple[float, np.ndarray]:
    times, result = [], None
    for _ in range(repeats):
        t0 = time.process_time()
        result = fn(*call)
        times.append(time.process_time() - t0)
    return statistics.median(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", type=Path)
    parser.add_argument("--limit", type=int, default=None, help="replay this many plans")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    calls = capture(args.recording, args.limit)
    if not calls:
        sys.exit("the replay made no distance_fields call")
    planning.distance_fields(*calls[0])  # load the compiled search once, untimed
    rows = []
    for call in calls:
        new_s, new = timed(planning.distance_fields, call, args.repeats)
        ref_s, ref = timed(planning.scipy_distance_fields, call, args.repeats)
        if not np.array_equal(new, ref):
            sys.exit(f"fields differ on a {call[0].shape} grid with {len(call[1])} starts")
        rows.append((call[0].size, len(call[1]), ref_s, new_s))
    cells, starts, ref_s, new_s = (np.array(c, float) for c in zip(*rows, strict=True))
    print(f"{len(rows)} calls over {args.limit or 'all'} plans, fields identical; grid cells "
          f"median {int(np.median(cells))} (max {int(cells.max())}), starts per call median "
          f"{np.median(starts):.0f} (max {int(starts.max())})\n")
    print("| search | total CPU s | per call median ms | per call max ms |\n|---|---:|---:|---:|")
    for name, s in (("scipy, CSR graph (reference)", ref_s),
                    ("compiled buckets (planning)", new_s)):
        print(f"| {name} | {s.sum():.2f} | {1e3 * np.median(s):.1f} | {1e3 * s.max():.1f} |")


if __name__ == "__main__":
    main()
