"""The zenoh router, run from Python (mode router)."""

from __future__ import annotations

import logging
import threading
from pathlib import Path

import zenoh

from services.common.access import DICTIONARY, acl_config, credentials_robots
from services.common.bus import zenoh_config
from services.common.tls import TlsError, is_tls, router_names, router_tls

log = logging.getLogger(__name__)

TCP_RETRIES2 = Path("/proc/sys/net/ipv4/tcp_retries2")
RECOMMENDED_TCP_RETRIES2 = 5  # TCP gives up on a dead peer after about 12.6 s


def tcp_give_up_s(retries2: int, rto_min_s: float = 0.2, rto_max_s: float = 120.0) -> float:
    """How long Linux retransmits unacknowledged data before failing the connection, from
    `net.ipv4.tcp_retries2` (the kernel's bound: exponential backoff from the minimum RTO)."""
    return sum(min(rto_min_s * 2**i, rto_max_s) for i in range(retries2 + 1))


def check_tcp_retries2(path: Path = TCP_RETRIES2) -> int | None:
    """Warn when this host keeps retrying a dead client's data long: a TLS client whose link
    is cut while data is queued toward it keeps its liveliness token (and the lockstep clock
    waits for it) until TCP gives up (ARCHITECTURE.md, "A cut link"). The setting's value,
    None where it cannot be read."""
    try:
        retries2 = int(path.read_text())
    except (OSError, ValueError):
        return None
    if retries2 > RECOMMENDED_TCP_RETRIES2:
        log.warning("net.ipv4.tcp_retries2=%d on this host: a client cut off while data is "
                    "queued toward it is declared gone only after about %.0f s; set %d "
                    "(about %.0f s) on the router's host (sysctl, or the compose file's "
                    "sysctls)", retries2, tcp_give_up_s(retries2), RECOMMENDED_TCP_RETRIES2,
                    tcp_give_up_s(RECOMMENDED_TCP_RETRIES2))
    return retries2


def default_listen(credentials: str | None, tls: bool) -> list[str]:
    """Where `spacemap router` listens without --listen: TLS when it has credentials."""
    return ["tls/0.0.0.0:7447" if credentials is not None and tls else "tcp/0.0.0.0:7447"]


def _check_links(listen: list[str], credentials: str | None, tls: bool) -> bool:
    """True when the router listens on TLS; TlsError for a mix it cannot secure."""
    secure = [is_tls(e) for e in listen]
    if any(secure) and not all(secure):
        raise TlsError(f"listen endpoints {listen} mix tls/ and plain links: the access "
                       "rules bind to client certificates, so use tls/ for all of them")
    if any(secure) and credentials is None:
        raise TlsError("tls/ endpoints need bus.credentials (a folder from `spacemap "
                       "credentials` with the CA and the router's certificate)")
    if not any(secure) and credentials is not None and tls:
        raise TlsError(f"bus.tls is on but the router would listen on {listen}: listen on "
                       "tls/HOST:PORT, or set bus.tls=false to accept logins over plain TCP")
    return all(secure)


def run_router(
    listen: list[str],
    stop: threading.Event,
    lease_s: float = 10.0,
    credentials: str | None = None,
    prefix: str = "spacemap",
    tls: bool = True,
) -> None:
    """Serve as the mission's router until `stop` is set. With `credentials` (a folder from
    `spacemap credentials`) only its users may connect, each only on its role's keys; on
    tls/ endpoints every client must also show its own certificate from the folder's CA."""
    on_tls = _check_links(listen, credentials, tls)
    secure: dict = {}
    if credentials is not None:
        robots = credentials_robots(credentials)
        secure = {"dictionary_file": str(Path(credentials) / DICTIONARY),
                  "access_control": acl_config(prefix, robots, mtls=on_tls)}
        log.info("authentication on, access control for %d robots under %s/", robots, prefix)
    else:
        log.warning("no credentials: any client may connect and publish on any key")
    if on_tls:
        assert credentials is not None
        secure["tls"] = router_tls(credentials)
        zenoh.init_log_from_env_or("warn")  # refused handshakes (unknown CA, no certificate)
        log.info("mutual TLS: certificate for %s", ", ".join(router_names(credentials)))
        check_tcp_retries2()
    elif credentials is not None:
        log.warning("plain TCP: logins and traffic are not encrypted (bus.tls=false)")
    session = zenoh.open(zenoh_config("router", listen=listen, lease_s=lease_s, **secure))
    log.info("zenoh router listening on %s", ", ".join(listen))
    try:
        stop.wait()
    finally:
        session.close()
