"""Fuzz at the issue's scale (issue 14): at least --messages bad messages during one lockstep
mission, then the same seed's clean mission, and whether their metrics.json agree.

Both missions run through `run_mission` against one `spacemap router` with fresh credentials
(logins, access control, mutual TLS). During the fuzzed one a client holding agent 0's login
and certificate sends, every --every-ticks ticks, one burst of tests/fuzz.py's payloads on
every key agent 0 may publish (pose, cmd_vel, goal_status, submap: random bytes, empty,
truncated, wrong kind and version, lying arrays, NaN/inf, absurd ids, oversize, ...), until
--messages are out. Prints the messages sent, each process's drop count (from the totals it
logs at exit) against what it should have dropped, the exit codes, and whether metrics.json
equals the clean run's apart from wall_time_s. tests/test_access_mission.py is the CI-sized
version (a few hundred messages).

    .venv/bin/python bench/bench_fuzz.py --messages 10000 --robots 2 --sim-time 60
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import threading
import time
from pathlib import Path

import zenoh

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from schemas import decode  # noqa: E402
from schemas.messages import Clock  # noqa: E402
from services.common.access import identity, make_credentials  # noqa: E402
from services.common.bus import open_session  # noqa: E402
from services.config import SpacemapConfig, load_config  # noqa: E402
from services.launcher.run import run_mission  # noqa: E402
from services.processes import ProcessGroup, free_tcp_port, spacemap_command  # noqa: E402
from tests.fuzz import bad_payloads, templates  # noqa: E402

BLOCK = zenoh.CongestionControl.BLOCK


class Fuzzer(threading.Thread):
    """Agent 0's login, misbehaving: a burst on each of its keys every `every` ticks (read
    through a monitor login, which may see the clock) until `target` messages are out."""

    def __init__(self, config: SpacemapConfig, target: int, every: int) -> None:
        super().__init__(daemon=True)
        self.config, self.target, self.every = config, target, every
        self.bursts = {topic: bad_payloads(t, seed=i)
                       for i, (topic, t) in enumerate(templates(0).items())}
        self.sent = {topic: 0 for topic in self.bursts}
        self.stop = threading.Event()
        self.tick = -1
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self._run()
        except BaseException as exc:  # reported by main
            self.error = exc

    def _on_clock(self, sample: zenoh.Sample) -> None:
        self.tick = decode(sample.payload.to_bytes(), Clock).tick

    def _run(self) -> None:
        bus = self.config.bus
        with open_session(bus, identity("monitor")) as watch, \
                open_session(bus, identity("agent", 0)) as rogue:
            watch.declare_subscriber(f"{bus.prefix}/sim/clock", self._on_clock)
            last = -self.every
            while not self.stop.is_set() and sum(self.sent.values()) < self.target:
                if self.tick >= last + self.every:
                    last = self.tick
                    for topic, payloads in self.bursts.items():
                        for _, payload in payloads:
                            rogue.put(f"{bus.prefix}/robot/0/{topic}", payload,
                                      congestion_control=BLOCK)
                        self.sent[topic] += len(payloads)
                time.sleep(0.005)


def drop_totals(log: Path) -> int:
    found = re.findall(r"dropped \d+ bad messages in all: (\{.*\})", log.read_text())
    return sum(json.loads(found[-1]).values()) if found else 0


def mission(config: SpacemapConfig, out: Path, fuzz: Fuzzer | None) -> tuple[dict, dict]:
    if fuzz is not None:
        fuzz.start()
    try:
        result = run_mission(config, out, router_endpoint=config.bus.connect,
                             sample_every_s=0)
    finally:
        if fuzz is not None:
            fuzz.stop.set()
            fuzz.join(timeout=30)
    return dict(result.metrics), result.exit_codes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--messages", type=int, default=10_000)
    parser.add_argument("--every-ticks", type=int, default=2)
    parser.add_argument("--robots", type=int, default=2)
    parser.add_argument("--sim-time", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--world", default="house")
    parser.add_argument("--keep", type=Path, default=None, help="keep the run folders here")
    opts = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = opts.keep or Path(tmp)
        make_credentials(root / "cred", opts.robots)
        endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
        router = ProcessGroup(root / "router-logs")
        router.start("router", spacemap_command(
            "router", "--listen", endpoint, "--set", f"bus.credentials={root / 'cred'}"))
        try:
            config = load_config(overrides={
                "bus.connect": endpoint, "bus.credentials": str(root / "cred"),
                "bus.connect_timeout_s": 60.0, "sim.robots": opts.robots,
                "sim.world": opts.world, "sim.seed": opts.seed,
                "sim.max_sim_time_s": opts.sim_time})
            fuzz = Fuzzer(config, opts.messages, opts.every_ticks)
            t0 = time.monotonic()
            fuzzed, codes = mission(config, root / "fuzzed", fuzz)
            fuzz_wall = time.monotonic() - t0
            clean, clean_codes = mission(config, root / "clean", None)
        finally:
            router_codes = router.stop()
        report(opts, fuzz, fuzzed, codes, clean, clean_codes, router_codes, root, fuzz_wall)


def report(opts: argparse.Namespace, fuzz: Fuzzer, fuzzed: dict, codes: dict, clean: dict,
           clean_codes: dict, router_codes: dict, root: Path, wall_s: float) -> None:
    n = fuzz.sent
    expected = {"sim": n["cmd_vel"], "edge": n["pose"] + n["submap"] + n["goal_status"],
                **{f"agent{i}": n["pose"] for i in range(opts.robots)}}
    print(f"bench_fuzz: {opts.robots} robots, {opts.world}, seed {opts.seed}, sim-time cap "
          f"{opts.sim_time} s, a burst every {opts.every_ticks} ticks; fuzzed mission "
          f"{wall_s:.0f} s wall")
    if fuzz.error is not None:
        print(f"fuzzer failed: {fuzz.error!r}")
    print(f"bad messages sent: {sum(n.values())} ({json.dumps(n)})")
    print("| process | dropped | expected |\n|---|---:|---:|")
    for name, count in expected.items():
        print(f"| {name} | {drop_totals(root / 'fuzzed' / 'logs' / f'{name}.log')} | {count} |")
    print(f"exit codes, fuzzed: {codes}; clean: {clean_codes}; router: {router_codes}")
    same = ({k: v for k, v in fuzzed.items() if k != "wall_time_s"}
            == {k: v for k, v in clean.items() if k != "wall_time_s"})
    print(f"metrics.json equal to the clean run's apart from wall_time_s: {same}")
    if not same:
        diff = {k: (fuzzed.get(k), clean.get(k)) for k in sorted(set(fuzzed) | set(clean))
                if k != "wall_time_s" and fuzzed.get(k) != clean.get(k)}
        print(f"differences (fuzzed, clean): {diff}")


if __name__ == "__main__":
    main()
