"""bench/bench_fleet_drift.py --affine: the fleet's shared error as one affine map."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from bench_fleet_drift import fleet_affine  # noqa: E402


def test_a_fleet_stretched_and_turned_is_recovered_under_each_robots_own_noise() -> None:
    rng = np.random.default_rng(0)
    truth = rng.uniform([0, 0], [40, 30], size=(5000, 2))
    turn = np.radians(-0.09)
    A = np.array([[0.0017, -turn], [turn, 0.0012]])  # 0.17 / 0.12 cm per m, −0.09°
    t = np.array([0.007, 0.022])
    est = truth + truth @ A.T + t + rng.normal(0, 0.03, size=truth.shape)
    A_fit, t_fit = fleet_affine(truth, est)
    np.testing.assert_allclose(A_fit, A, atol=2e-4)
    np.testing.assert_allclose(t_fit, t, atol=3e-3)


def test_a_fleet_that_only_disagrees_has_no_shared_map() -> None:
    rng = np.random.default_rng(1)
    truth = rng.uniform([0, 0], [40, 30], size=(5000, 2))
    A_fit, t_fit = fleet_affine(truth, truth + rng.normal(0, 0.05, size=truth.shape))
    assert np.abs(A_fit).max() < 2e-4
    assert np.abs(t_fit).max() < 5e-3
