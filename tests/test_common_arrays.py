"""Sort-based unique helpers equal np.unique."""

import numpy as np

from services.common.arrays import (
    column_extremes,
    in_sorted,
    insert_rows,
    missing_rows_2,
    row_items,
    union_rows_2,
    unique_first,
    unique_groups,
    unique_rows_2,
    unique_sorted,
)
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
    members = unique_sorted(k[::3])
    assert np.array_equal(in_sorted(k, members), np.isin(k, members))
    assert not in_sorted(k, np.zeros(0, np.int64)).any()
    for a in (rc, rng.normal(size=(50, 3)).astype(np.float32)):
        lo, hi = column_extremes(a)
        assert np.array_equal(lo, a.min(axis=0)) and np.array_equal(hi, a.max(axis=0))
        assert lo.dtype == a.dtype
    known = unique_rows_2(rc[::2])
    want = np.array([r for r in rc if not any((known == r).all(axis=1))]).reshape(-1, 2)
    assert np.array_equal(missing_rows_2(rc, known), want) and len(want)


def test_union_rows_2_equals_a_unique_of_both() -> None:
    rng = np.random.default_rng(1)
    for n_old, n_more in [(0, 0), (0, 40), (300, 0), (300, 40), (5, 400)]:
        old = unique_rows_2(rng.integers(-30, 30, (n_old, 2)))
        more = rng.integers(-40, 40, (n_more, 2))
        shared = min(n_more // 2, len(old))  # half of `more` already known
        more[:shared] = old[:shared]
        union = union_rows_2(old, more)
        assert np.array_equal(union, np.unique(np.concatenate([old, more]).reshape(-1, 2),
                                               axis=0)), (n_old, n_more)
        assert union.dtype == np.int64 and union.shape[1] == 2


def test_diff_of_sorted_sets() -> None:
    old, new = np.array([1, 3, 5, 7]), np.array([0, 3, 4, 7, 9])
    added, removed = _diff(old, new)
    assert added.tolist() == [0, 4, 9] and removed.tolist() == [1, 5]
    added, removed = _diff(np.zeros(0, np.int64), new)
    assert added.tolist() == new.tolist() and removed.size == 0


def test_unique_groups_equals_numpy() -> None:
    rng = np.random.default_rng(2)
    for keys in [rng.integers(-20, 20, 1000), np.repeat(rng.integers(0, 9, 50), 7),
                 np.zeros(0, np.int64), np.array([5])]:
        got = unique_groups(keys)
        want = np.unique(keys, return_index=True, return_inverse=True, return_counts=True)
        for g, w in zip(got, want, strict=True):
            assert np.array_equal(g, w) and g.dtype == w.dtype, keys[:5]


def test_insert_rows_and_row_items_move_whole_rows() -> None:
    rng = np.random.default_rng(4)
    for a in (rng.integers(0, 255, (40, 3)).astype(np.uint8), rng.normal(size=(40, 3)),
              rng.integers(0, 9, 40)):
        at = np.sort(rng.integers(0, len(a) + 1, 7))
        rows = a[:7] + 1
        assert np.array_equal(insert_rows(a, at, rows), np.insert(a, at, rows, axis=0))
        out = np.zeros_like(a)
        mask = rng.random(len(a)) < 0.5
        row_items(out)[mask] = row_items(a[mask].copy())
        want = np.zeros_like(a)
        want[mask] = a[mask]
        assert np.array_equal(out, want)
        empty = a[:0]
        assert np.array_equal(insert_rows(empty, np.zeros(2, int), a[:2]), a[:2])
