"""Liveliness events checked against the router's tokens: a peer whose DELETE never came is
declared gone once, after two queries that miss it; live peers never are."""

from __future__ import annotations

import time

import zenoh

from services.common import liveliness
from services.common.bus import Bus, BusConfig, Presence, zenoh_config
from services.common.liveliness import LivelinessWatch, complete_answer, departed


def test_departed_needs_two_misses_with_no_event_between() -> None:
    gone, suspects = departed({"a": 1, "b": 2}, {}, held={"a"})
    assert gone == [] and suspects == {"b": 2}
    gone, suspects = departed({"a": 1, "b": 2}, suspects, held={"a"})
    assert gone == ["b"] and suspects == {}
    # b came back (a new PUT, a new generation) between the two queries: not gone yet
    gone, suspects = departed({"b": 5}, {"b": 2}, held=set())
    assert gone == [] and suspects == {"b": 5}
    # held again: no longer a suspect
    assert departed({"b": 5}, {"b": 5}, held={"b"}) == ([], {})


def test_an_answer_is_evidence_only_in_time_and_with_our_own_tokens() -> None:
    own = {"alive/edge/0"}
    assert complete_answer({"alive/edge/0", "alive/sim/0"}, own, 0.01, 1.0)
    assert complete_answer(set(), set(), 0.01, 1.0)  # nothing of ours to hold
    assert not complete_answer(set(), own, 0.01, 1.0)  # the router left ours out: no answer
    assert not complete_answer({"alive/edge/0"}, own, 1.0, 1.0)  # ran into its timeout


def test_silent_or_late_answers_declare_no_one_gone(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """A loaded router's empty or late answers once declared every peer gone (the edge then
    gave no goals and the mission ended at 46 s): they are skipped now; a complete answer
    that misses a peer twice still declares it gone."""
    seen: list[tuple[str, bool]] = []
    with zenoh.open(zenoh_config("peer", listen=[])) as session:
        own = "t/alive/edge/0"
        token = session.liveliness().declare_token(own)
        watch = LivelinessWatch(session, "t/alive/**", lambda k, a: seen.append((k, a)),
                                interval_s=3600.0, own=lambda: {own})
        try:
            _wait(lambda: (own, True) in seen)
            watch._on_token(_sample("t/alive/agent/1", zenoh.SampleKind.PUT))
            answers = iter([set(), {"t/alive/agent/1"}, set()])  # silent, ours missing, silent
            monkeypatch.setattr(watch, "_ask", lambda: next(answers))
            assert [watch.check() for _ in range(3)] == [[], [], []]
            monkeypatch.setattr(liveliness, "QUERY_TIMEOUT_S", 0.05)

            def late() -> set[str]:
                time.sleep(0.06)
                return {own}
            monkeypatch.setattr(watch, "_ask", late)
            assert watch.check() == [] and watch.check() == []
            assert watch.skipped == 5 and ("t/alive/agent/1", False) not in seen
            # two complete answers without it, then one with it: a glitch, not a departure
            answers = iter([{own}, {own}, {own, "t/alive/agent/1"}])
            monkeypatch.setattr(watch, "_ask", lambda: next(answers))
            assert watch.check() == [] and watch.check() == []
            monkeypatch.setattr(watch, "_ask", lambda: {own})  # in time, with ours, three times
            assert watch.check() == [] and watch.check() == ["t/alive/agent/1"]
            assert seen.count(("t/alive/agent/1", False)) == 1
        finally:
            watch.close()
            token.undeclare()


def _wait(cond, timeout_s: float = 5.0) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def test_watch_declares_a_token_without_delete_gone_once() -> None:
    seen: list[tuple[str, bool]] = []
    with zenoh.open(zenoh_config("peer", listen=[])) as session:
        token = session.liveliness().declare_token("t/alive/agent/0")
        watch = LivelinessWatch(session, "t/alive/**", lambda k, a: seen.append((k, a)),
                                interval_s=3600.0)  # checks run by hand below
        try:
            _wait(lambda: ("t/alive/agent/0", True) in seen)
            # a PUT whose DELETE is lost: the router (here the session itself) never held it
            watch._on_token(_sample("t/alive/agent/7", zenoh.SampleKind.PUT))
            assert watch.check() == []  # first miss: a suspect only
            assert watch.check() == ["t/alive/agent/7"]
            assert seen[-1] == ("t/alive/agent/7", False) and watch.reconciled == 1
            assert watch.check() == []  # said once
            # a real token stays; its real DELETE comes through once
            token.undeclare()
            _wait(lambda: seen[-1] == ("t/alive/agent/0", False))
            assert watch.check() == [] and watch.check() == []
            assert seen.count(("t/alive/agent/0", False)) == 1
        finally:
            watch.close()


def test_bus_presence_from_a_reconciled_departure() -> None:
    config = BusConfig(lease_s=2.0)
    with zenoh.open(zenoh_config("peer", listen=[])) as session:
        bus = Bus(session, config)
        bus.watch_liveliness()
        assert bus._liveliness is not None
        key = bus.keys.alive("agent", 3)
        bus._liveliness._on_token(_sample(key, zenoh.SampleKind.PUT))
        assert bus.poll(timeout=1.0) == Presence("agent", "3", alive=True)
        # the watch checks every max(1, lease / 2) s: two misses within a few seconds
        assert bus.poll(timeout=5.0) == Presence("agent", "3", alive=False)
        bus.close()


class _Sample:
    def __init__(self, key: str, kind: zenoh.SampleKind) -> None:
        self.key_expr = key
        self.kind = kind


def _sample(key: str, kind: zenoh.SampleKind) -> zenoh.Sample:
    return _Sample(key, kind)  # type: ignore[return-value]
