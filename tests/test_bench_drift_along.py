"""bench/bench_drift_along.py --windows: where in a mission the estimates ran ahead."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from bench_drift_along import windowed_growth  # noqa: E402


def _tum(stamps: np.ndarray, xy: np.ndarray) -> np.ndarray:
    rows = np.zeros((len(stamps), 8))
    rows[:, 0], rows[:, 1:3], rows[:, 7] = stamps, xy, 1.0
    return rows


def test_an_estimate_that_runs_ahead_early_only_shows_in_the_early_window() -> None:
    """0.5 m/s along x for 60 s at 10 Hz; the estimate runs 1 % ahead for the first 25 s,
    then keeps that lead and drifts no more; across the track it wanders without bias."""
    stamps = np.arange(601) * 0.1
    x = 0.05 * np.arange(601)
    ahead = 0.01 * np.minimum(x, x[250])
    gt = _tum(stamps, np.column_stack([x, np.zeros_like(x)]))
    wobble = 0.01 * np.sin(np.arange(601))
    est = _tum(stamps, np.column_stack([x + ahead, wobble]))
    (a0, d0), (a1, d1), (a2, d2) = windowed_growth(gt, est, [0.0, 25.0, 50.0])
    assert a0 / d0 == pytest.approx(0.01, rel=1e-6)
    assert d0 == pytest.approx(12.5, rel=1e-9)  # the step out of the window counted once
    assert a1 == pytest.approx(0.0, abs=1e-12) and d1 == pytest.approx(12.5, rel=1e-9)
    assert a2 == pytest.approx(0.0, abs=1e-12) and d2 == pytest.approx(5.0, rel=1e-9)


def test_a_window_without_poses_is_empty() -> None:
    stamps = np.arange(11) * 0.1
    gt = _tum(stamps, np.column_stack([np.arange(11) * 0.05, np.zeros(11)]))
    assert windowed_growth(gt, gt.copy(), [0.0, 5.0]) == [(0.0, pytest.approx(0.5)), (0.0, 0.0)]
