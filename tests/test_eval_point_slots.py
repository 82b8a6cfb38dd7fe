"""The tallies' slot store: appended, killed and compacted points keep the figures exact."""

from __future__ import annotations

import numpy as np
import pytest

from services.evaluator import point_slots
from services.evaluator.incremental import LiveQuality
from services.evaluator.point_slots import PointSlots
from services.evaluator.scoring import map_quality
from tests.test_eval_incremental import assert_same, box_probe, lattice, step


def test_compaction_moves_live_slots_to_the_front(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(point_slots, "MIN_CAPACITY", 2)
    store = PointSlots()
    n = 6
    slots = store.append(np.arange(n, dtype=np.uint64), np.arange(3 * n, dtype=float).reshape(n, 3),
                         np.ones(n, bool), np.ones(n, bool), np.arange(n), np.arange(n))
    assert np.array_equal(slots, np.arange(n)) and store.compact() is None
    store.kill(np.array([0, 2, 3]))
    assert not store.counting[[0, 2, 3]].any()
    moved = store.compact()
    assert moved is not None and np.array_equal(moved, [-1, 0, -1, -1, 1, 2])
    assert np.array_equal(store.used("ids"), [1, 4, 5])
    assert np.array_equal(store.used("points")[:, 0], [3.0, 12.0, 15.0])
    assert store.used("alive").all() and store.dead == 0


@pytest.mark.parametrize("seed", range(3))
def test_figures_stay_exact_through_compactions(seed: int,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(point_slots, "MIN_CAPACITY", 4)
    compactions = []
    real = PointSlots.compact
    monkeypatch.setattr(PointSlots, "compact",
                        lambda self: (lambda moved: compactions.append(moved is not None)
                                      or moved)(real(self)))
    rng = np.random.default_rng(seed)
    probe = box_probe(seed)
    maps = [lattice(rng, 200) for _ in range(2)]
    scorer = LiveQuality(probe)
    for _ in range(8):
        maps = [step(rng, p) for p in maps]
        merged = np.unique(np.concatenate(maps), axis=0)
        assert_same(scorer(merged, maps), map_quality(probe, merged, maps))
    assert any(compactions)
