"""`spacemap health`'s probe: a live token found even when the router's first answer is
empty (it now and then answers a liveliness query at once with nothing)."""

from __future__ import annotations

from contextlib import contextmanager

from services.common import health
from services.common.bus import BusConfig


class _Reply:
    ok = object()


class _Session:
    def __init__(self, answers: list[list[_Reply]]) -> None:
        self.answers, self.asked = answers, 0

    def liveliness(self) -> _Session:
        return self

    def get(self, key: str, timeout: float) -> list[_Reply]:
        assert key.endswith("alive/edge/0") and timeout > 0
        self.asked += 1
        return self.answers.pop(0) if self.answers else []


def _probe(monkeypatch, session: _Session) -> bool:  # type: ignore[no-untyped-def]
    @contextmanager
    def open_session(config, login_as):  # type: ignore[no-untyped-def]
        yield session
    monkeypatch.setattr(health, "open_session", open_session)
    return health.is_alive(BusConfig(), "edge", 0, timeout_s=2.0)


def test_an_empty_first_answer_is_asked_again(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    session = _Session([[], [_Reply()]])
    assert _probe(monkeypatch, session) and session.asked == 2


def test_a_token_nobody_holds_is_not_alive_after_a_few_answers(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    session = _Session([])
    assert not _probe(monkeypatch, session) and session.asked == health.PROBE_TRIES
