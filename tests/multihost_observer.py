"""Observer for the multi-host test: runs inside a test host and prints the mission's state as
JSON lines (sim time, live processes, completion) to stdout, until stdin closes. Its one
argument is the mission's config file; it logs in as the monitor.

Live processes twice: `alive` from the liveliness events this session received (what the
services act on), `alive_router` from a liveliness query each second (the router's view)."""

from __future__ import annotations

import json
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zenoh

from schemas.messages import Clock, Frontiers
from services.common.access import identity
from services.common.bus import Inbound, Presence, connect
from services.config import load_config


def query_alive(session: zenoh.Session, key_expr: str,
                keys_of: Callable[[str], tuple[str, str]]) -> list[str] | None:
    """`role/id` of every liveliness token the router holds; None when the query fails."""
    try:
        replies = session.liveliness().get(key_expr, timeout=1.0)
        keys = [str(r.ok.key_expr) for r in replies if r.ok is not None]
    except zenoh.ZError:
        return None
    return sorted("/".join(keys_of(k)) for k in keys)


def main(config_path: str) -> None:
    stop = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    state: dict[str, object] = {"t": 0.0, "alive": [], "alive_router": [], "complete": False}
    alive: set[str] = set()
    with connect(load_config(Path(config_path)).bus, identity("monitor")) as bus:
        bus.subscribe(bus.keys.clock(), Clock)
        bus.subscribe(bus.keys.map_frontiers(), Frontiers)
        bus.watch_liveliness()
        last = None
        next_query = 0.0
        while not stop.is_set():
            if time.monotonic() >= next_query:
                next_query = time.monotonic() + 1.0
                queried = query_alive(bus.session, bus.keys.alive_all(), bus.keys.alive_member)
                if queried is not None:
                    state["alive_router"] = queried
            item = bus.poll(timeout=0.2)
            if isinstance(item, Presence):
                name = f"{item.role}/{item.ident}"
                alive.add(name) if item.alive else alive.discard(name)
                state["alive"] = sorted(alive)
            elif isinstance(item, Inbound) and isinstance(item.message, Clock):
                state["t"] = round(item.message.stamp_ns * 1e-9, 1)
            elif isinstance(item, Inbound) and isinstance(item.message, Frontiers):
                state["complete"] = state["complete"] or item.message.complete
            line = json.dumps(state, sort_keys=True)
            if line != last:
                print(line, flush=True)
                last = line


if __name__ == "__main__":
    main(sys.argv[1])
