"""The live scorer's look-ups: truth around points (dense table and packed-key fallback alike),
and the ghost test's shortcut, each against a plain distance computation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from schemas import messages as m
from services.common.grid import GridSpec
from services.evaluator import metrics as mx
from services.evaluator import truth_cells
from services.evaluator.config import EvalConfig
from services.evaluator.free_space import FreeGrid
from services.evaluator.ground_truth import GroundTruth
from services.evaluator.incremental import LiveQuality
from services.evaluator.scoring import Probe, grid_spec, map_quality
from services.evaluator.truth_cells import TruthIndex
from tests.test_eval_incremental import assert_same, box_probe, lattice, step

R = 0.10


def truth_and_points(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    truth = rng.uniform(0, 2, (3000, 3))
    pts = np.concatenate([rng.uniform(-0.3, 2.3, (60, 3)),  # some outside the truth's box
                          rng.uniform(40, 50, (5, 3))])     # far outside it (clamped)
    return truth, pts


@pytest.fixture(params=["dense", "packed"])
def table(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    if request.param == "packed":
        monkeypatch.setattr(truth_cells, "MAX_TABLE_CELLS", 0)
    return request.param


@pytest.mark.parametrize("seed", range(3))
def test_around_holds_every_truth_point_within_the_radius(seed: int, table: str) -> None:
    truth, pts = truth_and_points(seed)
    index = TruthIndex(truth, R)
    assert index.dense == (table == "dense")
    near = np.flatnonzero((cdist(truth, pts) <= R).any(axis=1))
    found = index.around(pts)
    assert np.unique(found).size == found.size  # each truth point once
    assert np.isin(near, found).all()
    assert found.size < 0.5 * len(truth)  # and not the whole truth


@pytest.mark.parametrize("seed", range(3))
def test_near_cells_hold_every_point_within_the_radius(seed: int, table: str) -> None:
    truth, pts = truth_and_points(seed)
    index = TruthIndex(truth, R)
    some = np.arange(0, len(truth), 7)
    close = (cdist(pts, truth[some]) <= R).any(axis=1)
    near = index.near_cells(index.cells_of(pts), some)
    assert close.any() and near[close].all()
    assert not near.all()


def test_the_ghost_shortcut_equals_the_distance_test() -> None:
    """Points in a cell holding a surface sample pass unasked; the rest are asked, with a
    search bound that still keeps distances of exactly the threshold."""
    rng = np.random.default_rng(3)
    for ev in (EvalConfig(), EvalConfig(ghost_dist_m=0.03)):
        probe = box_probe(1, ev)
        surface = probe.gt.surface_points_world
        g = ev.ghost_dist_m
        pts = np.concatenate([surface[rng.integers(0, len(surface), 4000)]
                              + rng.normal(0.0, g, (4000, 3)),
                              surface[:50] + [0.0, 0.0, g],  # at the threshold, or an ulp off
                              surface[50:100] + [0.0, 0.0, np.nextafter(g, 1)]])
        expected = probe.surface_distance(pts) <= g
        assert np.array_equal(probe.near_surface(pts), expected)
        assert 0.1 < expected.mean() < 0.9


@pytest.mark.parametrize("seed", range(2))
def test_the_fallback_table_scores_like_map_quality(seed: int, table: str) -> None:
    rng = np.random.default_rng(seed)
    probe = box_probe(seed)
    maps = [lattice(rng, 200) for _ in range(2)]
    scorer = LiveQuality(probe)
    assert scorer.truth.dense == (table == "dense")
    for _ in range(6):
        maps = [step(rng, p) for p in maps]
        merged = np.unique(np.concatenate(maps), axis=0)
        assert_same(scorer(merged, maps), map_quality(probe, merged, maps))


def test_probe_coverage_2d_equals_the_metric_as_the_grid_changes() -> None:
    """The free truth cells' places are kept per grid geometry: a grown or moved grid is
    looked up afresh."""
    rng = np.random.default_rng(2)
    truth_spec = GridSpec(0.0, 0.0, 0.05, 40, 50)
    free = rng.random(truth_spec.shape) < 0.6
    probe = Probe(GroundTruth(FreeGrid(truth_spec, ~free, free, free), np.zeros((1, 3)),
                              np.ones(1, bool), np.ones(1, bool)), EvalConfig())
    seen = set()
    for origin, shape in [((-0.3, -0.2), (30, 30)), ((-0.3, -0.2), (30, 30)),
                          ((-0.3, -0.2), (60, 70)), ((0.51, 0.27), (25, 40))]:
        cells = np.where(rng.random(shape) < 0.7, 0, -1).astype(np.int8)
        grid = m.OccupancyGrid(tick=1, origin_x=origin[0], origin_y=origin[1],
                               resolution_m=0.05, cells=cells)
        want = mx.coverage_2d(cells >= 0, grid_spec(grid), free, truth_spec)
        assert probe.coverage_2d(grid) == want
        seen.add(round(want, 6))
    assert len(seen) > 2
