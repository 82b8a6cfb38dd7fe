"""Health probe: is a process of the mission alive (its liveliness token present)?"""

from __future__ import annotations

import time

import zenoh

from schemas import Keys
from services.common.bus import BusConfig, open_session


def is_alive(config: BusConfig, role: str, ident: int | str = 0, timeout_s: float = 3.0,
             login_as: str = "monitor") -> bool:
    """True when `alive/{role}/{ident}` is declared; for the router, when it accepts a session
    (with credentials: logs in as `login_as`, any user may read liveliness). A missing or
    unusable certificate raises services.common.tls.TlsError: a probe cannot fix that."""
    probe = config.model_copy(update={"connect_timeout_s": timeout_s})
    try:
        with open_session(probe, login_as) as session:
            if role == "router":
                return True
            return _token_held(session, Keys(config.prefix).alive(role, ident), timeout_s)
    except zenoh.ZError:
        return False


PROBE_TRIES = 3


def _token_held(session: zenoh.Session, key: str, timeout_s: float) -> bool:
    """Whether the router holds the token, asked up to PROBE_TRIES times within `timeout_s`:
    the router now and then answers a liveliness query at once with no token at all
    (services.common.liveliness), which would fail a health check of a live process."""
    deadline = time.monotonic() + timeout_s
    for _ in range(PROBE_TRIES):
        left = deadline - time.monotonic()
        if left <= 0:
            return False
        if any(reply.ok is not None for reply in session.liveliness().get(key, timeout=left)):
            return True
    return False
