"""bench/bench_agent_replay.py's `interleave`: another arrival order the bus could have given."""

from __future__ import annotations

import random
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from bench_agent_replay import interleave  # noqa: E402

MESSAGES = [("edge", 0), ("a", 0), ("b", 0), ("edge", 1), ("a", 1), ("b", 1), ("a", 2)]


def sender(msg: tuple[str, int]) -> str:
    return msg[0]


def test_without_a_generator_the_order_is_kept() -> None:
    assert interleave(MESSAGES, sender, None) == MESSAGES  # type: ignore[arg-type]


def test_each_sender_keeps_its_order_and_nothing_is_lost_or_doubled() -> None:
    orders = set()
    for seed in range(20):
        out = interleave(MESSAGES, sender, random.Random(seed))  # type: ignore[arg-type]
        assert sorted(out) == sorted(MESSAGES)
        for who in ("edge", "a", "b"):
            assert [m for m in out if m[0] == who] == [m for m in MESSAGES if m[0] == who]
        orders.add(tuple(out))
    assert len(orders) > 5  # senders really are interleaved differently
