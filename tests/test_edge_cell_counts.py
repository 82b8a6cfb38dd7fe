"""Counted cell sets: a union that forgets the cells of a set taken out."""

from __future__ import annotations

import numpy as np

from services.common.grid import GridSpec
from services.edge_server.cell_counts import CellCounts


def test_counts_hold_the_union_of_the_sets_still_in() -> None:
    rng = np.random.default_rng(0)
    sets = [np.unique(rng.integers(-300, 300, (200, 2)), axis=0) for _ in range(6)]
    counts = CellCounts()
    for rc in sets:
        counts.add(rc, +1)
    counts.add(sets[2], -1)  # moved away
    counts.add(sets[5], -1)
    union = np.unique(np.concatenate([sets[i] for i in (0, 1, 3, 4)]), axis=0)
    np.testing.assert_array_equal(np.argwhere(counts.counts > 0) + counts.origin, union)
    np.testing.assert_array_equal(counts.extremes(), [union.min(axis=0), union.max(axis=0)])
    spec = GridSpec(origin_x=-5.0, origin_y=2.0, resolution_m=0.05, height=300, width=250)
    mask = np.zeros(spec.shape, bool)
    counts.draw(mask, spec)
    want = np.zeros(spec.shape, bool)
    rc = union - np.array([40, -100])  # origin (y, x) / resolution
    rc = rc[spec.contains(rc)]
    want[rc[:, 0], rc[:, 1]] = True
    assert want.any() and not want.all()
    np.testing.assert_array_equal(mask, want)
    for i in (0, 1, 3, 4):
        counts.add(sets[i], -1)
    assert counts.extremes().shape == (0, 2) and not counts.counts.any()
