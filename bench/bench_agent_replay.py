"""Robot agent cost on a real mission's messages: record every agent's bus inputs and outputs
once, then replay one robot's inputs through `AgentCore` offline, timed per stage.

The replay follows `node.handle` (teammate poses, goals, grids and corrections applied from the
tick after the one they were stamped with), so with an unchanged agent its outputs are the
mission's byte for byte: `--check` compares them, which shows a speed change left the results
alone. The edge is taken as alive throughout (true for a normal mission).

    # record (runs its own router and `spacemap run --connect` on it; ~2.5 min, ~0.8 GB):
    .venv/bin/python bench/bench_agent_replay.py record /tmp/agent_rec -- \
        --robots 3 --sim-time 300 --seed 0 --sample-every 0
    # replay robot 0, per-stage medians, outputs checked against the mission's:
    .venv/bin/python bench/bench_agent_replay.py replay /tmp/agent_rec --robot 0 --check
    # the same with each tick's teammate poses and edge messages in another arrival order
    # (a random interleaving of their senders): outputs that differ depend on arrival order
    .venv/bin/python bench/bench_agent_replay.py replay /tmp/agent_rec --robot 0 --check \
        --shuffle 1
    # the node's tick order at its most extreme: each tick's mapping left queued for as long
    # as the ticks after it may run ahead of it (AgentCore._runs_ahead); outputs must not move
    .venv/bin/python bench/bench_agent_replay.py replay /tmp/agent_rec --robot 0 --check \
        --run-ahead
    # the same under cProfile (top functions by cumulative and own time):
    .venv/bin/python bench/bench_agent_replay.py replay /tmp/agent_rec --robot 0 --profile
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import random
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from schemas import encode  # noqa: E402
from schemas.codec import decode  # noqa: E402
from schemas.keys import Keys  # noqa: E402
from schemas.messages import (  # noqa: E402
    Correction,
    Goal,
    Message,
    OccupancyGrid,
    Odometry,
    RgbdFrame,
    RobotPose,
)
from services.common.bus import BusConfig, connect  # noqa: E402
from services.common.geometry import wrap_angle  # noqa: E402
from services.config import load_config  # noqa: E402
from services.processes import free_tcp_port  # noqa: E402
from services.robot_agent import agent as agent_mod  # noqa: E402
from services.robot_agent import navigation as nav_mod  # noqa: E402
from services.robot_agent.agent import AgentCore  # noqa: E402
from services.robot_agent.local_grid import LocalGrid  # noqa: E402
from services.robot_agent.node import TICKED, _apply, defers  # noqa: E402

_GRID_UPDATE = LocalGrid.update  # unwrapped, so instrumenting twice does not nest timers
_NAV = {name: getattr(nav_mod, name) for name in ("plan_path", "astar", "path_blocked",
                                                  "traversable_of")}
REPO = Path(__file__).resolve().parents[1]
LOG = "messages.bin"
_HEAD = struct.Struct("<HI")  # key length, payload length
INPUTS = {"rgbd": RgbdFrame, "odom": Odometry, "goal": Goal, "correction": Correction}
OUTPUTS = ("pose", "submap", "goal_status", "cmd_vel")


# -- record ---------------------------------------------------------------------------------
def record(out: Path, run_args: list[str]) -> None:
    """Run a mission on a router of our own and log every robot/** and map/grid payload."""
    out.mkdir(parents=True, exist_ok=True)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    py = [sys.executable, "-m", "services"]
    router = subprocess.Popen([*py, "router", "--listen", endpoint], cwd=REPO)
    lock = threading.Lock()
    try:
        time.sleep(1.0)
        with open(out / LOG, "wb") as f, connect(BusConfig(connect=endpoint)) as bus:
            def write(key: str, payload: bytes) -> None:
                k = key.encode()
                with lock:
                    f.write(_HEAD.pack(len(k), len(payload)) + k + payload)

            bus.tap(f"{bus.keys.prefix}/robot/**", write)
            bus.tap(bus.keys.map_grid(), write)
            bus.tap(bus.keys.map_frontiers(), write)  # for studies of the plans' regions
            subprocess.run([*py, "run", "--connect", endpoint, "--out", str(out / "run"),
                            *run_args], cwd=REPO, check=True)
            time.sleep(1.0)
    finally:
        router.terminate()
        router.wait()


def read_log(path: Path) -> Iterator[tuple[str, bytes]]:
    with open(path, "rb") as f:
        while head := f.read(_HEAD.size):
            nk, npl = _HEAD.unpack(head)
            yield f.read(nk).decode(), f.read(npl)


# -- replay ---------------------------------------------------------------------------------
class StageTimer:
    """CPU seconds of wrapped callables, summed per stage within one tick (process time: on a
    shared machine wall time measures the neighbours too); `clock=time.perf_counter` for wall
    seconds (a stage that waits, or runs on several threads)."""

    def __init__(self, clock: Callable[[], float] = time.process_time) -> None:
        self.clock = clock
        self.tick: dict[str, float] = {}
        self.ticks: list[dict[str, float]] = []

    def wrap(self, name: str, fn: Callable) -> Callable:
        def timed(*args, **kwargs):
            t0 = self.clock()
            try:
                return fn(*args, **kwargs)
            finally:
                self.tick[name] = self.tick.get(name, 0.0) + self.clock() - t0
        return timed

    def add(self, name: str, seconds: float) -> None:
        self.tick[name] = self.tick.get(name, 0.0) + seconds

    def close_tick(self) -> None:
        self.ticks.append(self.tick)
        self.tick = {}


def instrument(core: AgentCore, timer: StageTimer) -> None:
    """Time the agent's stages (names as in the docs' table) on this core instance."""
    for attr, name in (("_filtered_points", "DRF + depth to points"),
                       ("_whole_voxels", "registration: whole voxels"),
                       ("_register", "registration (localization)"),
                       ("_integrate", "submap + grid integration")):
        setattr(core, attr, timer.wrap(name, getattr(core, attr)))
    # module functions the stages call: the wrapped ones are looked up at call time
    core.nav.step = timer.wrap("navigation (plan + follow)", core.nav.step)
    core.on_grid = timer.wrap("edge grid merge", core.on_grid)
    core.mapper.take_delta = timer.wrap("submap deltas", core.mapper.take_delta)
    agent_mod.filter_mask = timer.wrap("DRF mask (DBSCAN)", agent_mod.filter_mask)
    walls = core.localizer.walls
    if walls is not None:
        walls.update = timer.wrap("- registration: wall heading", walls.update)
    reg = core.localizer.registrar
    for attr in ("_cloud", "align", "insert", "flush"):
        setattr(reg, attr, timer.wrap(f"- registration: {attr.strip('_')}", getattr(reg, attr)))
    agent_mod.floor_rays = timer.wrap("- integration: free-space rays", agent_mod.floor_rays)
    core.mapper.integrate = timer.wrap("- integration: submap voxels", core.mapper.integrate)
    LocalGrid.update = timer.wrap("- integration: grid update", _GRID_UPDATE)
    for name in ("plan_path", "astar", "path_blocked", "traversable_of"):
        setattr(nav_mod, name, timer.wrap(f"- navigation: {name}", _NAV[name]))


def robot_inputs(keys: Keys, robot: int, path: Path) -> Iterator[tuple[str, str, bytes]]:
    """(kind, key, payload) of what robot `robot`'s agent subscribes to and publishes."""
    mine = {keys.rgbd(robot): "rgbd", keys.odom(robot): "odom", keys.goal(robot): "goal",
            keys.correction(robot): "correction", keys.map_grid(): "grid"}
    mine |= {getattr(keys, t)(robot): "out:" + t for t in OUTPUTS if t != "pose"}
    own_pose, robots = keys.pose(robot), f"{keys.prefix}/robot/"
    for key, payload in read_log(path):
        kind = mine.get(key)
        if key.startswith(robots) and key.endswith("/pose"):
            kind = "pose"  # every robot's, as the agent subscribes (it skips its own)
            if key == own_pose:
                yield "out:pose", key, payload
        if kind is not None:
            yield kind, key, payload


def interleave(messages: list[Message], sender: Callable[[Message], object],
               rng: random.Random | None) -> list[Message]:
    """`messages` in a random interleaving of their senders, each sender's own order kept:
    an arrival order the bus could have given (None: as they are)."""
    if rng is None:
        return messages
    queues: dict[object, list[Message]] = {}
    for msg in messages:
        queues.setdefault(sender(msg), []).append(msg)
    lanes = [q[::-1] for q in queues.values()]
    out: list[Message] = []
    while lanes:
        lane = rng.choice(lanes)
        out.append(lane.pop())
        lanes = [q for q in lanes if q]
    return out


def _agent_sender(msg: Message) -> object:
    return msg.robot_id if isinstance(msg, RobotPose) else "edge"


def replay(rec: Path, robot: int, limit: int | None, overrides: dict[str, str] | None = None,
           shuffle: int | None = None, run_ahead: bool = False,
           ) -> tuple[StageTimer, dict, list[str]]:
    """(timer, mismatches per output topic, outputs as published) of one robot's replay;
    `overrides` (dotted config keys) change the agent from the recorded mission's, so its
    outputs differ and the inputs, being the mission's, are open loop; `shuffle` (a seed)
    applies each tick's due messages in a random interleaving of their senders;
    `run_ahead` defers as the node does (`defers`) but never finishes a tick's mapping
    until a later tick needs it done."""
    config = load_config(rec / "run" / "config.yaml", overrides or {})
    keys = Keys(config.bus.prefix)
    core = AgentCore(config.agent, robot, config.sim.tick_s, team_size=config.sim.robots - 1)
    timer = StageTimer()
    instrument(core, timer)
    models = {**INPUTS, "grid": OccupancyGrid, "pose": RobotPose}
    expected: dict[str, list[bytes]] = {t: [] for t in OUTPUTS}
    produced: dict[str, list[bytes]] = {t: [] for t in OUTPUTS}
    pending: list[Message] = []
    rng = None if shuffle is None else random.Random(shuffle)
    n_odom = 0
    for kind, _key, payload in robot_inputs(keys, robot, rec / LOG):
        if kind.startswith("out:"):
            expected[kind[4:]].append(payload)
            continue
        t0 = time.process_time()
        msg = decode(payload, models[kind], config.bus.max_array_bytes)
        timer.add("decode inputs", time.process_time() - t0)
        if kind == "pose" and msg.robot_id == robot:
            continue
        if isinstance(msg, TICKED):
            pending.append(msg)
        elif isinstance(msg, RgbdFrame):
            core.on_rgbd(msg)
        elif isinstance(msg, Odometry):
            _tick(core, msg, pending, timer, produced, rng,
                  config.sim.edge_every_ticks if run_ahead else None)
            n_odom += 1
            if limit is not None and n_odom >= limit:
                break
    for out in core.finish_tick():  # the node finishes when idle: after the last tick too
        produced[out.topic].append(encode(out.message))
    mismatches = {t: _mismatch(expected[t], produced[t], limit is not None) for t in OUTPUTS}
    if mismatches["pose"].startswith("differ"):
        mismatches["pose"] += _pose_gap(expected["pose"], produced["pose"])
    return timer, mismatches, [f"{t}: {len(produced[t])}" for t in OUTPUTS]


def _tick(core: AgentCore, odom: Odometry, pending: list[Message], timer: StageTimer,
          produced: dict[str, list[bytes]], rng: random.Random | None,
          run_ahead_every: int | None = None) -> None:
    t0 = time.process_time()
    due = interleave([m for m in pending if m.tick < odom.tick],  # type: ignore[attr-defined]
                     _agent_sender, rng)
    pending[:] = [m for m in pending if m.tick >= odom.tick]  # type: ignore[attr-defined]
    for earlier in due:
        _apply(core, earlier)
    camera = core.frame is not None and core.frame.tick <= odom.tick
    # as the node: CmdVel first, then the rest
    ahead = run_ahead_every is not None
    outs = core.on_odometry(odom, defer=defers(odom.tick, run_ahead_every) if ahead else True)
    t1 = time.process_time()
    outs += core.finish_tick(until=(lambda: True) if ahead else None)
    t2 = time.process_time()
    for out in outs:
        produced[out.topic].append(encode(out.message))
    t3 = time.process_time()
    timer.add("encode outputs", t3 - t2)
    timer.add("whole tick (apply + on_odometry + finish_tick)", t2 - t0)
    timer.add("camera tick, until CmdVel" if camera else "other tick", t1 - t0)
    timer.add("finish_tick (after CmdVel)", t2 - t1)
    timer.close_tick()


def _mismatch(expected: list[bytes], produced: list[bytes], partial: bool) -> str:
    n = min(len(expected), len(produced))
    first = next((i for i in range(n) if expected[i] != produced[i]), None)
    if first is not None:
        return f"differ from message {first} of {n}"
    if not partial and len(expected) != len(produced):
        return f"{len(produced)} produced, {len(expected)} in the mission"
    return "identical"


def _pose_gap(expected: list[bytes], produced: list[bytes]) -> str:
    """How far the replayed poses stray from the mission's: rounding, or another mission."""
    pairs = [(decode(a, RobotPose).pose_world, decode(b, RobotPose).pose_world)
             for a, b in zip(expected, produced, strict=False)]
    d_m = max(float(np.hypot(a.x - b.x, a.y - b.y)) for a, b in pairs)
    d_rad = max(abs(float(wrap_angle(a.yaw - b.yaw))) for a, b in pairs)
    return f" (largest gap {d_m:.2g} m, {d_rad:.2g} rad)"


def report(timer: StageTimer) -> None:
    names = sorted({n for t in timer.ticks for n in t}, key=lambda n: -sum(
        t.get(n, 0.0) for t in timer.ticks))
    total = sum(t.get("whole tick (apply + on_odometry + finish_tick)", 0.0) for t in timer.ticks)
    print(f"{len(timer.ticks)} ticks; whole ticks {total:.1f} s\n")
    print("| stage | total s | share of ticks % | median ms (ticks it ran) | p90 ms | ticks |")
    print("|---|---:|---:|---:|---:|---:|")
    for name in names:
        v = np.array([t[name] for t in timer.ticks if name in t]) * 1e3
        print(f"| {name} | {v.sum() / 1e3:.2f} | {100 * v.sum() / 1e3 / max(total, 1e-9):.1f} "
              f"| {np.median(v):.2f} | {np.percentile(v, 90):.2f} | {v.size} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("out", type=Path)
    r.add_argument("run_args", nargs=argparse.REMAINDER)
    p = sub.add_parser("replay")
    p.add_argument("rec", type=Path)
    p.add_argument("--robot", type=int, default=0)
    p.add_argument("--ticks", type=int, default=None, help="stop after this many ticks")
    p.add_argument("--check", action="store_true", help="compare outputs with the mission's")
    p.add_argument("--profile", action="store_true", help="cProfile the replay")
    p.add_argument("--shuffle", type=int, default=None, metavar="SEED",
                   help="apply each tick's teammate poses and edge messages in a random "
                   "interleaving of their senders (with --check: does arrival order matter?)")
    p.add_argument("--run-ahead", action="store_true",
                   help="leave each tick's mapping queued until a later tick needs it (the "
                   "node's order at its most extreme; with --check: outputs must not move)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="config override (repeatable), e.g. agent.reg_whole_voxels=pixels: the "
                   "stage costs of another setting on the same inputs (open loop)")
    args = ap.parse_args()
    if args.cmd == "record":
        record(args.out, [a for a in args.run_args if a != "--"])
        return
    prof = cProfile.Profile() if args.profile else None
    if prof is not None:
        prof.enable()
    overrides = dict(kv.split("=", 1) for kv in args.set)
    timer, mismatches, counts = replay(args.rec, args.robot, args.ticks, overrides,
                                       args.shuffle, args.run_ahead)
    if prof is not None:
        prof.disable()
        stats = pstats.Stats(prof).strip_dirs()
        stats.sort_stats("cumulative").print_stats(45)
        stats.sort_stats("tottime").print_stats(30)
    report(timer)
    print("\noutputs: " + ", ".join(counts))
    if args.check:
        print("outputs against the mission: " + ", ".join(
            f"{t} {m}" for t, m in mismatches.items()))


if __name__ == "__main__":
    main()
