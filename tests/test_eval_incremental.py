"""The incremental live scorer equals `map_quality` from scratch, exactly, while maps grow,
lose points (pose corrections) and move them."""

from __future__ import annotations

import numpy as np
import pytest

from services.common import voxels
from services.common.grid import GridSpec
from services.evaluator.config import EvalConfig
from services.evaluator.free_space import FreeGrid
from services.evaluator.ground_truth import GroundTruth
from services.evaluator.incremental import LiveQuality, MapTally
from services.evaluator.metrics import covered_mask
from services.evaluator.scoring import Probe, map_quality
from services.evaluator.truth_cells import TruthIndex

VOXEL_M = 0.05
SERIES_KEYS = ("coverage_3d_pct", "overlap_3d_pct", "bounding_volume_pct", "ghost_volume_m3")


def box_probe(seed: int = 0, ev: EvalConfig | None = None) -> Probe:
    """Truth on the floor and one wall of a 1 m box; half of it observable."""
    rng = np.random.default_rng(seed)
    floor = np.c_[rng.uniform(0, 1, (1500, 2)), np.zeros(1500)]
    wall = np.c_[np.zeros(800), rng.uniform(0, 1, (800, 2))]
    pts = np.concatenate([floor, wall])
    spec = GridSpec(0.0, 0.0, VOXEL_M, 20, 20)
    ones = np.ones(spec.shape, bool)
    seen = rng.random(len(pts)) < 0.5
    return Probe(GroundTruth(FreeGrid(spec, ~ones, ones, ones), pts, seen, seen),
                 ev or EvalConfig())


def lattice(rng: np.random.Generator, n: int) -> np.ndarray:
    """n distinct 5 cm voxel centres (float32, as a Cloud carries them) in and around the box,
    some far from any surface (ghosts)."""
    idx = np.unique(rng.integers(-2, 22, (3 * n, 3)), axis=0)
    idx = idx[rng.permutation(len(idx))[:n]]
    return voxels.centres(idx, VOXEL_M).astype(np.float32).astype(np.float64)


def step(rng: np.random.Generator, pts: np.ndarray) -> np.ndarray:
    """The next sample of a map: new voxels, some removed, some moved (a corrected pose)."""
    keep = pts[rng.random(len(pts)) > 0.15]
    moved = rng.random(len(keep)) < 0.1
    keep[moved] += rng.integers(-1, 2, (int(moved.sum()), 3)) * VOXEL_M
    merged = np.concatenate([keep, lattice(rng, int(rng.integers(0, 150)))])
    _, first = np.unique(voxels.pack(voxels.voxel_indices(merged, VOXEL_M)), return_index=True)
    return merged[rng.permutation(first)]  # one point per voxel, in any order


def assert_same(live: dict, scratch: dict) -> None:
    for key in SERIES_KEYS:
        assert live[key] == scratch[key], key  # exact: the last row must equal metrics.json


# a ghost_dist below the coverage radius lets a ghost lie near truth it must not cover
CONFIGS = [EvalConfig(), EvalConfig(ghost_dist_m=0.03, coverage_radius_m=0.12)]


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("ev", CONFIGS, ids=["default", "short-ghost-dist"])
def test_random_add_remove_move_sequences_match_map_quality(seed: int, ev: EvalConfig) -> None:
    rng = np.random.default_rng(seed)
    probe = box_probe(seed, ev)
    maps = [lattice(rng, 200) for _ in range(3)]
    scorer = LiveQuality(probe)
    for _ in range(12):
        maps = [step(rng, p) for p in maps]
        merged = np.concatenate(maps)
        _, first = np.unique(voxels.pack(voxels.voxel_indices(merged, VOXEL_M)),
                             return_index=True)
        merged = merged[np.sort(first)]
        assert_same(scorer(merged, maps), map_quality(probe, merged, maps))
    assert 0 < scorer.merged.n_ghost < scorer.merged.n_voxels  # the test saw both kinds


def test_emptied_map_and_no_robot_maps() -> None:
    rng = np.random.default_rng(7)
    probe = box_probe()
    scorer = LiveQuality(probe)
    pts = lattice(rng, 300)
    assert_same(scorer(pts, None), map_quality(probe, pts, None))
    assert scorer(np.zeros((0, 3)), []) == {k: (None if k == "overlap_3d_pct" else 0.0)
                                           for k in SERIES_KEYS}


def test_radius_bound_is_strict_like_covered_mask() -> None:
    """Truth points at exactly the radius (in float arithmetic or one ulp off), or on the
    point, are covered exactly when `covered_mask` says so, as points come and go."""
    centre = np.array([[0.025, 0.025, 0.025]])
    r = 0.10
    offsets = np.array([r, np.nextafter(r, 0), np.nextafter(r, 1), 0.5 * r, 0.0])
    truth = np.concatenate([centre + np.outer(offsets, axis) for axis in np.eye(3)])
    truth = np.concatenate([truth, centre + np.c_[offsets, offsets, 0 * offsets] / np.sqrt(2),
                            centre - np.c_[offsets, 0 * offsets, offsets] / np.sqrt(2)])
    tally = MapTally(TruthIndex(truth, r), VOXEL_M, None)
    other = centre + 3 * VOXEL_M
    for pts in (centre, np.concatenate([centre, other]), other, centre):
        assert tally.update(pts)
        assert np.array_equal(tally.covered, covered_mask(pts, truth, r))
    assert 0 < tally.covered.sum() < len(truth)


def test_a_point_moved_inside_its_voxel_is_scored_again() -> None:
    """Same voxel key, new coordinates (a cloud that is not voxel centres)."""
    probe = box_probe()
    rng = np.random.default_rng(4)
    pts = lattice(rng, 300)
    scorer = LiveQuality(probe)
    scorer(pts, [pts])
    for shift in (0.024, -0.024):
        moved = pts + np.array([0.0, 0.0, shift])
        assert_same(scorer(moved, [moved]), map_quality(probe, moved, [moved]))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("ev", CONFIGS, ids=["default", "short-ghost-dist"])
def test_several_points_in_a_voxel_match_map_quality(seed: int, ev: EvalConfig) -> None:
    """Maps of voxel means, as the edge sends: several points to a voxel of `voxel_m`, a
    voxel a ghost only when all of them are, points that come, go and move in their voxel."""
    rng = np.random.default_rng(10 + seed)
    probe = box_probe(seed, ev)

    def means(n: int) -> np.ndarray:
        centres = lattice(rng, n)
        jitter = rng.uniform(-0.024, 0.024, (3 * n, 3))  # three to a voxel, some in others'
        return (np.repeat(centres, 3, axis=0) + jitter).astype(np.float32).astype(np.float64)

    maps = [means(150) for _ in range(3)]
    scorer = LiveQuality(probe)
    for _ in range(10):
        maps = [np.concatenate([p[rng.random(len(p)) > 0.15], means(40)]) for p in maps]
        merged = np.concatenate(maps)
        assert_same(scorer(merged, maps), map_quality(probe, merged, maps))
        moved = rng.random(len(maps[0])) < 0.2
        maps[0][moved] += rng.uniform(-0.02, 0.02, (int(moved.sum()), 3))
    keys = voxels.pack(voxels.voxel_indices(merged, VOXEL_M))
    assert np.unique(keys).size < 0.6 * len(keys)  # the maps did share voxels
    assert 0 < scorer.merged.n_ghost < scorer.merged.n_voxels


def test_a_point_held_twice_falls_back_to_map_quality() -> None:
    probe = box_probe()
    rng = np.random.default_rng(3)
    pts = lattice(rng, 100)
    twin = np.concatenate([pts, pts[:5]])
    scorer = LiveQuality(probe)
    tally = MapTally(scorer.truth, VOXEL_M, None)
    assert not tally.update(twin) and tally.ids.size == 0
    assert_same(scorer(twin, [twin, pts]), map_quality(probe, twin, [twin, pts]))
    assert_same(scorer(pts, [pts, pts]), map_quality(probe, pts, [pts, pts]))


def test_a_sample_scores_only_new_points(monkeypatch: pytest.MonkeyPatch) -> None:
    """Unchanged points are not looked up again: the cost of a sample is what changed."""
    rng = np.random.default_rng(5)
    scorer = LiveQuality(box_probe())
    pts = lattice(rng, 400)
    scorer(pts, [pts])
    looked_up: list[int] = []
    real = TruthIndex.around
    monkeypatch.setattr(TruthIndex, "around",
                        lambda self, p: looked_up.append(len(p)) or real(self, p))
    more = np.concatenate([pts, lattice(rng, 30)])
    more = more[np.unique(voxels.pack(voxels.voxel_indices(more, VOXEL_M)),
                          return_index=True)[1]]
    scorer(more, [more])
    assert sum(looked_up) <= 2 * (len(more) - len(pts))


def test_the_same_final_maps_are_scored_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """A mission's end scores its final maps as the series' last row (float32 cloud) and as
    metrics.json (float64 read back from the PLY files): the second call gives the first's
    figures without scoring; other maps are scored again."""
    import services.evaluator.scoring as scoring

    probe = box_probe()
    rng = np.random.default_rng(11)
    pts = lattice(rng, 300).astype(np.float32)
    robots = [pts[:150], pts[150:]]
    calls = []
    real = scoring._map_quality
    monkeypatch.setattr(scoring, "_map_quality", lambda *a: calls.append(1) or real(*a))
    first = map_quality(probe, pts, robots)
    again = map_quality(probe, pts.astype(np.float64), [r.astype(np.float64) for r in robots])
    assert again == first and len(calls) == 1
    assert map_quality(probe, pts, None)["overlap_3d_pct"] is None and len(calls) == 2
    moved = pts.copy()
    moved[0, 0] += 0.5
    assert map_quality(probe, moved, robots) != first and len(calls) == 3
