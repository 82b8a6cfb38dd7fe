"""The zenoh router, run from Python (mode router)."""

from __future__ import annotations

import logging
import threading

import zenoh

from services.common.bus import zenoh_config

log = logging.getLogger(__name__)


def run_router(listen: list[str], stop: threading.Event, lease_s: float = 10.0) -> None:
    """Serve as the mission's router until `stop` is set."""
    session = zenoh.open(zenoh_config("router", listen=listen, lease_s=lease_s))
    log.info("zenoh router listening on %s", ", ".join(listen))
    try:
        stop.wait()
    finally:
        session.close()
