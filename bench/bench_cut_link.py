"""How long a router takes to declare a client gone when its link is cut while traffic flows
toward it. Needs root (network namespaces).

Four test hosts on a bridge: a router, a victim client (a liveliness token, a subscriber of
`big/**`), a pusher client that publishes `--size` bytes on `big/x` every 50 ms (reliable;
congestion control BLOCK, or DROP with `--drop`) and an observer client that watches the
token. The victim's link is cut; the time until the observer sees the token's DELETE is
printed (or "not within" the deadline), with whether the router logged zenoh's "Unable to push
non droppable network message" meanwhile (a BLOCK message that waited `wait_before_close` for
the victim's full queue; the router then drops the pusher's link too).

    sudo .venv/bin/python bench/bench_cut_link.py --size 1000000 [--shm] [--drop]
        [--tls] [--tcp-retries2 N] [--reconcile] [--watcher-pushes] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import zenoh

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from services.common.access import make_credentials  # noqa: E402
from services.common.bus import zenoh_config  # noqa: E402
from services.common.liveliness import LivelinessWatch  # noqa: E402
from services.common.tls import client_tls, router_tls  # noqa: E402
from tests.netns import make_hosts  # noqa: E402

COLLATERAL = "Unable to push non droppable network message"


def _config(args: argparse.Namespace) -> zenoh.Config:
    """spacemap's session flags (services.common.bus.zenoh_config), a 2 s lease."""
    router = args.role == "router"
    tls = None
    if args.cred:
        user = {"victim": "agent-0", "observer": "monitor", "pusher": "sim"}.get(args.role)
        tls = router_tls(args.cred) if router else client_tls(args.cred, user)
    return zenoh_config("router" if router else "client",
                        listen=[args.endpoint] if router else None,
                        connect=None if router else [args.endpoint],
                        shared_memory=args.shm, lease_s=2.0, tls=tls)


def _query(session: zenoh.Session) -> None:
    """Print HELD-GONE once a liveliness query (the router's view) no longer has the token
    that an earlier query found."""
    seen = False
    while True:
        try:
            held = [r for r in session.liveliness().get("t/**", timeout=1.0) if r.ok is not None]
        except zenoh.ZError:
            held = None
        seen = seen or bool(held)
        if seen and held == []:
            print(f"HELD-GONE {time.monotonic()}", flush=True)
            return
        time.sleep(0.2)


def serve(args: argparse.Namespace) -> None:
    """One host's part, until killed."""
    if args.role == "router":
        zenoh.init_log_from_env_or("warn")  # the collateral close is logged at ERROR
    session = zenoh.open(_config(args))
    if args.role == "victim":
        _token = session.liveliness().declare_token("t/victim")
        _sub = session.declare_subscriber("big/**", lambda _sample: None)
    if args.role == "observer" and args.reconcile:  # as every spacemap service watches
        def deliver(_key: str, alive: bool) -> None:
            if not alive:
                print(f"GONE {time.monotonic()}", flush=True)
        _watch = LivelinessWatch(session, "t/**", deliver, interval_s=1.0)
    elif args.role == "observer":
        def on_token(sample: zenoh.Sample) -> None:
            if sample.kind == zenoh.SampleKind.DELETE:
                print(f"GONE {time.monotonic()}", flush=True)
        _watch = session.liveliness().declare_subscriber("t/**", on_token)
    if args.role == "observer":
        threading.Thread(target=_query, args=(session,), daemon=True).start()
    if args.role == "pusher" or (args.role == "observer" and args.watcher_pushes):
        cc = zenoh.CongestionControl.DROP if args.drop else zenoh.CongestionControl.BLOCK
        pub = session.declare_publisher("big/x", congestion_control=cc,
                                        reliability=zenoh.Reliability.RELIABLE)
        payload = b"x" * args.size
        while args.size:
            pub.put(payload)
            time.sleep(0.05)
    while True:
        time.sleep(1)


def measure(args: argparse.Namespace) -> tuple[float | None, float | None, bool]:
    """Seconds from the cut to the observer's DELETE event and to its liveliness query no
    longer finding the token (None past the deadline), and whether the router could not push a
    BLOCK message to the victim meanwhile."""
    with make_hosts(["core", "a0", "obs", "pub"]) as hosts, tempfile.TemporaryDirectory() as tmp:
        if args.tcp_retries2 is not None:  # how long the router host retries unacked data
            subprocess.run(hosts.exec_prefix("core") + [
                "sysctl", "-q", "-w", f"net.ipv4.tcp_retries2={args.tcp_retries2}"], check=True)
        cred = ""
        if args.tls:  # mutual TLS as a mission has it (no logins, no access control)
            cred = str(Path(tmp) / "cred")
            make_credentials(Path(cred), 1, router_hosts=[hosts.address["core"]])
        endpoint = f"{'tls' if args.tls else 'tcp'}/{hosts.address['core']}:7447"
        router_log = Path(tmp) / "router.log"
        procs = []

        def start(host: str, role: str, out: int | None = subprocess.PIPE) -> subprocess.Popen:
            argv = [sys.executable, __file__, "--role", role, "--endpoint", endpoint,
                    "--size", str(args.size)] + ["--shm"] * args.shm + ["--drop"] * args.drop
            argv += ["--cred", cred] * bool(cred) + ["--watcher-pushes"] * args.watcher_pushes
            argv += ["--reconcile"] * args.reconcile
            proc = subprocess.Popen(hosts.exec_prefix(host) + argv, stdout=out,
                                    stderr=subprocess.STDOUT, text=True,
                                    env={**os.environ, "NO_COLOR": "1"})
            procs.append(proc)
            return proc

        try:
            with router_log.open("w") as log:
                start("core", "router", out=log.fileno())
            time.sleep(2)
            start("a0", "victim", out=subprocess.DEVNULL)
            observer = start("obs", "observer")
            if not args.watcher_pushes:
                start("pub", "pusher", out=subprocess.DEVNULL)
            time.sleep(4)
            hosts.link("a0", up=False)
            t_cut = time.monotonic()
            seen: dict[str, float] = {}

            def read() -> None:
                assert observer.stdout is not None
                for line in observer.stdout:
                    word, *rest = line.split()
                    if word in ("GONE", "HELD-GONE"):
                        seen[word] = float(rest[0]) - t_cut
                    if len(seen) == 2:
                        return
            reader = threading.Thread(target=read, daemon=True)
            reader.start()
            reader.join(args.deadline)
            return seen.get("GONE"), seen.get("HELD-GONE"), COLLATERAL in router_log.read_text()
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
    parser.add_argument("--drop", action="store_true", help="congestion control DROP")
    parser.add_argument("--tcp-retries2", type=int, help="the router host's "
                        "net.ipv4.tcp_retries2 (kernel default 15)")
    parser.add_argument("--watcher-pushes", action="store_true", help="the observer is the "
                        "pusher (no fourth host)")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--deadline", type=float, default=40.0, help="seconds to wait")
    parser.add_argument("--tls", action="store_true", help="mutual TLS links, as a mission's")
    parser.add_argument("--reconcile", action="store_true", help="the observer's DELETE "
                        "from services.common.liveliness (events checked against the router)")
    parser.add_argument("--role", help=argparse.SUPPRESS)
    parser.add_argument("--cred", help=argparse.SUPPRESS)
    parser.add_argument("--endpoint", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role:
        serve(args)
        return
    setting = (f"{'TLS' if args.tls else 'TCP'}, size {args.size} B, "
               f"shared memory {'on' if args.shm else 'off'}, "
               f"{'DROP' if args.drop else 'BLOCK'}"
               + ("" if args.tcp_retries2 is None else f", tcp_retries2 {args.tcp_retries2}")
               + (", the observer pushes" if args.watcher_pushes else "")
               + (", events checked against the router" if args.reconcile else ""))
    for _ in range(args.repeats):
        event, query, collateral = measure(args)
        late = f"not within {args.deadline:.0f} s"
        print(f"{setting}: DELETE event {late if event is None else f'after {event:.2f} s'}, "
              f"router's token {late if query is None else f'gone after {query:.2f} s'}; "
              f"a push to the victim failed: {'yes' if collateral else 'no'}", flush=True)


if __name__ == "__main__":
    main()
