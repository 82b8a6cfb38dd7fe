"""The bus inbox: one FIFO, where quiet items keep their place without waking the reader."""

from __future__ import annotations

import queue
import threading
import time

import pytest

from services.common.inbox import Inbox


def test_quiet_and_waking_items_come_out_in_arrival_order() -> None:
    box: Inbox[int] = Inbox()
    for i in range(6):
        box.put(i, wake=i % 3 == 2)
    assert [box.get(timeout=0) for _ in range(6)] == list(range(6))
    assert box.empty()
    with pytest.raises(queue.Empty):
        box.get(timeout=0)


def _wait_until_blocked(box: Inbox, deadline_s: float = 5.0) -> None:
    """Until the reader waits on the inbox's condition (CPython keeps its waiters)."""
    end = time.monotonic() + deadline_s
    while not box._ready._waiters:  # type: ignore[attr-defined]
        assert time.monotonic() < end, "the reader never blocked"
        time.sleep(0.001)


def test_a_quiet_item_does_not_wake_a_waiting_reader_but_is_read_at_its_timeout() -> None:
    box: Inbox[str] = Inbox()
    got: list[tuple[str, float]] = []
    t0 = time.monotonic()

    def read() -> None:
        got.append((box.get(timeout=1.0), time.monotonic() - t0))

    reader = threading.Thread(target=read)
    reader.start()
    _wait_until_blocked(box)
    box.put("quiet", wake=False)
    reader.join(timeout=5.0)
    assert got and got[0][0] == "quiet"
    assert got[0][1] >= 0.9  # it waited out its timeout: nobody woke it


def test_a_waking_item_wakes_the_reader_and_the_quiet_ones_before_it_come_first() -> None:
    box: Inbox[str] = Inbox()
    got: list[str] = []

    def read() -> None:
        got.append(box.get(timeout=30.0))
        got.append(box.get(timeout=0))

    reader = threading.Thread(target=read)
    reader.start()
    _wait_until_blocked(box)
    box.put("pose", wake=False)
    box.put("odometry")
    reader.join(timeout=5.0)
    assert not reader.is_alive()  # woken long before its 30 s timeout
    assert got == ["pose", "odometry"]


def test_woken_counts_the_waking_items_in_line_only() -> None:
    box: Inbox[str] = Inbox()
    assert not box.woken()
    box.put("pose", wake=False)
    assert not box.woken()  # a quiet item is no reason to stop work that can wait
    box.put("odom")
    box.put("goal")
    assert box.woken()
    assert box.get(timeout=0) == "pose" and box.woken()
    assert box.get(timeout=0) == "odom" and box.woken()
    assert box.get(timeout=0) == "goal" and not box.woken()
