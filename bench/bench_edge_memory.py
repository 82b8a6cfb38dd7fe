"""Where the edge's memory goes: replay a recording of `bench_agent_replay.py record` through
`EdgePlanner` (as bench_edge_replay.py does) and, every N plans, print the process's resident
memory and the bytes of the numpy arrays each part of the planner holds.

    .venv/bin/python bench/bench_edge_memory.py /tmp/agent_rec --every 20

Arrays are counted once each (a view counts its base) and reached through attributes, dicts,
lists, tuples, sets and dataclasses; small_gicp clouds count 160 bytes a point (a point and
its 4 × 4 covariance in doubles), their k-d trees are not counted. "RSS growth" is the
resident size less the size once the recording was decoded (the messages stay in memory).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
import small_gicp  # noqa: E402
from bench_agent_replay import LOG  # noqa: E402
from bench_edge_replay import INPUTS, _feed, edge_inputs  # noqa: E402

from schemas.codec import decode  # noqa: E402
from schemas.keys import Keys  # noqa: E402
from services.common.heap import keep_freed_memory  # noqa: E402
from services.config import load_config  # noqa: E402
from services.edge_server.planner import EdgePlanner  # noqa: E402

CLOUD_POINT_BYTES = 160


def rss_bytes() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    return 0


def _children(obj: object) -> Iterator[object]:
    if isinstance(obj, dict):
        yield from obj.keys()
        yield from obj.values()
    elif isinstance(obj, (list, tuple, set, frozenset)):
        yield from obj
    else:
        yield from getattr(obj, "__dict__", {}).values()
        for name in getattr(type(obj), "__slots__", ()):
            if hasattr(obj, name):
                yield getattr(obj, name)


def array_bytes(root: object, seen: set[int]) -> int:
    """Bytes of the arrays (and small_gicp clouds) reachable from `root` not yet in `seen`."""
    total, stack = 0, [root]
    while stack:
        obj = stack.pop()
        if id(obj) in seen or isinstance(obj, (str, bytes, int, float, bool, type(None))):
            continue
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            base = obj
            while isinstance(base.base, np.ndarray):
                base = base.base
            if base is obj or id(base) not in seen:
                seen.add(id(base))
                total += base.nbytes
        elif isinstance(obj, small_gicp.PointCloud):
            total += CLOUD_POINT_BYTES * obj.size()
        elif not callable(obj) or hasattr(obj, "__dict__"):
            stack.extend(_children(obj))
    return total


def parts(obj: object) -> dict[str, int]:
    """Array bytes per attribute of `obj`, largest first (shared arrays go to the first)."""
    seen: set[int] = set()
    sizes = {name: array_bytes(value, seen) for name, value in vars(obj).items()}
    return dict(sorted(sizes.items(), key=lambda kv: -kv[1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", type=Path)
    parser.add_argument("--every", type=int, default=20, help="report every N plans")
    parser.add_argument("--top", type=int, default=8, help="planner parts to show")
    parser.add_argument("--detail", type=int, default=4,
                        help="at the end, break the largest N parts down by attribute")
    args = parser.parse_args()
    keep_freed_memory()  # as the edge does
    config = load_config(args.recording / "run" / "config.yaml")
    planner = EdgePlanner(config.edge, config.sim.tick_s)
    for robot in range(config.sim.robots):
        planner.on_agent(robot, True)
    inbox = [decode(payload, INPUTS[topic], config.bus.max_array_bytes)
             for topic, _key, payload in edge_inputs(Keys(config.bus.prefix),
                                                     args.recording / LOG)
             if topic in INPUTS]
    inbox.sort(key=lambda m: m.tick)  # type: ignore[attr-defined]
    rss0 = rss_bytes()
    print(f"{len(inbox)} messages decoded; RSS {rss0 / 2**20:.0f} MiB\n")
    print("| plan | sim s | RSS growth MiB | planner arrays MiB | largest parts MiB |")
    print("|---:|---:|---:|---:|---|")
    every, fed, n = config.sim.edge_every_ticks, 0, 0
    t0 = time.monotonic()
    for k in range(0, inbox[-1].tick + 1, every):  # type: ignore[attr-defined]
        while fed < len(inbox) and inbox[fed].tick < k:  # type: ignore[attr-defined]
            _feed(planner, inbox[fed])
            fed += 1
        planner.plan(k)
        n += 1
        if n % args.every == 0 or fed == len(inbox):
            sizes = parts(planner)
            top = ", ".join(f"{name} {b / 2**20:.0f}" for name, b in
                            list(sizes.items())[: args.top])
            print(f"| {n} | {k * config.sim.tick_s:.0f} | {(rss_bytes() - rss0) / 2**20:.0f} | "
                  f"{sum(sizes.values()) / 2**20:.0f} | {top} |", flush=True)
    print(f"\n{n} plans in {time.monotonic() - t0:.0f} s wall")
    for name in list(parts(planner))[: args.detail]:
        inner = ", ".join(f"{a} {b / 2**20:.0f}" for a, b in
                          list(parts(getattr(planner, name)).items())[: args.top] if b >= 2**20)
        print(f"{name}: {inner}")


if __name__ == "__main__":
    main()
