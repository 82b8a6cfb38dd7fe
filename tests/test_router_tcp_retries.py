"""The router's check of its host's TCP retry bound (a cut TLS client is declared gone only
when TCP gives up on the data queued toward it)."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from services.common.router import RECOMMENDED_TCP_RETRIES2, check_tcp_retries2, tcp_give_up_s


def test_give_up_time_follows_the_kernels_backoff() -> None:
    assert tcp_give_up_s(15) == pytest.approx(924.6)  # the kernel's documented default
    assert tcp_give_up_s(RECOMMENDED_TCP_RETRIES2) == pytest.approx(12.6)
    assert tcp_give_up_s(3) == pytest.approx(3.0)


def test_check_warns_above_the_recommendation(tmp_path: Path,
                                              caplog: pytest.LogCaptureFixture) -> None:
    setting = tmp_path / "tcp_retries2"
    setting.write_text("15\n")
    with caplog.at_level(logging.WARNING, logger="services.common.router"):
        assert check_tcp_retries2(setting) == 15
    assert "about 925 s" in caplog.text and "set 5" in caplog.text
    caplog.clear()
    setting.write_text(f"{RECOMMENDED_TCP_RETRIES2}\n")
    with caplog.at_level(logging.WARNING, logger="services.common.router"):
        assert check_tcp_retries2(setting) == RECOMMENDED_TCP_RETRIES2
    assert caplog.text == ""
    assert check_tcp_retries2(tmp_path / "absent") is None
