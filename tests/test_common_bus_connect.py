"""A client that starts before its router connects as soon as the router listens."""

from __future__ import annotations

import json
import threading

import zenoh

from services.common.bus import CONNECT_RETRY, zenoh_config
from services.processes import free_tcp_port


def test_connect_retries_soon_and_reaches_a_router_that_comes_up_late() -> None:
    conf = zenoh_config("client", connect=["tcp/127.0.0.1:1"], connect_timeout_s=5.0)
    assert json.loads(conf.get_json("connect/retry")) == CONNECT_RETRY
    assert CONNECT_RETRY["period_init_ms"] <= 100  # zenoh's default waits 1 s after a refusal

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    stop = threading.Event()

    def late_router() -> None:
        # the scenario, not a wait for a condition: the router comes up after the client tried
        stop.wait(0.3)
        with zenoh.open(zenoh_config("router", listen=[endpoint])):
            stop.wait(10.0)

    thread = threading.Thread(target=late_router, daemon=True)
    thread.start()
    try:
        with zenoh.open(zenoh_config("client", connect=[endpoint],
                                     connect_timeout_s=5.0)) as session:
            assert list(session.info.routers_zid())
    finally:
        stop.set()
        thread.join(timeout=15.0)
