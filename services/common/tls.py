"""TLS on every link: a mission's certificate authority, the router's server certificate, one
client certificate per user (mutual TLS, the user name as the common name), and the zenoh
`transport/link/tls` settings that use them.

`spacemap credentials` writes these files into the credentials folder beside the logins
(services/common/access.py): `ca.pem`, `router.pem` + `router.key`, `{user}.pem` +
`{user}.key`. The CA's private key is never written: to add a host or a robot, make the
whole folder again. Every file is checked before zenoh sees it, so a missing, unreadable,
expired or foreign certificate fails with a message that names the file.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
from collections.abc import Iterable
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

CA = "ca.pem"
ROUTER = "router"  # router.pem, router.key: the server certificate
ROUTER_HOSTS = ("localhost", "127.0.0.1", "::1", "router")  # loopback and compose's service
DEFAULT_DAYS = 365
TLS_KEY = "transport/link/tls"


class TlsError(ValueError):
    """A certificate or key that cannot be used (missing, unreadable, expired, not ours)."""


def scheme(endpoint: str) -> str:
    """The protocol of a zenoh endpoint: `tls/host:port` → `tls`."""
    return endpoint.split("/", 1)[0] if "/" in endpoint else ""


def is_tls(endpoint: str) -> bool:
    return scheme(endpoint) == "tls"


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _san(host: str) -> x509.GeneralName:
    try:
        return x509.IPAddress(ipaddress.ip_address(host))
    except ValueError:
        return x509.DNSName(host)


def _write(path: Path, data: bytes, private: bool) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600 if private else 0o644)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)


def _builder(subject: x509.Name, issuer: x509.Name, key: ec.EllipticCurvePrivateKey,
             days: int) -> x509.CertificateBuilder:
    now = dt.datetime.now(dt.UTC)
    return (x509.CertificateBuilder().subject_name(subject).issuer_name(issuer)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5))
            .not_valid_after(now + dt.timedelta(days=days)))


def _leaf(out: Path, stem: str, ca_key: ec.EllipticCurvePrivateKey, ca: x509.Certificate,
          days: int, server_hosts: Iterable[str] | None) -> None:
    """`{stem}.pem` + `{stem}.key` signed by the CA: a server certificate for `server_hosts`
    (subject alternative names), else a client certificate with common name `stem`."""
    key = ec.generate_private_key(ec.SECP256R1())
    usage = ExtendedKeyUsageOID.SERVER_AUTH if server_hosts is not None else (
        ExtendedKeyUsageOID.CLIENT_AUTH)
    builder = (_builder(_name(stem), ca.subject, key, days)
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
               .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(
                   ca_key.public_key()), critical=False))
    if server_hosts is not None:
        sans = [_san(h) for h in dict.fromkeys(server_hosts)]
        builder = builder.add_extension(x509.SubjectAlternativeName(sans), critical=False)
    cert = builder.sign(ca_key, hashes.SHA256())
    _write(out / f"{stem}.key", key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption()), private=True)
    _write(out / f"{stem}.pem", cert.public_bytes(serialization.Encoding.PEM), private=False)


def make_certificates(out: Path, users: Iterable[str], router_hosts: Iterable[str] = (),
                      days: int = DEFAULT_DAYS) -> None:
    """A fresh CA (`ca.pem`; its key is dropped), the router's certificate valid for
    loopback, `router` and `router_hosts`, and a client certificate per user."""
    if days < 1:
        raise ValueError("certificates must be valid for at least one day")
    ca_key = ec.generate_private_key(ec.SECP256R1())
    subject = _name(f"spacemap mission CA {os.urandom(4).hex()}")
    ca = (_builder(subject, subject, ca_key, days)
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .add_extension(x509.KeyUsage(
              digital_signature=True, key_cert_sign=True, crl_sign=True,
              content_commitment=False, key_encipherment=False, data_encipherment=False,
              key_agreement=False, encipher_only=False, decipher_only=False), critical=True)
          .add_extension(x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()),
                         critical=False)
          .sign(ca_key, hashes.SHA256()))
    _write(out / CA, ca.public_bytes(serialization.Encoding.PEM), private=False)
    _leaf(out, ROUTER, ca_key, ca, days, [*ROUTER_HOSTS, *router_hosts])
    for user in users:
        _leaf(out, user, ca_key, ca, days, None)


def _load_cert(path: Path, what: str) -> x509.Certificate:
    try:
        cert = x509.load_pem_x509_certificate(path.read_bytes())
    except FileNotFoundError as exc:
        raise TlsError(f"{what}: {path} is missing (make the credentials folder with "
                       "`spacemap credentials`, or set bus.tls=false for plain TCP)") from exc
    except (OSError, ValueError) as exc:
        raise TlsError(f"{what}: {path} is not a readable PEM certificate ({exc})") from exc
    now = dt.datetime.now(dt.UTC)
    if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
        raise TlsError(f"{what}: {path} is valid only from {cert.not_valid_before_utc:%F %T} "
                       f"to {cert.not_valid_after_utc:%F %T} UTC (make new credentials)")
    return cert


def _check_pair(folder: Path, stem: str, what: str) -> tuple[str, str]:
    """(certificate, key) paths of `stem`, checked: both load, the key matches the
    certificate, and the folder's CA signed it."""
    ca = _load_cert(folder / CA, "CA certificate")
    cert = _load_cert(folder / f"{stem}.pem", what)
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature) as exc:
        raise TlsError(f"{what}: {folder / f'{stem}.pem'} was not signed by {folder / CA} "
                       "(files from two runs of `spacemap credentials`?)") from exc
    key_path = folder / f"{stem}.key"
    try:
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except FileNotFoundError as exc:
        raise TlsError(f"{what}: private key {key_path} is missing") from exc
    except (OSError, ValueError, TypeError) as exc:
        raise TlsError(f"{what}: {key_path} is not a readable PEM private key ({exc})") from exc
    if key.public_key() != cert.public_key():
        raise TlsError(f"{what}: {key_path} does not belong to {folder / f'{stem}.pem'}")
    return str(folder / f"{stem}.pem"), str(key_path)


def router_tls(folder: str | Path) -> dict[str, object]:
    """The router's `transport/link/tls` settings: its certificate, and mutual TLS (every
    client shows a certificate the mission's CA signed)."""
    cert, key = _check_pair(Path(folder), ROUTER, "router certificate")
    return {"root_ca_certificate": str(Path(folder) / CA), "listen_certificate": cert,
            "listen_private_key": key, "enable_mtls": True}


def client_tls(folder: str | Path, user: str) -> dict[str, object]:
    """A client's `transport/link/tls` settings: the CA that must have signed the router's
    certificate, and `user`'s own certificate (its common name is the user)."""
    cert, key = _check_pair(Path(folder), user, f"certificate of {user!r}")
    return {"root_ca_certificate": str(Path(folder) / CA), "connect_certificate": cert,
            "connect_private_key": key, "enable_mtls": True}


def common_name(path: str | Path) -> str:
    """The common name of a certificate file."""
    cert = x509.load_pem_x509_certificate(Path(path).read_bytes())
    return str(cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value)


def router_names(folder: str | Path) -> list[str]:
    """Host names and addresses the router's certificate is valid for."""
    cert = _load_cert(Path(folder) / f"{ROUTER}.pem", "router certificate")
    sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    return [str(v) for v in sans.get_values_for_type(x509.DNSName)] + [
        str(v) for v in sans.get_values_for_type(x509.IPAddress)]
