"""Health probe: is a process of the mission alive (its liveliness token present)?"""

from __future__ import annotations

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
            key = Keys(config.prefix).alive(role, ident)
            replies = session.liveliness().get(key, timeout=timeout_s)
            return any(reply.ok is not None for reply in replies)
    except zenoh.ZError:
        return False
