"""The generated access control enforced by a real router (`spacemap router`, its own OS
process, on loopback, mutual TLS as by default): every forbidden publish, subscription,
queryable and liveliness token of every user is refused, every granted one goes through; no
login, no session."""

from __future__ import annotations

import json
import shutil
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest
import zenoh

from schemas.keys import Keys, role_keys
from services.common.access import identities, make_credentials
from services.common.bus import BusConfig, login_for, open_session, zenoh_config
from services.common.tls import client_tls
from services.processes import ProcessGroup, free_tcp_port, spacemap_command
from tests.test_access import every_key, matches

pytestmark = pytest.mark.multiprocess

ROBOTS = 2
KEYS = Keys("spacemap")
Received = dict[str, list[tuple[str, bytes]]]


def wait_until(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(0.02)


@contextmanager
def secure_router(tmp: Path, tls: bool = True) -> Iterator[BusConfig]:
    """`spacemap router` with fresh credentials in `tmp`, on loopback (tls/ unless `tls` is
    False); yields the config a client of it uses, once the router accepts sessions."""
    make_credentials(tmp / "cred", ROBOTS)
    endpoint = f"{'tls' if tls else 'tcp'}/127.0.0.1:{free_tcp_port()}"
    group = ProcessGroup(tmp / "logs")
    group.start("router", spacemap_command(
        "router", "--listen", endpoint, "--set", f"bus.credentials={tmp / 'cred'}",
        "--set", f"bus.tls={str(tls).lower()}"))
    config = BusConfig(connect=endpoint, credentials=str(tmp / "cred"), connect_timeout_s=20,
                       tls=tls)
    try:
        with open_session(config, "monitor"):  # the router is up
            pass
        yield config
    finally:
        codes = group.stop()
    assert codes == {"router": 0}, (tmp / "logs" / "router.log").read_text()[-2000:]


@pytest.fixture(scope="module")
def router(tmp_path_factory: pytest.TempPathFactory) -> Iterator[BusConfig]:
    with secure_router(tmp_path_factory.mktemp("acl")) as config:
        yield config


def grants(user: str):  # noqa: ANN201 - RoleKeys
    role, ident = identities(ROBOTS)[user]
    return role_keys(KEYS, role, ident, ROBOTS)


def owner(key: str) -> str | None:
    found = [u for u in identities(ROBOTS) if any(matches(p, key) for p in grants(u).publish)]
    return found[0] if found else None


def test_matrix_on_a_real_router(router: BusConfig) -> None:
    users = list(identities(ROBOTS))
    keys = [k for k in every_key(ROBOTS) if "/alive/" not in k]
    got: Received = {u: [] for u in users}  # through each user's own subscriptions
    spied: Received = {u: [] for u in users}  # through a `spacemap/**` spy with its login
    lock = threading.Lock()

    def recorder(into: list[tuple[str, bytes]]) -> zenoh.handlers.Callback:
        def on_sample(sample: zenoh.Sample) -> None:
            with lock:
                into.append((str(sample.key_expr), sample.payload.to_bytes()))
        return zenoh.handlers.Callback(on_sample, indirect=False)

    with ExitStack() as stack:
        sessions = {u: stack.enter_context(open_session(router, u)) for u in users}
        spies = {u: stack.enter_context(open_session(router, u)) for u in users}
        for user in users:
            for expr in grants(user).subscribe:
                sessions[user].declare_subscriber(expr, recorder(got[user]))
            spies[user].declare_subscriber("spacemap/**", recorder(spied[user]))
        # a queryable and a token in another's name must not be reachable
        for user in users:  # only the edge's may answer (the monitor asks, from its session)
            if user != "monitor":
                sessions[user].declare_queryable(
                    KEYS.map_cloud(), lambda q, u=user: q.reply(KEYS.map_cloud(), u.encode()))
        tokens = [sessions["agent-0"].liveliness().declare_token(KEYS.alive("edge", 0)),
                  sessions["sim"].liveliness().declare_token(KEYS.alive("agent", 1)),
                  sessions["agent-1"].liveliness().declare_token(KEYS.alive("agent", 1))]
        # liveliness declarations settle before the routing of puts matters
        wait_until(lambda: any(True for _ in sessions["monitor"].liveliness().get(
            KEYS.alive("agent", 1), timeout=2)), 10, "agent-1's own token")

        forged = 0
        for user in users:
            for key in keys:
                if owner(key) != user:
                    sessions[user].put(key, f"forged by {user}".encode())
                    forged += 1
        for user in users:  # a round trip per sender: its forged puts are routed by now
            list(sessions[user].liveliness().get(KEYS.alive_all(), timeout=2))
        owned = [k for k in keys if owner(k) is not None]
        for key in owned:
            sessions[owner(key)].put(key, b"owner")

        def owners_arrived() -> bool:
            with lock:
                return all((key, b"owner") in got[u] for key in owned for u in users
                           if any(matches(p, key) for p in grants(u).subscribe))
        wait_until(owners_arrived, 20, "every owner's put at every granted subscriber")

        with lock:
            # a session's own puts reach its own subscribers without the router: not counted
            bad = {u: [m for m in got[u] if m[1] not in (b"owner", f"forged by {u}".encode())]
                   for u in users}
            leaked = {u: sorted({k for k, _ in spied[u]
                                 if not any(matches(p, k) for p in grants(u).subscribe)})
                      for u in users}
        assert forged > 100
        assert all(not v for v in bad.values()), f"forged puts delivered: {bad}"
        assert all(not v for v in leaked.values()), f"delivered beyond grants: {leaked}"

        replies = {r.ok.payload.to_bytes() for r in sessions["monitor"].get(
            KEYS.map_cloud(), timeout=2) if r.ok is not None}
        assert replies == {b"edge"}, f"map/cloud answered by {replies}"
        alive = {str(r.ok.key_expr) for r in sessions["monitor"].liveliness().get(
            KEYS.alive_all(), timeout=2) if r.ok is not None}
        assert alive == {KEYS.alive("agent", 1)}, f"forged liveliness tokens seen: {alive}"
        del tokens


def login_folder(router: BusConfig, into: Path, login: str) -> tuple[str, str | None]:
    """A copy of the router's credentials folder that holds a bad login for `login`:
    (user to log in as, folder or None); certificates stay valid, so only the login fails."""
    if login == "none":
        return "agent-0", None
    shutil.copytree(str(router.credentials), into)
    if login == "wrong password":
        cred = json.loads((into / "agent-0.json").read_text())
        (into / "agent-0.json").write_text(json.dumps({**cred, "password": "x" * 32}))
        return "agent-0", str(into)
    for ext in ("pem", "key"):  # a stranger holding agent-0's certificate
        shutil.copy(into / f"agent-0.{ext}", into / f"stranger.{ext}")
    (into / "stranger.json").write_text(
        (into / "sim.json").read_text().replace('"sim"', '"stranger"'))
    return "stranger", str(into)


@pytest.mark.parametrize("login", ["none", "wrong password", "unknown user"])
def test_no_login_no_session(router: BusConfig, login: str, tmp_path: Path) -> None:
    """A client that passes TLS (the mission's CA, a certificate it signed) but has no valid
    login gets no session: the password check is not replaced by the certificate."""
    user, folder = login_folder(router, tmp_path / "other", login)
    assert router.credentials is not None
    tls = client_tls(router.credentials, "agent-0")
    conf = zenoh_config("client", connect=[router.connect], connect_timeout_s=2.0, tls=tls,
                        login=None if folder is None else login_for(
                            router.model_copy(update={"credentials": folder}), user))
    with pytest.raises(zenoh.ZError), zenoh.open(conf) as session:
        session.put(KEYS.cmd_vel(0), b"x")
