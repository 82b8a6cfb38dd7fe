"""Which registrations does PCM keep, against the truth? At the end of a recorded mission.

Replays the edge of a `bench_agent_replay.py record` folder exactly as the mission ran
(`bench_edge_replay.replay`), then takes every registration the merger kept (converged and
through the gates) and asks `consistency.select` which it keeps for each `min_clique`, with
the recording's own PCM tolerances. A registration is correct when its relative pose is
within `--bad-cm` of the submaps' ground-truth relative pose (`bench_merger_replay.truth_of`).
Also prints how many robot pairs hold a single registration: PCM per robot pair cannot judge
those, and with `min_clique` 2 they wait; and how many registrations close a consistent cycle
with two others through a third robot (group-3 consistency, Forsgren et al. 2022, with PCM's
tolerances over the three chains), which could judge them.

    .venv/bin/python bench/bench_pcm.py /tmp/rec_wh0_130 [/tmp/rec_aws3 ...]
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import Counter
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_edge_replay  # noqa: E402
import numpy as np  # noqa: E402
from bench_merger_replay import submaps_of, truth_of  # noqa: E402
from gtsam import Pose3  # noqa: E402

from schemas.keys import Keys  # noqa: E402
from services.common.geometry import invert  # noqa: E402
from services.common.pose_graph import Between  # noqa: E402
from services.config import load_config  # noqa: E402
from services.edge_server import merger as merger_mod  # noqa: E402
from services.edge_server.consistency import select  # noqa: E402
from services.edge_server.merger import merger_params  # noqa: E402

# ruff: noqa: N806 (T_a_b names)


def final_merger(rec: Path) -> tuple[merger_mod.MapMerger, dict]:
    """The merger and the stored submaps' reported poses after the recording's last plan."""
    held: dict = {}
    update = merger_mod.MapMerger.update

    def keep(self: merger_mod.MapMerger, store):  # noqa: ANN001, ANN202
        held["merger"], held["store"] = self, store
        return update(self, store)

    merger_mod.MapMerger.update = keep  # type: ignore[method-assign]
    try:
        bench_edge_replay.replay(rec, None)
    finally:
        merger_mod.MapMerger.update = update  # type: ignore[method-assign]
    reported = {k: sm.T_reported for k, sm in held["store"].submaps.items()}
    return held["merger"], reported


def _toward(e: Between, x: tuple) -> np.ndarray:
    """The edge's transform read from submap x to the other end."""
    return e.T_a_b if e.a == x else invert(e.T_a_b)


def in_cycle(i: int, edges: list[Between], by_pair: dict, reported: dict, params) -> bool:  # noqa: ANN001
    """Whether edge i closes a consistent loop with an edge b–c and an edge c–a of some
    third robot c, through the three robots' reported chains."""
    e1 = edges[i]
    a, b = e1.a, e1.b
    for c in sorted({r for pair in by_pair for r in pair} - {a[0], b[0]}):
        for j in by_pair.get(tuple(sorted((b[0], c))), []):
            b2 = edges[j].a if edges[j].a[0] == b[0] else edges[j].b
            c2 = edges[j].b if b2 == edges[j].a else edges[j].a
            for k in by_pair.get(tuple(sorted((c, a[0]))), []):
                c3 = edges[k].a if edges[k].a[0] == c else edges[k].b
                a3 = edges[k].b if c3 == edges[k].a else edges[k].a
                ends = ((b, b2), (c2, c3), (a3, a))
                chains = [invert(reported[x]) @ reported[y] for x, y in ends]
                loop = (_toward(e1, a) @ chains[0] @ _toward(edges[j], b2) @ chains[1]
                        @ _toward(edges[k], c3) @ chains[2])
                xi = Pose3.Logmap(Pose3(loop))
                span = sum(float(np.linalg.norm(T[:3, 3])) for T in chains)
                if (np.linalg.norm(xi[3:]) <= params.tol_m + params.tol_m_per_m * span
                        and np.linalg.norm(xi[:3]) <= params.tol_rad + params.tol_rad_per_m * span):
                    return True
    return False


def study(rec: Path, bad_m: float, cliques: list[int]) -> None:
    config = load_config(rec / "run" / "config.yaml", {})
    msgs = submaps_of(rec, Keys(config.bus.prefix), config.bus.max_array_bytes)
    truth, _ = truth_of(msgs, rec / "run", config.sim.tick_s, config.agent.submap_every_ticks)
    merger, reported = final_merger(rec)
    edges = [e for e in merger.registrations.values() if e is not None]
    err = np.array([float(np.hypot(*(invert(invert(truth[e.a]) @ truth[e.b]) @ e.T_a_b)[:2, 3]))
                    for e in edges])
    bad = err > bad_m
    pairs = Counter(tuple(sorted((e.a[0], e.b[0]))) for e in edges)
    lone = sum(n == 1 for n in pairs.values())
    print(f"\n{rec}: {config.sim.robots} robots, {len(edges)} registrations kept by the gates "
          f"({bad.sum()} more than {100 * bad_m:.0f} cm off), {len(pairs)} robot pairs, "
          f"{lone} of them with a single registration")
    print("| PCM | kept | correct kept | wrong kept |\n|---|---:|---:|---:|")
    robot_of = {k: (k[0], 0) for k in reported}
    base = merger_params(config.edge).consistency
    assert base is not None
    for m in cliques:
        keep = np.array(select(edges, reported, robot_of, replace(base, min_clique=m)))
        print(f"| min clique {m} | {keep.sum()} | {(keep & ~bad).sum()} of {(~bad).sum()} | "
              f"{(keep & bad).sum()} of {bad.sum()} |")
    by_pair: dict = {}
    for i, e in enumerate(edges):
        by_pair.setdefault(tuple(sorted((e.a[0], e.b[0]))), []).append(i)
    cycle = np.array([in_cycle(i, edges, by_pair, reported, base) for i in range(len(edges))])
    print(f"| in a consistent 3-robot cycle | {cycle.sum()} | {(cycle & ~bad).sum()} of "
          f"{(~bad).sum()} | {(cycle & bad).sum()} of {bad.sum()} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recordings", type=Path, nargs="+")
    parser.add_argument("--bad-cm", type=float, default=5.0)
    parser.add_argument("--min-clique", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    for rec in args.recordings:
        study(rec, args.bad_cm / 100, args.min_clique)


if __name__ == "__main__":
    main()
