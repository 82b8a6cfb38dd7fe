"""Submap inventories: building, encoding, and finding what the edge lacks."""

from __future__ import annotations

from schemas import decode, encode
from schemas.messages import Inventory
from services.common.inventory import as_json, inventory_of, missing_submaps


def test_inventory_round_trip_and_json() -> None:
    inv = inventory_of({2: [(7, 70_000, 120), (7, 70_001, 5)]}, tick=40)
    back = decode(encode(inv), Inventory)
    assert as_json(back) == {"2": {"7/70000": 120, "7/70001": 5}}
    assert as_json(None) is None


def test_missing_submaps() -> None:
    produced = {"0/1": 100, "0/2": 50, "9/90000": 10}
    merged = {"0/1": 100, "0/2": 49}
    assert missing_submaps(produced, merged) == {"0/2": (50, 49), "9/90000": (10, 0)}
    assert missing_submaps(produced, {**merged, "0/2": 60, "9/90000": 10}) == {}
