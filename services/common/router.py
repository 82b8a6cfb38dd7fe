"""The zenoh router, run from Python (mode router)."""

from __future__ import annotations

import logging
import threading
from pathlib import Path

import zenoh

from services.common.access import DICTIONARY, acl_config, credentials_robots
from services.common.bus import zenoh_config

log = logging.getLogger(__name__)


def run_router(
    listen: list[str],
    stop: threading.Event,
    lease_s: float = 10.0,
    credentials: str | None = None,
    prefix: str = "spacemap",
) -> None:
    """Serve as the mission's router until `stop` is set. With `credentials` (a folder from
    `spacemap credentials`) only its users may connect, each only on its role's keys."""
    secure = {}
    if credentials is not None:
        robots = credentials_robots(credentials)
        secure = {"dictionary_file": str(Path(credentials) / DICTIONARY),
                  "access_control": acl_config(prefix, robots)}
        log.info("authentication on, access control for %d robots under %s/", robots, prefix)
    else:
        log.warning("no credentials: any client may connect and publish on any key")
    session = zenoh.open(zenoh_config("router", listen=listen, lease_s=lease_s, **secure))
    log.info("zenoh router listening on %s", ", ".join(listen))
    try:
        stop.wait()
    finally:
        session.close()
