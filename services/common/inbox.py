"""The bus's FIFO inbox, with items that wait in line without waking the reader.

A 24-robot agent receives 230 teammate poses a second and acts on them only at its own
odometry tick. Waking its main thread for each one costs a context switch and a GIL handover
on a machine whose cores are already saturated (docs/benchmarks.md). A quiet item keeps its
place in the one FIFO, so the order between keys (which the lockstep determinism relies on)
is unchanged; the reader only learns of it with the next item that wakes it, or at its
timeout.
"""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from typing import Generic, TypeVar

T = TypeVar("T")


class Inbox(Generic[T]):
    """`queue.Queue`'s put / get / empty, where `put(item, wake=False)` notifies nobody."""

    def __init__(self) -> None:
        self._items: deque[tuple[T, bool]] = deque()
        self._ready = threading.Condition(threading.Lock())
        self._waking = 0  # items in line that woke (or would wake) the reader

    def put(self, item: T, wake: bool = True) -> None:
        with self._ready:
            self._items.append((item, wake))
            if wake:
                self._waking += 1
                self._ready.notify()

    def woken(self) -> bool:
        """Whether an item that wakes the reader is in line (a reader busy with work that
        can wait asks this between its steps)."""
        return self._waking > 0

    def get(self, timeout: float | None = None) -> T:
        """The oldest item; waits up to `timeout` s (None: forever) for one that wakes, and
        raises `queue.Empty` when none came and no quiet one is in line either."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._ready:
            while not self._items:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise queue.Empty
                self._ready.wait(left)
            item, wake = self._items.popleft()
            self._waking -= wake
            return item

    def empty(self) -> bool:
        return not self._items
