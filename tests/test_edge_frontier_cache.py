"""Incremental Alg. 1 (frontier_cache.py) equals the from-scratch lattice kernel."""

import numpy as np

from services.common.voxels import pack
from services.edge_server.frontier_cache import IncrementalFrontiers
from services.edge_server.frontiers3d import lattice_frontiers

V, R, DD, DV = 0.05, 0.15, 27.0, 0.0128


def _cloud(rng: np.random.Generator, n: int, lo: int = 0) -> np.ndarray:
    idx = rng.integers(lo, lo + 20, size=(n, 3))
    return np.unique(pack(idx), axis=0)


def _check(inc: IncrementalFrontiers, keys: np.ndarray, z_max: float = np.inf, **kw) -> None:
    got = inc.update(keys, **kw)
    from services.common.voxels import unpack
    idx = unpack(keys)
    ref = lattice_frontiers(idx, V, R, DD, DV)
    keep = (idx[:, 2] + 0.5) * V <= z_max
    assert np.array_equal(got.indices, idx[keep])
    assert np.array_equal(got.rho, ref.rho[keep])
    np.testing.assert_allclose(got.var_m2, ref.var_m2[keep], atol=1e-12)
    assert np.array_equal(got.weak, ref.weak[keep])
    assert np.array_equal(got.unexplored, ref.unexplored[keep])
    assert got.full_count == ref.full_count


def test_incremental_matches_full_through_growth_and_removal():
    rng = np.random.default_rng(0)
    inc = IncrementalFrontiers(V, R, DD, DV)
    keys = _cloud(rng, 1500)
    _check(inc, keys)
    more = np.union1d(keys, _cloud(rng, 800, lo=15))  # grows the box
    _check(inc, more, added=np.setdiff1d(more, keys))
    fewer = more[rng.random(more.size) < 0.7]  # removal (a rebuilt P*): set difference path
    _check(inc, fewer)
    far = np.union1d(fewer, _cloud(rng, 300, lo=-70))  # far outside the box, negative indices
    _check(inc, far)
    gone = far[rng.random(far.size) < 0.2]  # a rebuild that says what it added and removed
    new = np.setdiff1d(_cloud(rng, 400, lo=5), far)
    moved = np.union1d(np.setdiff1d(far, gone), new)
    _check(inc, moved, added=new, removed=gone)


def test_z_crop_returns_only_low_voxels():
    rng = np.random.default_rng(1)
    inc = IncrementalFrontiers(V, R, DD, DV, z_max_m=0.5)
    _check(inc, _cloud(rng, 2000), z_max=0.5)


def test_z_crop_keeps_no_cell_above_the_cap_and_stays_exact_through_changes():
    # cells above the highest centre read are not kept; voxels up to r_s above it still count
    rng = np.random.default_rng(4)
    z_max = 0.42  # centres up to lattice z 7 are read
    inc = IncrementalFrontiers(V, R, DD, DV, z_max_m=z_max)
    keys = _cloud(rng, 3000)  # z 0..19: most of the cloud above the cap
    _check(inc, keys, z_max=z_max)
    assert inc.stats.lo[2] + inc.stats.dims[2] == 10  # cells up to z_cap = floor(8.4) + 1 = 9
    more = np.union1d(keys, _cloud(rng, 900, lo=6))  # grows, much of it in the band
    _check(inc, more, z_max, added=np.setdiff1d(more, keys))
    low = np.union1d(more, _cloud(rng, 500, lo=-40))  # below: the box grows down
    _check(inc, low, z_max)
    gone = low[rng.random(low.size) < 0.3]
    _check(inc, np.setdiff1d(low, gone), z_max, added=np.zeros(0, np.int64), removed=gone)


def test_incremental_obstacle_cells_equal_a_fresh_grid() -> None:
    from services.common.geometry import T_from_xyyaw
    from services.edge_server.config import EdgeConfig
    from services.edge_server.merged_grid import MergedGrid
    from services.edge_server.merged_map import MergedMap
    from services.edge_server.submap_store import SubmapStore
    from tests.test_edge_map import make_submap

    rng = np.random.default_rng(2)
    cfg = EdgeConfig(grid_bounds_m=(-1.0, -1.0, 3.0, 3.0))
    store, merged, grid = SubmapStore(V), MergedMap(V), MergedGrid(cfg)
    free = np.argwhere(np.ones((20, 20), bool))
    for seq in range(3):
        pts = rng.uniform([0, 0, 0], [2, 2, 0.8], (300, 3))
        store.apply(make_submap(0, 0, seq, 0, np.eye(4), pts, free))
        merged.update(store)
        snap = grid.update(store, merged)  # incremental after the first
        fresh = MergedGrid(cfg).update(store, merged)
        assert np.array_equal(snap.cells, fresh.cells)
        assert snap.occupied.any()
    store.apply(make_submap(1, 0, 0, 1, np.eye(4), rng.uniform([0, 0, 0], [2, 2, 0.8], (300, 3)),
                            free))
    for yaw in (0.3, -0.5):  # merger corrections: P* rebuilt, voxels removed and added
        store.set_pose((0, 0), T_from_xyyaw(0.2, -0.1, yaw))
        assert merged.update(store) and merged.removed_keys.size and merged.added_keys.size
        snap = grid.update(store, merged)
        fresh = MergedGrid(cfg).update(store, merged)
        assert np.array_equal(snap.cells, fresh.cells)


def test_a_map_growing_one_way_reallocates_the_box_a_few_times_only() -> None:
    # each reallocation copies the whole box (10⁸ cells in the warehouse): a side that grows
    # takes a margin, so a robot driving 40 m reallocates O(log) times, not every 1.6 m
    rng = np.random.default_rng(3)
    inc = IncrementalFrontiers(V, R, DD, DV)
    keys = np.zeros(0, np.int64)
    shapes = []
    for step in range(100):
        idx = rng.integers(0, 20, size=(200, 3)) + np.array([8 * step, 0, 0])
        keys = np.union1d(keys, pack(idx))
        inc.update(keys)
        shapes.append(tuple(inc.stats.dims))
    reallocations = sum(a != b for a, b in zip(shapes, shapes[1:], strict=False))
    assert inc.stats.dims[0] >= 8 * 99 + 20
    assert reallocations <= 12
    _check(inc, keys)


def test_the_compiled_read_is_the_numpy_read_bit_for_bit(monkeypatch) -> None:
    """ρ and σ² of a large map in one compiled pass (compiled_stats.py): every array equal to
    the numpy path's to the last bit, through growth and removal."""
    from services.edge_server import frontier_cache

    rng = np.random.default_rng(5)
    dense = _cloud(rng, 6000)  # full balls: σ² at the stencil's own
    sparse = np.unique(pack(rng.integers(-60, 60, size=(3000, 3))))  # lone voxels: ρ 1, σ² 0
    steps = [np.union1d(dense, sparse)]
    steps.append(np.union1d(steps[0], _cloud(rng, 2000, lo=18)))
    steps.append(steps[1][rng.random(steps[1].size) < 0.8])
    runs = []
    for compiled_from in (10**12, 0):
        monkeypatch.setattr(frontier_cache, "COMPILED_FROM", compiled_from)
        inc = IncrementalFrontiers(V, R, DD, DV, z_max_m=0.6)
        runs.append([inc.update(keys) for keys in steps])
    for a, b in zip(*runs, strict=True):
        assert a.weak.any() and a.unexplored.any() and (a.var_m2 == 0).any()
        for name in ("indices", "points_world", "rho", "var_m2", "unexplored", "weak"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), name
