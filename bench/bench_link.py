"""What a link costs per message through a real `spacemap router` on loopback: mutual TLS
against plain TCP (issue 14), with the mission's logins and access control in both.

The simulator's login publishes `robot/0/rgbd` (reliable, congestion control BLOCK, as the
services do) and agent 0's login receives it, both in this process; the router is its own
process. Per message size: messages per second, and CPU microseconds per message in the router
(decrypt + route + encrypt) and in this process (both clients). Modes alternate TLS, TCP, TCP,
TLS, ... per repeat; medians. CPU time is the steadier figure on a shared machine.

    .venv/bin/python bench/bench_link.py --repeats 4
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import zenoh

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from schemas.keys import Keys  # noqa: E402
from services.common.access import make_credentials  # noqa: E402
from services.common.bus import BusConfig, open_session  # noqa: E402
from services.processes import (  # noqa: E402
    ProcessGroup,
    free_tcp_port,
    process_cpu_seconds,
    spacemap_command,
)

SIZES = {200: 20_000, 100_000: 2_000}  # payload bytes → messages (a pose; a 160×120 frame)


def cpu_of(pid: int) -> float:
    seconds = process_cpu_seconds(pid)
    if seconds is None:
        raise RuntimeError(f"process {pid} is gone")
    return seconds


def measure(config: BusConfig, router_pid: int, size: int, count: int) -> dict[str, float]:
    key = Keys(config.prefix).rgbd(0)
    done = threading.Event()
    got = [0]

    def on_sample(_: zenoh.Sample) -> None:
        got[0] += 1
        if got[0] == count:
            done.set()

    with open_session(config, "sim") as sim, open_session(config, "agent-0") as agent:
        agent.declare_subscriber(key, zenoh.handlers.Callback(on_sample, indirect=False))
        pub = sim.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK,
                                    reliability=zenoh.Reliability.RELIABLE)
        deadline = time.monotonic() + 10
        while not pub.matching_status.matching:
            if time.monotonic() > deadline:
                raise RuntimeError("the publisher never saw the subscriber")
            time.sleep(0.01)
        payload = bytes(size)
        router0, cpu0, t0 = cpu_of(router_pid), time.process_time(), time.monotonic()
        for _ in range(count):
            pub.put(payload)
        if not done.wait(120):
            raise RuntimeError(f"only {got[0]} of {count} messages arrived")
        wall = time.monotonic() - t0
        cpu, router = time.process_time() - cpu0, cpu_of(router_pid) - router0
    return {"msgs/s": count / wall, "MB/s": count * size / wall / 1e6,
            "router CPU µs/msg": router / count * 1e6, "clients CPU µs/msg": cpu / count * 1e6}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=4)
    opts = parser.parse_args()
    rows: dict[tuple[bool, int], list[dict[str, float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        cred = Path(tmp) / "cred"
        make_credentials(cred, 1)
        for i in range(opts.repeats):
            for tls in (True, False) if i % 2 == 0 else (False, True):
                endpoint = f"{'tls' if tls else 'tcp'}/127.0.0.1:{free_tcp_port()}"
                group = ProcessGroup(Path(tmp) / f"logs{i}{tls}")
                group.start("router", spacemap_command(
                    "router", "--listen", endpoint, "--set", f"bus.credentials={cred}",
                    "--set", f"bus.tls={str(tls).lower()}"))
                config = BusConfig(connect=endpoint, credentials=str(cred), tls=tls,
                                   connect_timeout_s=60)
                try:
                    for size, count in SIZES.items():
                        rows.setdefault((tls, size), []).append(
                            measure(config, group.children["router"].pid, size, count))
                finally:
                    group.stop()
    print(f"bench_link: {opts.repeats} repeats, medians\n")
    print("| link | payload | msgs/s | MB/s | router CPU µs/msg | clients CPU µs/msg |")
    print("|---|---:|---:|---:|---:|---:|")
    for (tls, size), runs in rows.items():
        med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        print(f"| {'mutual TLS' if tls else 'plain TCP'} | {size} B | {med['msgs/s']:.0f} | "
              f"{med['MB/s']:.1f} | {med['router CPU µs/msg']:.1f} | "
              f"{med['clients CPU µs/msg']:.1f} |")


if __name__ == "__main__":
    main()
