"""The observation table's cost per correction (`observations.py`) at a given table size.

A synthetic mission: `--rows` observations already held, then `--plans` plans that each add
`--new` rows (new submap voxels) and move `--moved` parts (a merger correction: their rows
dropped and added again under new keys), then judge the first observers. Prints the CPU
seconds per plan of `first_observers` (merging the new rows, judging the touched keys) and of
`drop`. `--fold-share` sets `observations.FOLD_SHARE` (0: every merge goes into the main
run, as before the two runs).

    .venv/bin/python bench/bench_observations.py --rows 16000000 --new 100000 --plans 20
    .venv/bin/python bench/bench_observations.py --rows 2000000 --new 20000 --fold-share 0
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from services.edge_server import observations
from services.edge_server.observations import ObservationTable

PART_ROWS = 5000  # rows per part (a submap's voxels)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--new", type=int, default=20_000, help="rows added per plan")
    ap.add_argument("--moved", type=int, default=2, help="parts moved per plan")
    ap.add_argument("--plans", type=int, default=20)
    ap.add_argument("--fold-share", type=float, default=getattr(observations, "FOLD_SHARE", 0.0))
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    observations.FOLD_SHARE = args.fold_share
    rng = np.random.default_rng(args.seed)
    key_span = args.rows // 6  # about six observations per voxel, as in the missions
    table = ObservationTable()
    parts: dict[int, np.ndarray] = {}

    def add_part(uid: int, n: int, tick: int) -> None:
        keys = rng.integers(0, key_span, n).astype(np.int64)
        table.add(keys, np.full(n, tick), np.full(n, uid % 24), np.full(n, uid),
                  np.arange(n))
        parts[uid] = keys

    for uid in range(args.rows // PART_ROWS):
        add_part(uid, PART_ROWS, uid // 24)
    submap_of = np.arange(args.rows // PART_ROWS + args.plans * (args.new // PART_ROWS + 1))
    table.first_observers(submap_of)
    table.compact()
    judge, drop = [], []
    uid = len(parts)
    for plan in range(args.plans):
        for _ in range(max(1, args.new // PART_ROWS)):
            add_part(uid, PART_ROWS, 1000 + plan)
            uid += 1
        moved = {int(u): parts[int(u)] for u in rng.choice(len(parts), args.moved, replace=False)}
        t = time.process_time()
        table.drop(moved)
        drop.append(time.process_time() - t)
        for u, keys in moved.items():  # the same rows under shifted keys
            table.add(np.minimum(keys + 1, key_span - 1), np.full(keys.size, 1000 + plan),
                      np.full(keys.size, u % 24), np.full(keys.size, u), np.arange(keys.size))
        t = time.process_time()
        table.first_observers(submap_of)
        judge.append(time.process_time() - t)
    print("| rows | new per plan | fold share | first_observers ms (median, max) | drop ms |")
    print("|---:|---:|---:|---|---:|")
    print(f"| {args.rows} | {args.new} | {args.fold_share} | {statistics.median(judge) * 1e3:.1f}, "
          f"{max(judge) * 1e3:.1f} | {statistics.median(drop) * 1e3:.1f} |")


if __name__ == "__main__":
    main()
