"""The merger's back-to-back gate on a real mission: replay an edge recording (see
bench_edge_replay.py) and count what `registration.opposed_fraction` costs: its calls and CPU
seconds, and the covariance rows `flat_normals` eigen-decomposed for it.

    .venv/bin/python bench/bench_agent_replay.py record /tmp/rec -- --robots 3 --seed 0 \
        --sample-every 0 --world ../shared/worlds/aws_small_house/small_house.xml --sim-time 500
    .venv/bin/python bench/bench_opposed.py /tmp/rec [--limit PLANS]

Run it from another checkout's root (`git worktree add /tmp/before REV`, then
`cd /tmp/before && /work/main/.venv/bin/python /work/main/bench/bench_opposed.py /tmp/rec`)
for the figures before a change: it wraps the module functions of the code it imports.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, os.getcwd())  # the checkout being measured
sys.path.insert(1, str(Path(__file__).resolve().parent))

from bench_edge_replay import replay  # noqa: E402

from services.common import registration  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", type=Path)
    parser.add_argument("--limit", type=int, default=None, help="stop after this many plans")
    args = parser.parse_args()
    rows, gate = [0, 0], [0.0, 0]
    flat_normals, opposed_fraction = registration.flat_normals, registration.opposed_fraction

    def counted(covs, points, viewpoint):  # type: ignore[no-untyped-def]
        rows[0] += len(covs)
        rows[1] += 1
        return flat_normals(covs, points, viewpoint)

    def timed(*args, **kwargs):  # type: ignore[no-untyped-def]
        t0 = time.process_time()
        out = opposed_fraction(*args, **kwargs)
        gate[0] += time.process_time() - t0
        gate[1] += 1
        return out

    registration.flat_normals = counted  # looked up as module globals: both are caught
    registration.opposed_fraction = timed
    replay(args.recording, args.limit)
    print(f"opposed_fraction: {gate[1]} calls, {gate[0]:.2f} CPU s; flat_normals: {rows[1]} "
          f"calls, {rows[0]} rows")


if __name__ == "__main__":
    main()
