"""Agent replicas claim robot ids (services/common/fleet.py): distinct, stable per holder,
never more than the fleet; `spacemap health --id auto` finds the claim."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest
from typer.testing import CliRunner

from services.cli import app
from services.common import fleet


def _claim(args: tuple[str, int, str]) -> int:
    folder, robots, holder = args
    return fleet.claim_robot(Path(folder), robots, holder)


def test_replicas_claim_distinct_ids_at_once(tmp_path: Path) -> None:
    holders = [f"container{i}" for i in range(6)]
    with ProcessPoolExecutor(max_workers=6) as pool:
        ids = list(pool.map(_claim, [(str(tmp_path), 6, h) for h in holders]))
    assert sorted(ids) == list(range(6))
    for holder, robot in zip(holders, ids, strict=True):
        assert fleet.claimed_robot(tmp_path, holder) == robot


def test_a_restarted_replica_gets_its_id_back(tmp_path: Path) -> None:
    assert fleet.claim_robot(tmp_path, 3, "a") == 0
    assert fleet.claim_robot(tmp_path, 3, "b") == 1
    assert fleet.claim_robot(tmp_path, 3, "a") == 0
    assert fleet.claim_robot(tmp_path, 3, "c") == 2
    with pytest.raises(RuntimeError, match="all 3 robot ids"):
        fleet.claim_robot(tmp_path, 3, "d")


def test_new_credentials_forget_claims(tmp_path: Path) -> None:
    creds = tmp_path / "creds"
    result = CliRunner().invoke(app, ["credentials", "--out", str(creds), "--robots", "2"])
    assert result.exit_code == 0, result.output
    folder = fleet.claims_folder(creds)
    assert fleet.claim_robot(folder, 2, "a") == 0
    assert fleet.claim_robot(folder, 2, "b") == 1
    result = CliRunner().invoke(app, ["credentials", "--out", str(creds), "--robots", "2"])
    assert result.exit_code == 0, result.output
    assert fleet.claim_robot(folder, 2, "b") == 0


def test_resolve_robot(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert fleet.resolve_robot("4", None, 3, claim=True) == 4
    with pytest.raises(ValueError):
        fleet.resolve_robot("-1", None, 3, claim=True)
    with pytest.raises(ValueError, match="needs bus.credentials"):
        fleet.resolve_robot("auto", None, 3, claim=True)
    monkeypatch.setattr(fleet, "holder_name", lambda: "me")
    assert fleet.resolve_robot("auto", str(tmp_path), 3, claim=False) is None
    assert fleet.resolve_robot("auto", str(tmp_path), 3, claim=True) == 0
    assert fleet.resolve_robot("auto", str(tmp_path), 3, claim=False) == 0


def test_health_auto_without_a_claim_is_unhealthy(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, [
        "health", "--role", "agent", "--id", "auto", "--as", "auto",
        "--set", f"bus.credentials={tmp_path}", "--connect", "tcp/127.0.0.1:9"])
    assert result.exit_code == 1
    assert "no robot id claimed yet" in result.output
