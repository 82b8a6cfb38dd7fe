"""Who may speak on which key: identities, the router's zenoh access control, credentials.

Each process authenticates to the router with zenoh's user/password authentication (one user
per process: `sim`, `edge`, `monitor`, `agent-{id}`) and, on TLS links, with a client
certificate whose common name is the same user (services/common/tls.py); the router's access
control binds each user to the keys `schemas.keys.role_keys` gives its role, and denies
everything else. `acl_config` is pure; the file helpers below it write and read a credentials
folder.
"""

from __future__ import annotations

import json
import os
import secrets
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from schemas.keys import Keys, RoleKeys, role_keys
from services.common.tls import DEFAULT_DAYS, make_certificates

SINGLE_ROLES = ("sim", "edge", "monitor")
DICTIONARY = "users.txt"  # the router's user:password dictionary
MISSION = "mission.json"  # the fleet the credentials were made for

# zenoh 1.10 access-control message kinds (zenoh-config AclMessage)
PUBLISH = ["put", "delete"]


def identity(role: str, ident: int | str = 0) -> str:
    """The user name of process (`role`, `ident`)."""
    return f"agent-{ident}" if role == "agent" else role


def identities(robots: int) -> dict[str, tuple[str, int]]:
    """Every user of a mission with `robots` robots → its (role, id)."""
    out = {identity(r): (r, 0) for r in SINGLE_ROLES}
    out.update({identity("agent", i): ("agent", i) for i in range(robots)})
    return out


def _rule(rule_id: str, flow: str, messages: list[str], key_exprs: tuple[str, ...]
          ) -> dict[str, Any]:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages,
            "key_exprs": list(key_exprs)}


def _user_rules(user: str, grants: RoleKeys) -> list[dict[str, Any]]:
    """Ingress: what the user may send. Egress: what the router may deliver to it (a
    subscriber receives puts, a queryable queries, a querier replies)."""
    spec = [
        ("pub", "ingress", PUBLISH, grants.publish),
        ("sub", "ingress", ["declare_subscriber"], grants.subscribe),
        ("recv", "egress", PUBLISH, grants.subscribe),
        ("serve", "ingress", ["declare_queryable", "reply"], grants.serve),
        ("asked", "egress", ["query"], grants.serve),
        ("ask", "ingress", ["query"], grants.query),
        ("answers", "egress", ["reply"], grants.query),
        ("token", "ingress", ["liveliness_token"], grants.token),
    ]
    # zenoh rejects a rule without key expressions: leave empty ones out
    return [_rule(f"{user}/{name}", flow, msgs, keys) for name, flow, msgs, keys in spec if keys]


def _shared_rules(keys: Keys) -> list[dict[str, Any]]:
    """Granted to every user: reading liveliness (who is alive), and learning where
    subscribers and queryables are (declarations only, no data), which zenoh clients need
    to route their own puts and queries."""
    prefix = f"{keys.prefix}/**"
    return [
        _rule("all/liveliness", "ingress",
              ["declare_liveliness_subscriber", "liveliness_query"], (keys.alive_all(),)),
        _rule("all/liveliness-out", "egress", ["liveliness_token", "reply"],
              (keys.alive_all(),)),
        _rule("all/routing", "egress", ["declare_subscriber", "declare_queryable"], (prefix,)),
    ]


def acl_config(prefix: str, robots: int, mtls: bool = False) -> dict[str, Any]:
    """The router's `access_control` section for a mission: one subject per user, each
    bound to its role's keys; default deny. With `mtls` a subject is the user's login AND a
    client certificate with the user as common name (zenoh matches every attribute of a
    subject), so a login presented with another user's certificate matches no one."""
    keys = Keys(prefix)
    shared = _shared_rules(keys)
    rules, subjects, policies = list(shared), [], []
    for user, (role, ident) in identities(robots).items():
        own = _user_rules(user, role_keys(keys, role, ident, robots))
        rules += own
        subject: dict[str, Any] = {"id": user, "usernames": [user]}
        if mtls:
            subject["cert_common_names"] = [user]
        subjects.append(subject)
        policies.append({"id": user, "subjects": [user],
                         "rules": [r["id"] for r in own] + [r["id"] for r in shared]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


class Credential(BaseModel):
    """One process's login, as stored in `{dir}/{user}.json`."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    user: str = Field(pattern=r"^[A-Za-z0-9_-]+$")
    password: str = Field(min_length=16, pattern=r"^[A-Za-z0-9_-]+$")  # no ':' (dictionary)


def _write_private(path: Path, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as fh:
        fh.write(text)


def make_credentials(out: Path, robots: int, router_hosts: Iterable[str] = (),
                     days: int = DEFAULT_DAYS) -> list[str]:
    """Write a fresh password per user of a `robots`-robot mission into `out`: the router's
    dictionary, one `{user}.json` per process, and the fleet size; and a fresh CA with the
    router's certificate (valid for loopback, `router` and `router_hosts`) and one client
    certificate per user (services/common/tls.py). Returns the users."""
    if robots < 1:
        raise ValueError("robots must be ≥ 1")
    out.mkdir(parents=True, exist_ok=True)
    os.chmod(out, 0o700)
    creds = [Credential(user=u, password=secrets.token_urlsafe(24)) for u in identities(robots)]
    for cred in creds:
        _write_private(out / f"{cred.user}.json", cred.model_dump_json())
    _write_private(out / DICTIONARY, "".join(f"{c.user}:{c.password}\n" for c in creds))
    _write_private(out / MISSION, json.dumps({"robots": robots}))
    make_certificates(out, [c.user for c in creds], router_hosts, days)
    return [c.user for c in creds]


def load_credential(folder: str | Path, user: str) -> Credential:
    path = Path(folder) / f"{user}.json"
    try:
        return Credential.model_validate_json(path.read_text())
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"no credentials for {user!r} in {folder}") from exc


def credentials_robots(folder: str | Path) -> int:
    """The fleet size a credentials folder was made for."""
    return int(json.loads((Path(folder) / MISSION).read_text())["robots"])
