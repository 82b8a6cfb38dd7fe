"""TLS on every link (issue 14): the certificates `spacemap credentials` makes, the checks that
name a bad file, and a real `spacemap router` on loopback that only a client with the
mission's CA and its own certificate reaches."""

from __future__ import annotations

import shutil
import socket
import ssl
import stat
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh
from cryptography import x509

from schemas.keys import Keys
from services.common.access import acl_config, identities, make_credentials
from services.common.bus import BusConfig, login_for, open_session, tls_for, zenoh_config
from services.common.router import _check_links, default_listen, run_router
from services.common.tls import (
    CA,
    TlsError,
    client_tls,
    common_name,
    router_names,
    router_tls,
)
from services.processes import free_tcp_port
from tests.test_access_router import secure_router

KEYS = Keys("spacemap")


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("tls") / "cred"
    make_credentials(out, 2, router_hosts=["192.0.2.10", "fleet.example"])
    return out


def test_certificates(folder: Path) -> None:
    ca = x509.load_pem_x509_certificate((folder / CA).read_bytes())
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    assert not list(folder.glob("ca*.key")), "the CA's private key must not be kept"
    assert set(router_names(folder)) >= {"localhost", "127.0.0.1", "router", "192.0.2.10",
                                         "fleet.example"}
    for user in identities(2):
        assert common_name(folder / f"{user}.pem") == user
        x509.load_pem_x509_certificate((folder / f"{user}.pem").read_bytes()
                                       ).verify_directly_issued_by(ca)
        assert stat.S_IMODE((folder / f"{user}.key").stat().st_mode) == 0o600
        assert client_tls(folder, user)["enable_mtls"] is True
    assert router_tls(folder)["listen_certificate"] == str(folder / "router.pem")


def broken(folder: Path, into: Path, how: str) -> Path:
    """A copy of `folder` with one thing wrong with agent-0's certificate or the CA."""
    shutil.copytree(folder, into)
    if how == "missing CA":
        (into / CA).unlink()
    elif how == "garbage certificate":
        (into / "agent-0.pem").write_text("-----BEGIN CERTIFICATE-----\nnope\n")
    elif how == "missing key":
        (into / "agent-0.key").unlink()
    elif how == "someone else's key":
        shutil.copy(into / "agent-1.key", into / "agent-0.key")
    elif how == "another CA":
        make_credentials(into.parent / "other", 2)
        shutil.copy(into.parent / "other" / CA, into / CA)
    return into


@pytest.mark.parametrize("how, says", [
    ("missing CA", "ca.pem is missing"), ("garbage certificate", "not a readable PEM"),
    ("missing key", "private key .* is missing"), ("someone else's key", "does not belong"),
    ("another CA", "was not signed by"),
])
def test_bad_files_are_named(folder: Path, tmp_path: Path, how: str, says: str) -> None:
    bad = broken(folder, tmp_path / "bad", how)
    with pytest.raises(TlsError, match=says):
        client_tls(bad, "agent-0")


def test_endpoint_and_config_must_agree(folder: Path) -> None:
    with pytest.raises(TlsError, match="bus.tls is on"):
        tls_for(BusConfig(connect="tcp/127.0.0.1:7447", credentials=str(folder)), "sim")
    with pytest.raises(TlsError, match="set bus.credentials"):
        tls_for(BusConfig(connect="tls/127.0.0.1:7447"), None)
    assert tls_for(BusConfig(connect="tcp/127.0.0.1:7447", credentials=str(folder),
                             tls=False), "sim") is None
    assert tls_for(BusConfig(), None) is None  # no credentials: anonymous plain TCP
    assert _check_links(["tls/0.0.0.0:7447"], str(folder), tls=True)
    for listen, creds, tls in ((["tls/a:1", "tcp/a:2"], str(folder), True),
                               (["tls/a:1"], None, True), (["tcp/a:1"], str(folder), True)):
        with pytest.raises(TlsError):
            _check_links(listen, creds, tls)
    assert default_listen(str(folder), True) == ["tls/0.0.0.0:7447"]
    assert default_listen(None, True) == ["tcp/0.0.0.0:7447"]


def test_acl_binds_login_and_certificate() -> None:
    for mtls in (False, True):
        subjects = acl_config("spacemap", 2, mtls=mtls)["subjects"]
        for subject in subjects:
            assert subject["usernames"] == [subject["id"]]
            assert subject.get("cert_common_names") == ([subject["id"]] if mtls else None)


# -- a real router on loopback ---------------------------------------------------------------

@pytest.fixture(scope="module")
def router(tmp_path_factory: pytest.TempPathFactory) -> Iterator[BusConfig]:
    with secure_router(tmp_path_factory.mktemp("tls-router")) as config:
        yield config


def port(config: BusConfig) -> int:
    return int(config.connect.rsplit(":", 1)[1])


def wait_until(condition: Callable[[], bool], timeout_s: float) -> bool:
    """True once `condition` holds, False when `timeout_s` passes first."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def delivered(router: BusConfig, sender: zenoh.Session, robot: int, payload: bytes) -> bool:
    """Does `payload`, put once by `sender` on robot `robot`'s cmd_vel, reach the sim?
    In order, each step waited for with a deadline: the sender learns of the sim's
    subscriber (a sender the router admits to no subject never does: it puts anyway after
    3 s), puts, and round-trips through the router (its put is routed by then); then the
    key's owner puts a marker, which the router forwards to the sim after the sender's put:
    when the marker is there, so is the put, if it passed."""
    key = KEYS.cmd_vel(robot)
    got: list[bytes] = []
    with open_session(router, "sim") as sim, open_session(router, f"agent-{robot}") as owner:
        sim.declare_subscriber(key, zenoh.handlers.Callback(
            lambda s: got.append(s.payload.to_bytes()), indirect=False))
        publisher = sender.declare_publisher(key)
        wait_until(lambda: publisher.matching_status.matching, 3)
        publisher.put(payload)
        list(sender.liveliness().get(KEYS.alive_all(), timeout=5))
        owner.put(key, b"marker")
        assert wait_until(lambda: b"marker" in got, 10), "the owner's marker never came"
        publisher.undeclare()
        return payload in got


@pytest.mark.multiprocess
def test_tls_client_exchanges_messages(router: BusConfig) -> None:
    with open_session(router, "agent-0") as agent:
        assert delivered(router, agent, 0, b"agent-0 over TLS")


@pytest.mark.multiprocess
def test_the_port_speaks_tls_with_the_mission_ca(router: BusConfig, tmp_path: Path) -> None:
    """Python's own TLS stack, independent of zenoh: the router's port completes a handshake
    for a client that trusts the mission's CA and shows its certificate, and presents a
    certificate no other CA vouches for."""
    assert router.credentials is not None
    folder = Path(router.credentials)
    ctx = ssl.create_default_context(cafile=str(folder / CA))
    ctx.load_cert_chain(folder / "agent-0.pem", folder / "agent-0.key")
    with socket.create_connection(("127.0.0.1", port(router)), timeout=5) as raw, \
            ctx.wrap_socket(raw, server_hostname="localhost") as tls:
        peer = x509.load_der_x509_certificate(tls.getpeercert(binary_form=True))
        assert "127.0.0.1" in {str(v) for v in peer.extensions.get_extension_for_class(
            x509.SubjectAlternativeName).value.get_values_for_type(x509.IPAddress)}
    make_credentials(tmp_path / "other", 2)
    other = ssl.create_default_context(cafile=str(tmp_path / "other" / CA))
    with socket.create_connection(("127.0.0.1", port(router)), timeout=5) as raw, \
            pytest.raises(ssl.SSLCertVerificationError):
        other.wrap_socket(raw, server_hostname="localhost")


@pytest.mark.multiprocess
@pytest.mark.parametrize("client", ["plain tcp", "wrong CA", "no certificate"])
def test_no_session_without_tls_and_the_mission_ca(router: BusConfig, tmp_path: Path,
                                                   client: str) -> None:
    """Each with agent-0's valid login: plain TCP to the TLS-only port, a client whose CA
    and certificate come from another `spacemap credentials` run, and a client that trusts
    the right CA but shows no certificate."""
    assert router.credentials is not None
    login = login_for(router, "agent-0")
    endpoint, tls = router.connect, client_tls(router.credentials, "agent-0")
    if client == "plain tcp":
        endpoint, tls = endpoint.replace("tls/", "tcp/"), None
    elif client == "wrong CA":
        make_credentials(tmp_path / "other", 2)
        tls = client_tls(tmp_path / "other", "agent-0")
    else:
        tls = {"root_ca_certificate": tls["root_ca_certificate"]}
    conf = zenoh_config("client", connect=[endpoint], connect_timeout_s=2.0, login=login,
                        tls=tls)
    with pytest.raises(zenoh.ZError), zenoh.open(conf):
        pass


@pytest.mark.multiprocess
def test_a_login_with_another_users_certificate_speaks_for_no_one(router: BusConfig,
                                                                 tmp_path: Path) -> None:
    """agent-0's password with agent-1's certificate: TLS and the login both pass, but the
    access rules want both to name the same user, so its puts on agent-0's keys are
    dropped (with rules bound to the login alone they pass: the test fails)."""
    assert router.credentials is not None
    swapped = zenoh_config("client", connect=[router.connect], connect_timeout_s=5.0,
                           login=login_for(router, "agent-0"),
                           tls=client_tls(router.credentials, "agent-1"))
    with zenoh.open(swapped) as rogue:
        assert not delivered(router, rogue, 0, b"swapped certificate")


@pytest.mark.multiprocess
def test_the_router_name_is_checked(folder: Path) -> None:
    """A router listening on two loopback addresses, its certificate made for 127.0.0.1
    only: a client that dials 127.0.0.2 refuses the router (the name is verified), the same
    client dialling 127.0.0.1 connects."""
    port_ = free_tcp_port()
    stop = threading.Event()
    serve = threading.Thread(target=run_router, args=(
        [f"tls/127.0.0.1:{port_}", f"tls/127.0.0.2:{port_}"], stop),
        kwargs={"credentials": str(folder)}, daemon=True)
    serve.start()
    try:
        ok = BusConfig(connect=f"tls/127.0.0.1:{port_}", credentials=str(folder),
                       connect_timeout_s=10)
        with open_session(ok, "sim"):
            pass
        other = ok.model_copy(update={"connect": f"tls/127.0.0.2:{port_}",
                                      "connect_timeout_s": 2.0})
        with pytest.raises(zenoh.ZError), open_session(other, "sim"):
            pass
    finally:
        stop.set()
        serve.join(timeout=10)


@pytest.mark.parametrize("command", [["health", "--role", "sim", "--as", "agent-0"],
                                     ["inventory", "--robots", "1"]])
def test_cli_names_the_bad_file(folder: Path, tmp_path: Path, command: list[str]) -> None:
    """A command with a user's key missing: one line naming the file, status 2."""
    from typer.testing import CliRunner

    from services.cli import app

    bad = broken(folder, tmp_path / "bad", "missing key")
    shutil.copy(bad / "agent-0.pem", bad / "monitor.pem")  # monitor: a foreign key
    result = CliRunner().invoke(app, [*command, "--connect", "tls/127.0.0.1:9",
                                      "--set", f"bus.credentials={bad}"])
    assert result.exit_code == 2, result.output
    assert ("agent-0.key is missing" in result.output if "health" in command
            else "monitor.key does not belong" in result.output), result.output
