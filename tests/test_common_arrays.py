"""Sort-based unique helpers equal np.unique."""

import numpy as np

from services.common.arrays import unique_first, unique_rows_2, unique_sorted
from services.edge_server.frontier_cache import _diff


def test_unique_helpers_match_numpy() -> None:
    rng = np.random.default_rng(0)
    k = rng.integers(-50, 50, 500)
    assert np.array_equal(unique_sorted(k), np.unique(k))
    u, first = unique_first(k)
    ru, rfirst = np.unique(k, return_index=True)
    assert np.array_equal(u, ru) and np.array_equal(first, rfirst)
    rc = rng.integers(-(2**20), 2**20, (500, 2))
    rc[100:200] = rc[:100]
    assert np.array_equal(unique_rows_2(rc), np.unique(rc, axis=0))
    assert unique_sorted(np.zeros(0, np.int64)).size == 0
    assert unique_rows_2(np.zeros((0, 2), np.int64)).shape == (0, 2)


def test_diff_of_sorted_sets() -> None:
    old, new = np.array([1, 3, 5, 7]), np.array([0, 3, 4, 7, 9])
    added, removed = _diff(old, new)
    assert added.tolist() == [0, 4, 9] and removed.tolist() == [1, 5]
    added, removed = _diff(np.zeros(0, np.int64), new)
    assert added.tolist() == new.tolist() and removed.size == 0
