"""How long a router takes to declare a client gone when its link is cut while reliable
(congestion control BLOCK) traffic flows toward it. Needs root (network namespaces).

Three test hosts on a bridge: a router, a victim client (a liveliness token, a subscriber of
`big/**`) and an observer client that publishes `--size` bytes on `big/x` every 50 ms and
watches the token. The victim's link is cut; the time until the observer sees the token's
DELETE is printed (or "not within" the deadline).

    sudo .venv/bin/python bench/bench_cut_link.py --size 1000000 [--shm] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import zenoh

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tests.netns import make_hosts  # noqa: E402


def _config(mode: str, endpoint: str, shm: bool) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    key = "listen/endpoints" if mode == "router" else "connect/endpoints"
    conf.insert_json5(key, json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/link/tx/lease", "2000")
    conf.insert_json5("transport/shared_memory/enabled", json.dumps(shm))
    return conf


def serve(role: str, endpoint: str, shm: bool, size: int) -> None:
    """One host's part, until killed."""
    session = zenoh.open(_config("router" if role == "router" else "client", endpoint, shm))
    if role == "victim":
        _token = session.liveliness().declare_token("t/victim")
        _sub = session.declare_subscriber("big/**", lambda _sample: None)
    elif role == "observer":
        def on_token(sample: zenoh.Sample) -> None:
            if sample.kind == zenoh.SampleKind.DELETE:
                print(f"GONE {time.monotonic()}", flush=True)
        _watch = session.liveliness().declare_subscriber("t/**", on_token)
        pub = session.declare_publisher("big/x", congestion_control=zenoh.CongestionControl.BLOCK,
                                        reliability=zenoh.Reliability.RELIABLE)
        payload = b"x" * size
        while size:
            pub.put(payload)
            time.sleep(0.05)
    while True:
        time.sleep(1)


def measure(size: int, shm: bool, deadline_s: float) -> float | None:
    """Seconds from the cut to the observer seeing the token go; None past the deadline."""
    with make_hosts(["core", "a0", "obs"]) as hosts:
        endpoint = f"tcp/{hosts.address['core']}:7447"
        procs = []

        def start(host: str, role: str) -> subprocess.Popen[str]:
            argv = [sys.executable, __file__, "--role", role, "--endpoint", endpoint,
                    "--size", str(size)] + (["--shm"] if shm else [])
            proc = subprocess.Popen(hosts.exec_prefix(host) + argv, stdout=subprocess.PIPE,
                                    stderr=subprocess.DEVNULL, text=True)
            procs.append(proc)
            return proc

        try:
            start("core", "router")
            time.sleep(2)
            start("a0", "victim")
            observer = start("obs", "observer")
            time.sleep(4)
            hosts.link("a0", up=False)
            t_cut = time.monotonic()
            lines: list[str] = []
            reader = threading.Thread(target=lambda: lines.append(observer.stdout.readline()),
                                      daemon=True)
            reader.start()
            reader.join(deadline_s)
            return float(lines[0].split()[1]) - t_cut if lines and lines[0] else None
        finally:
            for proc in procs:
                proc.kill()
                proc.wait()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=1_000_000, help="bytes a put, 0: none")
    parser.add_argument("--shm", action="store_true", help="zenoh's shared memory enabled "
                        "(spacemap's processes turn it off)")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--deadline", type=float, default=40.0, help="seconds to wait")
    parser.add_argument("--role", help=argparse.SUPPRESS)
    parser.add_argument("--endpoint", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role:
        serve(args.role, args.endpoint, args.shm, args.size)
        return
    for _ in range(args.repeats):
        took = measure(args.size, args.shm, args.deadline)
        shown = f"after {took:.2f} s" if took is not None else f"not within {args.deadline:.0f} s"
        print(f"size {args.size} B, shared memory {'on' if args.shm else 'off'}: gone {shown}",
              flush=True)


if __name__ == "__main__":
    main()
