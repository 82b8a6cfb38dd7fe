"""The router's access control, as generated (pure): who may do what on which key."""

from __future__ import annotations

import json
import re
import stat
from pathlib import Path

import pytest

from schemas import DecodeError, decode, encode
from schemas.keys import Keys, role_keys
from services.common.access import (
    DICTIONARY,
    acl_config,
    credentials_robots,
    identities,
    load_credential,
    make_credentials,
)
from tests.fuzz import bad_payloads, templates

ROBOTS = 3
KEYS = Keys("spacemap")


def every_key(robots: int) -> list[str]:
    """Every concrete key of a mission, plus one robot beyond the fleet."""
    k = KEYS
    per_robot = (k.rgbd, k.odom, k.cmd_vel, k.pose, k.submap, k.correction, k.goal,
                 k.goal_status, k.inventory, k.gt_pose)
    return [k.clock(), k.map_grid(), k.map_frontiers(), k.map_cloud(), k.map_robot_grid(),
            k.map_inventory(), k.edge_ack(), "spacemap/other",
            *(f(r) for r in range(robots + 1) for f in per_robot),
            *(k.alive(role, i) for role in ("sim", "edge", "monitor", "agent", "router")
              for i in range(robots + 1))]


def matches(pattern: str, key: str) -> bool:
    """zenoh key-expression inclusion of a concrete key: `*` one chunk, `**` any chunks."""
    rx = "/".join("(.+)" if c == "**" else "[^/]+" if c == "*" else re.escape(c)
                  for c in pattern.split("/"))
    return re.fullmatch(rx, key) is not None


def allowed(acl: dict, user: str, flow: str, message: str, key: str) -> bool:
    """Does the config let `user` do `message` on `key` in direction `flow`?"""
    rules = {r["id"]: r for r in acl["rules"]}
    for policy in acl["policies"]:
        if user not in policy["subjects"]:
            continue
        for rid in policy["rules"]:
            rule = rules[rid]
            if (flow in rule["flows"] and message in rule["messages"]
                    and any(matches(p, key) for p in rule["key_exprs"])):
                return rule["permission"] == "allow"
    return acl["default_permission"] == "allow"


def test_shape() -> None:
    acl = acl_config("spacemap", ROBOTS)
    assert acl["enabled"] and acl["default_permission"] == "deny"
    users = set(identities(ROBOTS))
    assert users == {"sim", "edge", "monitor", "agent-0", "agent-1", "agent-2"}
    assert {s["id"] for s in acl["subjects"]} == users
    assert all(s["usernames"] == [s["id"]] for s in acl["subjects"])
    rule_ids = [r["id"] for r in acl["rules"]]
    assert len(rule_ids) == len(set(rule_ids))
    for policy in acl["policies"]:
        assert set(policy["rules"]) <= set(rule_ids)
    assert all(r["key_exprs"] and r["permission"] == "allow" for r in acl["rules"])
    json.dumps(acl)  # goes to zenoh as JSON


def owners(key: str, action: str) -> set[str]:
    """Users whose role_keys grant `action` on `key` (the table in schemas/keys.py)."""
    return {user for user, (role, ident) in identities(ROBOTS).items()
            if any(matches(p, key) for p in getattr(role_keys(KEYS, role, ident, ROBOTS),
                                                    action))}


@pytest.mark.parametrize("user", sorted(identities(ROBOTS)))
def test_matrix(user: str) -> None:
    """Every (user, key, action) not granted by the key table is refused, every granted one
    allowed; the table gives each publish key exactly one owner."""
    acl = acl_config("spacemap", ROBOTS)
    for key in every_key(ROBOTS):
        pub = owners(key, "publish")
        assert len(pub) <= 1, f"{key} has several publishers: {pub}"
        assert allowed(acl, user, "ingress", "put", key) == (user in pub), (user, key)
        assert allowed(acl, user, "ingress", "delete", key) == (user in pub), (user, key)
        assert allowed(acl, user, "egress", "put", key) == (user in owners(key, "subscribe"))
        serves = user in owners(key, "serve")
        assert allowed(acl, user, "ingress", "declare_queryable", key) == serves, (user, key)
        assert allowed(acl, user, "ingress", "reply", key) == serves, (user, key)
        assert allowed(acl, user, "ingress", "query", key) == (user in owners(key, "query"))
        assert allowed(acl, user, "ingress", "liveliness_token", key) == (
            user in owners(key, "token")), (user, key)


def test_agent_owns_only_its_robot() -> None:
    acl = acl_config("spacemap", ROBOTS)
    assert allowed(acl, "agent-1", "ingress", "put", KEYS.cmd_vel(1))
    for key in (KEYS.cmd_vel(2), KEYS.goal(1), KEYS.map_grid(), KEYS.edge_ack(),
                KEYS.correction(1), KEYS.submap(0)):
        assert not allowed(acl, "agent-1", "ingress", "put", key), key
    assert not allowed(acl, "agent-1", "ingress", "liveliness_token", KEYS.alive("edge", 0))
    assert not allowed(acl, "sim", "ingress", "put", KEYS.map_grid())
    assert not allowed(acl, "agent-1", "egress", "put", KEYS.rgbd(2))  # not its camera
    with pytest.raises(ValueError):
        role_keys(KEYS, "agent", ROBOTS, ROBOTS)


def test_credentials(tmp_path: Path) -> None:
    users = make_credentials(tmp_path / "c", robots=2)
    assert set(users) == set(identities(2))
    assert credentials_robots(tmp_path / "c") == 2
    assert stat.S_IMODE((tmp_path / "c").stat().st_mode) == 0o700
    lines = (tmp_path / "c" / DICTIONARY).read_text().splitlines()
    assert len(lines) == len(users)
    for user in users:
        cred = load_credential(tmp_path / "c", user)
        assert f"{user}:{cred.password}" in lines
        assert stat.S_IMODE((tmp_path / "c" / f"{user}.json").stat().st_mode) == 0o600
    assert (tmp_path / "c" / "ca.pem").exists() and (tmp_path / "c" / "router.key").exists()
    assert all((tmp_path / "c" / f"{user}.pem").exists() for user in users)
    again = make_credentials(tmp_path / "d", robots=2)
    assert load_credential(tmp_path / "d", again[0]).password != load_credential(
        tmp_path / "c", again[0]).password


@pytest.mark.parametrize("topic", ["pose", "cmd_vel", "goal_status", "submap"])
def test_fuzz_payloads_are_all_rejected(topic: str) -> None:
    """The fuzz test's payloads (tests/fuzz.py): each one fails decoding with a DecodeError
    of a known reason, so the mission test may count every one as a drop."""
    template = templates(0)[topic]
    payloads = bad_payloads(template, seed=1)
    assert len(payloads) >= 12
    for what, payload in payloads:
        with pytest.raises(DecodeError):
            decode(payload, type(template))
        assert what
    decode(encode(template), type(template))  # the template itself is valid
