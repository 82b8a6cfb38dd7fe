"""Edge planner cost on a real mission's messages: replay a recording of
`bench_agent_replay.py record` through `EdgePlanner` offline, timed per stage.

The edge plans at Clock(k) for every k a multiple of `sim.edge_every_ticks` with the messages
stamped before k (node.py), so feeding the recorded submaps, poses and goal statuses in tick
order and planning at each edge tick repeats the mission's plans: `--check` compares the goals
and grids the replay makes with the mission's byte for byte, which shows a speed change left
the results alone. Every agent is taken as alive throughout (true for a normal mission).

    .venv/bin/python bench/bench_agent_replay.py record /tmp/agent_rec -- \
        --robots 3 --sim-time 300 --seed 0 --sample-every 0
    .venv/bin/python bench/bench_edge_replay.py /tmp/agent_rec --check
    .venv/bin/python bench/bench_edge_replay.py /tmp/agent_rec --profile
    # each plan's inputs in another arrival order (a random interleaving of the robots):
    .venv/bin/python bench/bench_edge_replay.py /tmp/agent_rec --check --shuffle 1

It also prints why goals were not kept from one plan to the next (`GoalBook.drops`).
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import random
import statistics
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_agent_replay import LOG, StageTimer, interleave, read_log  # noqa: E402

from schemas import encode  # noqa: E402
from schemas.codec import decode  # noqa: E402
from schemas.keys import Keys  # noqa: E402
from schemas.messages import GoalStatus, Message, RobotPose, Submap  # noqa: E402
from services.common.heap import keep_freed_memory  # noqa: E402
from services.config import load_config  # noqa: E402
from services.edge_server import planner as planner_mod  # noqa: E402
from services.edge_server.node import merges_for  # noqa: E402
from services.edge_server.planner import EdgePlanner  # noqa: E402

INPUTS: dict[str, type[Message]] = {"submap": Submap, "pose": RobotPose,
                                    "goal_status": GoalStatus}


def edge_inputs(keys: Keys, path: Path) -> Iterator[tuple[str, str, bytes]]:
    """(topic, key, payload) of what the edge subscribes to, and of what it published
    (topics "goal" and "grid"), in recorded order."""
    robots = f"{keys.prefix}/robot/"
    grid = keys.map_grid()
    for key, payload in read_log(path):
        if key == grid:
            yield "grid", key, payload
        elif key.startswith(robots):
            topic = key.rsplit("/", 1)[1]
            if topic in INPUTS or topic == "goal":
                yield topic, key, payload


def instrument(planner: EdgePlanner, timer: StageTimer) -> list[float]:
    """Time the plan's stages on this planner instance (and the module functions it calls);
    the list fills with each plan's wall time waiting for a merger's worker."""
    waits: list[float] = []
    if planner.config.merge and planner.merges.concurrent:  # a worker process: its wait
        finish = timer.wrap("merger update (waited for)", planner.merges.finish)

        def waited(*args: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return finish(*args)
            finally:
                waits.append(time.perf_counter() - t0)

        planner.merges.finish = waited
    elif planner.config.merge:
        planner.merger.update = timer.wrap("merger update", planner.merger.update)
    planner.merged.update = timer.wrap("merged map update", planner.merged.update)
    planner.grid.update = timer.wrap("merged grid update", planner.grid.update)
    planner._frontiers = timer.wrap("frontiers (2D or 3D)", planner._frontiers)
    planner.book.plan = timer.wrap("goal book: assignment", planner.book.plan)
    # the goal cells' lookups (frontiers.GoalTransform) run inside the frontier stages
    for name, stage in (("RobotFields", "robot distance fields"),
                        ("detect_spatial_frontiers", "- 3D F_u/F_w regions")):
        setattr(planner_mod, name, timer.wrap(stage, getattr(planner_mod, name)))
    return waits


def replay(rec: Path, limit: int | None, overrides: dict[str, str] | None = None,
           prof: cProfile.Profile | None = None, profile_after: int = 0,
           shuffle: int | None = None, wall_stages: bool = False,
           ) -> tuple[StageTimer, list[float], dict, EdgePlanner]:
    """(timer, CPU s per plan, mismatches per output, the planner) of the whole recording;
    `overrides` (dotted keys) change the mission's config (then --check fails by design).
    `prof` runs from plan `profile_after` on (a large mission's late plans cost the most);
    `shuffle` (a seed) feeds each plan's inputs in a random interleaving of the robots;
    `wall_stages` times the stages in wall seconds instead of CPU seconds."""
    config = load_config(rec / "run" / "config.yaml", overrides or {})
    keys = Keys(config.bus.prefix)
    planner = EdgePlanner(config.edge, config.sim.tick_s, merges_for(config.edge))
    for robot in range(config.sim.robots):
        planner.on_agent(robot, True)
    timer = StageTimer(time.perf_counter if wall_stages else time.process_time)
    waits = instrument(planner, timer)
    every = config.sim.edge_every_ticks
    inbox: list[Message] = []
    expected: dict[str, list[bytes]] = {"goal": [], "grid": []}
    for topic, _key, payload in edge_inputs(keys, rec / LOG):
        if topic in expected:
            expected[topic].append(payload)
        else:
            inbox.append(decode(payload, INPUTS[topic], config.bus.max_array_bytes))
    last = max((m.tick for m in inbox), default=0)  # type: ignore[attr-defined]
    produced: dict[str, list[bytes]] = {"goal": [], "grid": []}
    plan_s: list[float] = []
    wall_s: list[float] = []
    fed = 0
    rng = None if shuffle is None else random.Random(shuffle)
    ordered = sorted(range(len(inbox)), key=lambda i: inbox[i].tick)  # type: ignore[attr-defined]
    for k in range(0, last + 1, every):
        if prof is not None and len(plan_s) == profile_after:
            prof.enable()
        batch = []
        while fed < len(ordered) and inbox[ordered[fed]].tick < k:  # type: ignore[attr-defined]
            batch.append(inbox[ordered[fed]])
            fed += 1
        for msg in interleave(batch, lambda m: m.robot_id, rng):  # type: ignore[attr-defined]
            _feed(planner, msg)
        if not planner.plan_due(k // every):  # edge.plan_every_edge_ticks, as node.py
            planner.skip()
            continue
        t0, w0 = time.process_time(), time.perf_counter()
        out = planner.plan(k)
        plan_s.append(time.process_time() - t0)
        wall_s.append(time.perf_counter() - w0)
        timer.close_tick()
        produced["goal"] += [encode(g) for g in out.goals]
        if out.grid is not None:
            produced["grid"].append(encode(out.grid))
        if limit is not None and len(plan_s) >= limit:
            break
    planner.close()
    print(f"plans' wall time {sum(wall_s):.2f} s, median {1e3 * statistics.median(wall_s):.1f} ms "
          f"(a merger worker's CPU is not in the CPU figures below)")
    if waits:
        print(f"waited for the merger's worker {sum(waits):.2f} s over {len(waits)} plans, "
              f"median {1e3 * statistics.median(waits):.1f} ms, over 5 ms in "
              f"{sum(w > 0.005 for w in waits)}")
    partial = limit is not None
    mismatches = {t: _mismatch(expected[t], produced[t], partial) for t in expected}
    return timer, plan_s, mismatches, planner


def _feed(planner: EdgePlanner, msg: Message) -> None:
    if isinstance(msg, Submap):
        planner.on_submap(msg)
    elif isinstance(msg, RobotPose):
        planner.on_pose(msg)
    elif isinstance(msg, GoalStatus):
        planner.on_goal_status(msg)


def _mismatch(expected: list[bytes], produced: list[bytes], partial: bool) -> str:
    if partial:
        expected = expected[: len(produced)]
    if len(expected) != len(produced):
        return f"{len(produced)} made, the mission published {len(expected)}"
    bad = [i for i, (a, b) in enumerate(zip(expected, produced, strict=True)) if a != b]
    return f"first differs at #{bad[0]} ({len(bad)} differ)" if bad else "identical"


def report(timer: StageTimer, plan_s: list[float]) -> None:
    total = sum(plan_s)
    print(f"{len(plan_s)} plans; CPU {total:.2f} s; median {1e3 * statistics.median(plan_s):.1f}"
          f" ms, p90 {1e3 * sorted(plan_s)[int(0.9 * (len(plan_s) - 1))]:.1f} ms\n")
    print("| stage | total s | share of plans % | median ms |\n|---|---:|---:|---:|")
    names = sorted({n for t in timer.ticks for n in t},
                   key=lambda n: -sum(t.get(n, 0.0) for t in timer.ticks))
    for name in names:
        per = [t[name] for t in timer.ticks if name in t]
        print(f"| {name} | {sum(per):.2f} | {100 * sum(per) / total:.1f} | "
              f"{1e3 * statistics.median(per):.1f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", type=Path)
    parser.add_argument("--check", action="store_true",
                        help="compare goals and grids with the mission's, byte for byte")
    parser.add_argument("--profile", action="store_true", help="cProfile the replay")
    parser.add_argument("--limit", type=int, default=None, help="stop after this many plans")
    parser.add_argument("--profile-after", type=int, default=0, metavar="N",
                        help="with --profile: profile from plan N on")
    parser.add_argument("--shuffle", type=int, default=None, metavar="SEED",
                        help="feed each plan's inputs in a random interleaving of the robots "
                        "(with --check: does arrival order matter?)")
    parser.add_argument("--wall-stages", action="store_true",
                        help="the stage table in wall seconds (a stage on several threads, or "
                        "waiting for the merger's worker), not CPU seconds")
    parser.add_argument("--return-freed", action="store_true",
                        help="leave glibc's default of unmapping large freed arrays (the edge "
                        "keeps them: services/common/heap.py)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="change the mission's config (e.g. edge.retarget_goals=true)")
    args = parser.parse_args()
    if not args.return_freed:
        keep_freed_memory()  # as the edge does
    prof = cProfile.Profile() if args.profile else None
    timer, plan_s, mismatches, planner = replay(args.recording, args.limit,
                                                dict(s.split("=", 1) for s in args.set),
                                                prof, args.profile_after, args.shuffle,
                                                args.wall_stages)
    if prof is not None:
        prof.disable()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(30)
        pstats.Stats(prof).sort_stats("tottime").print_stats(25)
    if args.wall_stages:
        print("stages below in wall seconds (their shares are of the plans' CPU seconds)")
    report(timer, plan_s)
    print("\ngoals not kept: " + (", ".join(f"{why} {n}" for why, n in
                                            planner.book.drops.most_common()) or "none"))
    if args.check:
        print("\noutputs against the mission: " + ", ".join(
            f"{t} {v}" for t, v in mismatches.items()))
        if any(v != "identical" for v in mismatches.values()):
            sys.exit(1)


if __name__ == "__main__":
    main()
