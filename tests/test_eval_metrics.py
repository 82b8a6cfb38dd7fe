"""Evaluator metrics on synthetic data with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from services.common.grid import GridSpec
from services.evaluator import metrics as mx


def plane_points(n_per_m2: float, size_m: float, rng: np.random.Generator) -> np.ndarray:
    n = int(n_per_m2 * size_m**2)
    return np.c_[rng.uniform(0, size_m, (n, 2)), np.zeros(n)]


@pytest.fixture
def gt() -> np.ndarray:
    return plane_points(1000, 2.0, np.random.default_rng(1))


def test_coverage_3d_half_plane(gt: np.ndarray) -> None:
    map_pts = plane_points(2000, 2.0, np.random.default_rng(2))
    half = map_pts[map_pts[:, 0] < 1.0]
    # Half the plane, plus the 0.10 m band the radius reaches past x = 1 → 55 %.
    assert mx.coverage_3d(half, gt) == pytest.approx(55.0, abs=1.5)
    assert mx.coverage_3d(map_pts, gt) == pytest.approx(100.0, abs=0.1)
    assert mx.coverage_3d(map_pts, gt, ghost_mask=np.ones(len(map_pts), bool)) == 0.0
    assert mx.coverage_3d(np.zeros((0, 3)), gt) == 0.0


def test_overlap_3d(gt: np.ndarray) -> None:
    map_pts = plane_points(2000, 2.0, np.random.default_rng(3))
    a, b = map_pts[map_pts[:, 0] < 1.2], map_pts[map_pts[:, 0] > 0.8]
    # Both robots reach 0.7 < x < 1.3 (radius 0.10) → 30 % of the covered plane.
    assert mx.overlap_3d([a, b], gt) == pytest.approx(30.0, abs=1.5)
    assert mx.overlap_3d([a], gt) == 0.0


def test_covered_mask_is_the_kd_trees_answer_for_every_truth_point() -> None:
    """The cell pre-pass (truth sharing a small cell with a map point is covered unasked)
    gives the mask a radius query of every truth point gives, points at the radius
    included; and it does ask the tree (some truth points lie beyond every shared cell)."""
    rng = np.random.default_rng(3)
    for radius in (0.05, 0.10, 0.2):
        map_pts = rng.uniform(-2.0, 2.0, (4000, 3))
        truth = np.concatenate([rng.uniform(-2.0, 2.0, (20000, 3)),
                                map_pts[:500] + radius * _unit(rng, 500),
                                map_pts[500:1000] + np.nextafter(radius, 0) * _unit(rng, 500)])
        dist, _ = cKDTree(map_pts).query(truth, distance_upper_bound=radius)
        mask = mx.covered_mask(map_pts, truth, radius)
        assert np.array_equal(mask, np.isfinite(dist))
        assert 0 < mask.sum() < len(truth)
    assert not mx.covered_mask(np.zeros((0, 3)), truth, 0.1).any()


def _unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_rmse_perfect_map_is_sampling_error(gt: np.ndarray) -> None:
    perfect = plane_points(1000, 2.0, np.random.default_rng(4))
    expected_cm = 100 * np.sqrt(1 / (np.pi * 1000))  # Poisson nearest-neighbour RMS, 1.78 cm
    assert mx.rmse_3d_cm(perfect, gt) == pytest.approx(expected_cm, rel=0.15)
    lifted = perfect + [0, 0, 0.05]
    assert mx.rmse_3d_cm(lifted, gt) == pytest.approx(np.hypot(5.0, expected_cm), rel=0.1)
    assert mx.rmse_3d_cm(np.zeros((0, 3)), gt) is None


def test_bounding_volume_ghost_blob(gt: np.ndarray) -> None:
    rng = np.random.default_rng(5)
    clean = plane_points(2000, 2.0, rng)
    assert mx.bounding_volume_pct(clean, gt) == 0.0
    blob = rng.uniform([0.9, 0.9, 0.5], [1.1, 1.1, 0.7], (2000, 3))  # 0.2 m cube, 0.5 m up
    _, ghost = mx.ghost_voxels(np.r_[clean, blob], gt)
    assert 64 <= ghost.sum() <= 125  # a 0.2 m cube spans 4³..5³ voxels of 5 cm
    bv = mx.bounding_volume_pct(np.r_[clean, blob], gt)
    assert 100 * 64 / (1600 + 125) <= bv <= 100 * 125 / (1600 + 64)
    # A point 5 cm above the surface is not a ghost (within 0.10 m).
    assert mx.bounding_volume_pct(clean + [0, 0, 0.05], gt) == 0.0


def test_coverage_2d_aligns_grids() -> None:
    truth_spec = GridSpec(0.0, 0.0, 0.05, 40, 40)
    truth = np.ones(truth_spec.shape, bool)
    map_spec = GridSpec(-1.0, -0.5, 0.05, 60, 60)  # another origin, same world
    known = np.zeros(map_spec.shape, bool)
    known[:, : int((1.0 + 1.0) / 0.05)] = True  # x < 1.0 → half the truth
    assert mx.coverage_2d(known, map_spec, truth, truth_spec) == pytest.approx(50.0)
    other = np.zeros(map_spec.shape, bool)
    other[:, int((0.5 + 1.0) / 0.05) :] = True  # x ≥ 0.5
    # Known by both: 0.5 ≤ x < 1.0 = 25 % of the truth, of 100 % covered.
    both = mx.overlap_2d([(known, map_spec), (other, map_spec)], truth, truth_spec)
    assert both == pytest.approx(25.0)


def test_path_and_times() -> None:
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], float)
    assert mx.path_length(square) == pytest.approx(4.0)
    assert mx.path_length(square[:1]) == 0.0
    t = np.arange(5.0) * 10
    cov = np.array([0, 50, 91, 98, 99.5])
    assert mx.t_at_coverage(t, cov, 90) == 20.0
    assert mx.t_at_coverage(t, cov, 99) == 40.0
    assert mx.t_at_coverage(t, cov, 99.9) is None


def test_an_unsampled_mission_has_no_t90() -> None:
    """With `--sample-every 0` the series is the final row alone: its time is the mapping
    time, not the time 90 % was reached, so T90/T99 are unknown, not the mapping time."""
    final = [{"sim_time_s": 187.0, "coverage_3d_pct": 99.2}]
    assert mx.coverage_times(final, 0.0) == (None, None)
    assert mx.coverage_times(final, 5.0) == (187.0, 187.0)
    sampled = [{"sim_time_s": 5.0 * i, "coverage_3d_pct": c}
               for i, c in enumerate([10, 60, 92, 99.1])]
    assert mx.coverage_times(sampled, 5.0) == (10.0, 15.0)
    assert mx.coverage_times(sampled, None) == (10.0, 15.0)  # folders from before the key


def test_assemble_metrics_keys() -> None:
    record = mx.assemble_metrics(coverage_3d_pct=np.float64(97.5), robots=3, completed=True)
    assert tuple(record) == mx.METRICS_KEYS
    assert record["coverage_3d_pct"] == 97.5 and type(record["coverage_3d_pct"]) is float
    assert record["t99_s"] is None
    with pytest.raises(KeyError):
        mx.assemble_metrics(coverage=1.0)
