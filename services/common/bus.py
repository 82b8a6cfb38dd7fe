"""The zenoh shell shared by every service: session flags, one ordered inbox, safe decoding.

Every subscriber pushes raw samples into one FIFO inbox; the service's main loop drains it in
arrival order, so its state depends only on message order (the lockstep determinism argument
in ARCHITECTURE.md). Decoding validates; a bad message is logged once per (key, reason),
counted, and dropped.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
from collections import Counter, deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Literal

import zenoh
from pydantic import BaseModel, ConfigDict, Field

from schemas import DecodeError, Keys, decode, encode
from schemas.arrays import DEFAULT_MAX_ARRAY_BYTES
from schemas.messages import Message
from services.common.access import load_credential
from services.common.inbox import Inbox
from services.common.liveliness import LivelinessWatch
from services.common.tls import TLS_KEY, TlsError, client_tls, is_tls

log = logging.getLogger(__name__)

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


class BusConfig(BaseModel):
    """How a process joins the bus."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    prefix: str = "spacemap"
    connect: str = Field(default=DEFAULT_ENDPOINT, description="router endpoint to connect to")
    shared_memory: bool = Field(default=False, description="zenoh SHM; never needed")
    max_array_bytes: int = Field(default=DEFAULT_MAX_ARRAY_BYTES, gt=0)
    connect_timeout_s: float = Field(default=30.0, gt=0)
    lease_s: float = Field(
        default=10.0, gt=0, description="a silent peer is declared gone after this long"
    )
    credentials: str | None = Field(
        default=None,
        description="folder from `spacemap credentials`: each process logs in as its own "
        "user from it (the router reads its dictionary); None: no authentication",
    )
    tls: bool = Field(
        default=True,
        description="with credentials, links must be TLS (tls/ endpoints; mutual TLS with "
        "the folder's CA and each user's certificate); false allows plain tcp/ (logins "
        "and access control still apply, the traffic is not encrypted)",
    )


CHANNEL_CAPACITY = 65536  # messages a `subscribe(channel=True)` queue holds before it blocks
CONNECT_RETRY = {"period_init_ms": 50, "period_max_ms": 1000, "period_increase_factor": 2}


def zenoh_config(
    mode: Literal["client", "peer", "router"],
    connect: list[str] | None = None,
    listen: list[str] | None = None,
    shared_memory: bool = False,
    connect_timeout_s: float = 30.0,
    lease_s: float = 10.0,
    login: tuple[str, str] | None = None,
    dictionary_file: str | None = None,
    access_control: dict[str, Any] | None = None,
    tls: dict[str, object] | None = None,
) -> zenoh.Config:
    """The one set of session flags every spacemap process uses. `login` (user, password):
    a client's identity; `dictionary_file` and `access_control`: the router's; `tls`: the
    `transport/link/tls` settings (services.common.tls), which also limit links to TLS."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    conf.insert_json5("transport/shared_memory/enabled", json.dumps(shared_memory))
    conf.insert_json5("transport/link/tx/lease", json.dumps(int(lease_s * 1000)))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(connect))
        conf.insert_json5("connect/timeout_ms", json.dumps(int(connect_timeout_s * 1000)))
        conf.insert_json5("connect/exit_on_failure", "true")
        # zenoh retries a refused connect after 1 s at first: a mission's services start
        # beside their router and would each wait that second for it to listen
        conf.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps(listen))
    if login is not None:
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(login[0]))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(login[1]))
    if dictionary_file is not None:
        conf.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(dictionary_file))
    if access_control is not None:
        conf.insert_json5("access_control", json.dumps(access_control))
    if tls is not None:
        conf.insert_json5("transport/link/protocols", json.dumps(["tls"]))
        for name, value in tls.items():
            conf.insert_json5(f"{TLS_KEY}/{name}", json.dumps(value))
    return conf


def login_for(config: BusConfig, identity: str | None) -> tuple[str, str] | None:
    """(user, password) of `identity` from the config's credentials folder, if it has one."""
    if config.credentials is None:
        return None
    if identity is None:
        raise ValueError("bus.credentials is set but this process has no identity")
    cred = load_credential(config.credentials, identity)
    return cred.user, cred.password


def tls_for(config: BusConfig, identity: str | None) -> dict[str, object] | None:
    """The client TLS settings of `identity` for `config.connect`, None on a plain link;
    TlsError when the endpoint and the config disagree or a certificate is unusable."""
    if is_tls(config.connect):
        if config.credentials is None or identity is None:
            raise TlsError(f"{config.connect} is a TLS endpoint: set bus.credentials to a "
                           "folder from `spacemap credentials` (its CA and this process's "
                           "certificate)")
        return client_tls(config.credentials, identity)
    if config.tls and config.credentials is not None:
        raise TlsError(f"bus.tls is on but bus.connect is {config.connect!r}: connect with "
                       "tls/HOST:PORT, or set bus.tls=false to send logins over plain TCP")
    return None


@contextmanager
def open_session(config: BusConfig, identity: str | None = None) -> Iterator[zenoh.Session]:
    """A client session connected to the router of `config`, logged in as `identity`
    (services.common.access.identity) when the config names a credentials folder, over
    mutual TLS when `config.connect` is a tls/ endpoint."""
    login = login_for(config, identity)
    tls = tls_for(config, identity)
    try:
        session = zenoh.open(
            zenoh_config(
                "client",
                connect=[config.connect],
                shared_memory=config.shared_memory,
                connect_timeout_s=config.connect_timeout_s,
                lease_s=config.lease_s,
                login=login,
                tls=tls,
            )
        )
    except zenoh.ZError:
        if tls is not None:  # zenoh only says "timeout": name what to check
            log.error("no TLS session with %s as %s: the router must run with a certificate "
                      "from the same `spacemap credentials` folder as %s, made for this host "
                      "name (--router-host); the router's log names the refused handshake",
                      config.connect, identity, tls["root_ca_certificate"])
        raise
    try:
        yield session
    finally:
        session.close()


def _direct(callback: Callable[[zenoh.Sample], None]) -> zenoh.handlers.Callback:
    """Run `callback` on zenoh's receive thread. zenoh-python's default ("indirect") gives
    each subscriber its own thread, which loses the order between keys that the lockstep
    determinism relies on; our callbacks only enqueue, so running them inline is safe."""
    return zenoh.handlers.Callback(callback, indirect=False)


@dataclass(frozen=True)
class Inbound:
    """One decoded message from the inbox."""

    key: str
    message: Message


@dataclass(frozen=True)
class Presence:
    """A liveliness change: `alive` False means the process is gone."""

    role: str
    ident: str
    alive: bool


class Bus:
    """A service's view of the bus: publish, subscribe into one inbox, liveliness, queries."""

    def __init__(self, session: zenoh.Session, config: BusConfig) -> None:
        self.session = session
        self.config = config
        self.keys = Keys(config.prefix)
        self.inbox: Inbox[tuple[str, str, bytes | bool, type[Message] | None]] = Inbox()
        self.dropped: Counter[str] = Counter()
        self.bytes_out: Counter[str] = Counter()
        self._logged: set[tuple[str, str]] = set()
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._handles: list[object] = []
        self._liveliness: LivelinessWatch | None = None
        self._own_tokens: list[str] = []  # alive/** keys this session declared
        self._lock = threading.Lock()
        # subscriptions read into `poll` from zenoh's own queues (`subscribe(channel=True)`)
        self._channels: list[tuple[zenoh.Subscriber, type[Message],
                                   Callable[[bytes], bool] | None]] = []
        self._ready: deque[tuple[str, str, bytes | bool, type[Message] | None]] = deque()
        self._entry_ready = False  # `_ready` ends with an entry taken from the inbox

    # -- inbound ---------------------------------------------------------------------------
    def subscribe(self, key_expr: str, model: type[Message],
                  keep: Callable[[bytes], bool] | None = None, wake: bool = True,
                  channel: bool = False) -> None:
        """Queue every message on `key_expr` for `poll` (decoded and validated there);
        `keep`, when given, sees each raw payload on the receive thread first and drops
        those it returns False for (a cheap sampler of heavy traffic, e.g. cameras).
        `wake=False`: the messages keep their place in the inbox without waking a waiting
        `poll` (frequent ones the service only needs when something else arrives).
        `channel=True`: they wait in zenoh's own queue instead, which takes no Python on the
        receive thread; `poll` reads them all just after it takes an item from the inbox
        and returns them before it. So each comes before every item that arrived after it
        (and before some that arrived just before it): enough for messages applied by their
        stamp, not by their place in line."""
        if channel:
            sub = self.session.declare_subscriber(key_expr, zenoh.handlers.FifoChannel(
                CHANNEL_CAPACITY))
            self._handles.append(sub)
            self._channels.append((sub, model, keep))
            return

        def on_sample(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            if keep is None or keep(payload):
                self.inbox.put(("msg", str(sample.key_expr), payload, model), wake)

        self._handles.append(self.session.declare_subscriber(key_expr, _direct(on_sample)))

    def tap(self, key_expr: str, on_payload: Callable[[str, bytes], None]) -> None:
        """Raw payloads on `key_expr`, undecoded, in arrival order (runs on a zenoh thread)."""

        def on_sample(sample: zenoh.Sample) -> None:
            on_payload(str(sample.key_expr), sample.payload.to_bytes())

        self._handles.append(self.session.declare_subscriber(key_expr, _direct(on_sample)))

    def watch_liveliness(self) -> None:
        """Push a Presence for every current and future `alive/**` token, and for a token
        the router dropped without its DELETE reaching us (services.common.liveliness)."""
        if self._liveliness is None:
            self._liveliness = LivelinessWatch(
                self.session, self.keys.alive_all(),
                lambda key, alive: self.inbox.put(("alive", key, alive, None)),
                interval_s=max(1.0, self.config.lease_s / 2),
                own=lambda: set(self._own_tokens),
            )

    def declare_alive(self, role: str, ident: int | str = 0) -> None:
        key = self.keys.alive(role, ident)
        self._handles.append(self.session.liveliness().declare_token(key))
        self._own_tokens.append(key)

    def poll(self, timeout: float | None = None) -> Inbound | Presence | None:
        """Next valid inbound item, or None when `timeout` passes with nothing valid."""
        if not self._ready:
            try:
                entry = self.inbox.get(timeout=timeout)
            except queue.Empty:
                entry = None
            self._read_channels()  # what came before `entry` (and a little after) first
            if entry is not None:
                self._ready.append(entry)
                self._entry_ready = True
            if not self._ready:
                return None
        tag, key, payload, model = self._ready.popleft()
        if not self._ready:
            self._entry_ready = False  # the inbox's entry is always the last one read
        if tag == "alive":
            role, ident = self.keys.alive_member(key)
            return Presence(role, ident, bool(payload))
        assert isinstance(payload, bytes) and model is not None
        try:
            return Inbound(key, decode(payload, model, self.config.max_array_bytes))
        except DecodeError as exc:
            self.reject(key, exc)
            return None

    def _read_channels(self) -> None:
        for sub, model, keep in self._channels:
            while (sample := sub.try_recv()) is not None:
                payload = sample.payload.to_bytes()
                if keep is None or keep(payload):
                    self._ready.append(("msg", str(sample.key_expr), payload, model))

    def input_waiting(self) -> bool:
        """Whether an inbound item that wakes `poll` is in line (quiet ones do not count)."""
        return self._entry_ready or self.inbox.woken()

    def drain(self) -> Iterator[Inbound | Presence]:
        """Every item already in the inbox, in order, without waiting."""
        self._read_channels()
        while self._ready or not self.inbox.empty():
            item = self.poll(timeout=0)
            if item is not None:
                yield item

    def reject(self, key: str, error: DecodeError) -> None:
        self.dropped[error.reason] += 1
        if (key, error.reason) not in self._logged:
            self._logged.add((key, error.reason))
            log.warning("dropped message on %s: %s", key, error)

    # -- outbound --------------------------------------------------------------------------
    def publish(self, key: str, message: Message) -> int:
        """Encode and publish reliably (congestion control BLOCK); returns payload bytes."""
        payload = encode(message)
        with self._lock:
            pub = self._publishers.get(key)
            if pub is None:
                pub = self.session.declare_publisher(
                    key,
                    congestion_control=zenoh.CongestionControl.BLOCK,
                    reliability=zenoh.Reliability.RELIABLE,
                )
                self._publishers[key] = pub
            pub.put(payload)
            self.bytes_out[key] += len(payload)
        return len(payload)

    def serve(self, key: str, answer: Callable[[bytes], Message]) -> None:
        """A queryable at `key`; `answer` gets the query payload and returns the reply."""

        def on_query(query: zenoh.Query) -> None:
            body = query.payload.to_bytes() if query.payload is not None else b""
            try:
                query.reply(key, encode(answer(body)))
            except DecodeError as exc:
                self.reject(key, exc)
                query.reply_err(str(exc).encode())

        self._handles.append(self.session.declare_queryable(key, on_query))

    def query(
        self, key: str, request: Message | None, model: type[Message], timeout: float
    ) -> Message:
        """One reply to a `get`, decoded and validated; TimeoutError when none comes."""
        payload = encode(request) if request is not None else None
        for reply in self.session.get(key, payload=payload, timeout=timeout):
            if reply.ok is not None:
                return decode(reply.ok.payload.to_bytes(), model, self.config.max_array_bytes)
        raise TimeoutError(f"no reply on {key} within {timeout} s")

    def close(self) -> None:
        if self._liveliness is not None:
            self._liveliness.close()
            self._liveliness = None
        self._read_channels()  # what zenoh's queues hold is counted below with the rest
        self._channels.clear()
        for handle in reversed(self._handles):
            undeclare = getattr(handle, "undeclare", None)
            if undeclare is not None:
                undeclare()
        self._handles.clear()
        self._own_tokens.clear()
        # what arrived but was never polled is validated too, so every bad message is counted
        # (a process stopped while busy would otherwise under-report)
        left = sum(1 for _ in self.drain())
        if left:
            log.info("%d valid inbound messages left unhandled at exit", left)
        if self.dropped:  # the count behind the log-once warnings, for the record
            log.warning("dropped %d bad messages in all: %s", self.dropped.total(),
                        json.dumps(dict(sorted(self.dropped.items()))))


@contextmanager
def connect(config: BusConfig, identity: str | None = None) -> Iterator[Bus]:
    """Open a session to the router (as `identity`) and wrap it in a Bus."""
    with open_session(config, identity) as session:
        bus = Bus(session, config)
        try:
            yield bus
        finally:
            bus.close()
