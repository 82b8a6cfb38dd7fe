"""Who is alive: zenoh liveliness events, checked against the router's tokens.

A process learns that a peer is gone from the DELETE of the peer's liveliness token. When a
peer's link is cut while reliable traffic is queued toward it, the router can drop the token
without that DELETE reaching every subscriber (measured: `bench/bench_cut_link.py`; a
subscriber that waits on it, such as the lockstep simulator, would wait for ever). So each
watch also asks the router which tokens it holds, every `interval_s`, and declares gone a
peer that its events still call alive but that the router has not held for two queries in a
row, nor in a third asked at once, with no event about it in between. A query that ran into
its timeout, or whose answer lacks a token this very session holds, is no evidence and is
skipped: the router now and then answers at once with no token at all, and two such answers
in a row once declared every agent gone and ended a mission at 46 s (docs/benchmarks.md,
sixty-eighth session).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping

import zenoh

log = logging.getLogger(__name__)

QUERY_TIMEOUT_S = 1.0


def complete_answer(held: set[str], own: set[str], elapsed_s: float, timeout_s: float) -> bool:
    """Whether a liveliness query's replies can be taken as everything the router holds: it
    finished before its timeout and holds every token of the asking session."""
    return elapsed_s < 0.9 * timeout_s and own <= held


def departed(candidates: Mapping[str, int], suspects: Mapping[str, int],
             held: set[str]) -> tuple[list[str], dict[str, int]]:
    """Keys to declare gone, and the suspects for the next query.

    `candidates`: key → generation (event counter at its last PUT) of every key the events
    call alive; `suspects`: the same for the keys the previous query did not find; `held`:
    the keys the router holds now. A key is gone when the router missed it twice with the
    same generation (no event about it in between)."""
    gone: list[str] = []
    missing: dict[str, int] = {}
    for key, generation in candidates.items():
        if key in held:
            continue
        if suspects.get(key) == generation:
            gone.append(key)
        else:
            missing[key] = generation
    return sorted(gone), missing


class LivelinessWatch:
    """Every current and future token under `key_expr`, delivered in order as
    `deliver(key, alive)` (on a zenoh thread, or the watch's own for a reconciled departure)."""

    def __init__(self, session: zenoh.Session, key_expr: str,
                 deliver: Callable[[str, bool], None], interval_s: float,
                 own: Callable[[], set[str]] = set) -> None:
        """`own()`: the tokens under `key_expr` this session has declared (and not undeclared),
        which any complete answer of the router holds."""
        self.session = session
        self.own = own
        self.skipped = 0  # queries that were no evidence (timed out, or missing our own)
        self.key_expr = key_expr
        self.deliver = deliver
        self.interval_s = interval_s
        self.reconciled = 0  # departures declared by the check, not by an event
        self._alive: dict[str, int] = {}
        self._suspects: dict[str, int] = {}
        self._generation = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._subscriber = session.liveliness().declare_subscriber(
            key_expr, zenoh.handlers.Callback(self._on_token, indirect=False), history=True)
        self._thread = threading.Thread(target=self._check_loop, name="liveliness-check",
                                        daemon=True)
        self._thread.start()

    def _on_token(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            self._generation += 1
            if alive:
                self._alive[key] = self._generation
            elif self._alive.pop(key, None) is None:
                return  # already declared gone by the check: say it once
            self.deliver(key, alive)

    def held(self) -> set[str] | None:
        """The keys the router holds now; None when the query fails, times out or misses a
        token of this session's (`complete_answer`)."""
        own = self.own()
        start = time.monotonic()
        try:
            replies = self._ask()
        except zenoh.ZError as exc:
            log.debug("liveliness query failed: %s", exc)
            return None
        elapsed_s = time.monotonic() - start
        if not complete_answer(replies, own, elapsed_s, QUERY_TIMEOUT_S):
            self.skipped += 1
            log.info("liveliness query skipped: %d tokens in %.2f s, %d of this session's "
                     "missing", len(replies), elapsed_s, len(own - replies))
            return None
        return replies

    def _ask(self) -> set[str]:
        replies = self.session.liveliness().get(self.key_expr, timeout=QUERY_TIMEOUT_S)
        return {str(r.ok.key_expr) for r in replies if r.ok is not None}

    def check(self) -> list[str]:
        """One comparison with the router; the keys it declared gone. A key missed twice is
        asked about once more at once: the router's bad answers come one at a time."""
        with self._lock:
            before = dict(self._alive)
        held = self.held()
        if held is None:
            return []
        with self._lock:
            candidates = {k: g for k, g in before.items() if self._alive.get(k) == g}
            gone, self._suspects = departed(candidates, self._suspects, held)
        if not gone:
            return []
        again = self.held()
        with self._lock:
            if again is None:  # no evidence either way: still suspects
                self._suspects.update({k: candidates[k] for k in gone})
                return []
            gone = [k for k in gone if k not in again and self._alive.get(k) == candidates[k]]
            for key in gone:
                del self._alive[key]
                self._generation += 1
                self.reconciled += 1
                log.warning("%s: the router no longer holds this token but its DELETE never "
                            "came; declared gone", key)
                self.deliver(key, False)
        return gone

    def _check_loop(self) -> None:
        while not self._stop.wait(self.interval_s):
            self.check()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=QUERY_TIMEOUT_S + 1.0)
        self._subscriber.undeclare()
