"""Edge server: submap store, merged cloud P* and merged grid."""

from __future__ import annotations

import numpy as np

from schemas.messages import Submap
from services.common.geometry import T_from_xyyaw, transform_points
from services.common.voxels import centres, unpack
from services.edge_server.config import EdgeConfig
from services.edge_server.merged_grid import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    MergedGrid,
    free_cells_world,
    world_cells,
)
from services.edge_server.merged_map import MergedMap, _first_observed
from services.edge_server.submap_store import SubmapStore

V = 0.05


def make_submap(
    robot: int, submap_id: int, seq: int, tick: int, T: np.ndarray, points_m: np.ndarray,
    free_cells: np.ndarray | None = None, color: int = 100,
) -> Submap:
    points_m = np.asarray(points_m, float).reshape(-1, 3)
    free = np.zeros((0, 2), np.int16) if free_cells is None else np.asarray(free_cells)
    return Submap(
        robot_id=robot, submap_id=submap_id, seq=seq, tick=tick, stamp_ns=tick * 10**8,
        T_world_submap=T, points_mm=np.round(points_m * 1000).astype(np.int16).T.copy(),
        colors=np.full((len(points_m), 3), color, np.uint8),
        counts=np.ones(len(points_m), np.uint16), free_cells=free.astype(np.int16).T.copy(),
        cell_m=V,
    )


def voxel_centres(idx: np.ndarray) -> np.ndarray:
    return (np.asarray(idx, float) + 0.5) * V


def test_delta_application_round_trip() -> None:
    store = SubmapStore(V)
    T = T_from_xyyaw(1.0, 2.0, 0.3)
    a = voxel_centres([[0, 0, 1], [1, 0, 1], [-3, 2, 4]])
    b = voxel_centres([[1, 0, 1], [5, 5, 5]])  # one known voxel, one new
    store.apply(make_submap(0, 0, 0, 1, T, a, np.array([[0, 0], [1, 0]]), color=10))
    sm = store.apply(make_submap(0, 0, 1, 2, T, b, np.array([[1, 0], [2, 0]]), color=20))
    got = np.round(centres(unpack(sm.keys), V) * 1000).astype(int)
    by_voxel = {tuple(p): (int(c), int(t)) for p, c, t in
                zip(got.tolist(), sm.colors[:, 0], sm.first_tick, strict=True)}
    assert by_voxel == {(25, 25, 75): (10, 1), (75, 25, 75): (20, 1),  # known voxel refreshed
                        (-125, 125, 225): (10, 1), (275, 275, 275): (20, 2)}
    assert sm.first_tick[-1] == 2  # new voxels are appended
    assert sorted(map(tuple, sm.free_cells.tolist())) == [(0, 0), (1, 0), (2, 0)]
    assert store.seq_gaps[0] == 0
    store.apply(make_submap(0, 0, 5, 3, T, b))
    assert store.seq_gaps[0] == 1


def test_merged_map_of_two_overlapping_submaps() -> None:
    store, merged = SubmapStore(V), MergedMap(V)
    idx = np.array([[i, 0, 2] for i in range(10)])
    # Robot 0's submap at the origin; robot 1's frame sits 0.25 m (5 voxels) further along x,
    # so its voxels 0..9 land on world voxels 5..14: 5 overlap.
    store.apply(make_submap(0, 0, 0, 1, np.eye(4), voxel_centres(idx), color=1))
    store.apply(make_submap(1, 0, 0, 2, T_from_xyyaw(0.25, 0, 0), voxel_centres(idx), color=2))
    assert merged.update(store)
    assert len(merged) == 15
    xs = np.round(merged.points_world[:, 0] / V - 0.5).astype(int)
    np.testing.assert_array_equal(np.sort(xs), np.arange(15))
    first = merged.robot_ids[np.argsort(xs)]
    assert first.tolist() == [0] * 10 + [1] * 5  # robot 0 saw the overlap first
    pts1, _ = merged.robot_cloud(1)
    assert len(pts1) == 10
    # Incremental delta, then a pose change (full rebuild) give the same as from scratch.
    store.apply(make_submap(1, 0, 1, 3, T_from_xyyaw(0.25, 0, 0), voxel_centres([[20, 0, 2]])))
    assert merged.update(store) and len(merged) == 16
    assert not merged.update(store)
    store.set_pose((1, 0), T_from_xyyaw(1.0, 0, 0))
    merged.update(store)
    fresh = MergedMap(V)
    fresh.update(store)
    np.testing.assert_array_equal(merged.keys, fresh.keys)
    np.testing.assert_array_equal(merged.robot_ids, fresh.robot_ids)
    assert len(merged) == 10 + 11 - 0  # robot 1 now starts at voxel 20


def robot_cloud_from_parts(
    merged: MergedMap, store: SubmapStore, robot: int
) -> tuple[np.ndarray, np.ndarray]:
    """The reference: every voxel of the robot's parts once, earliest tick first, at the
    store's current mean point of that first observation, moved by its submap's pose."""
    keyed = [(k, p) for k, p in sorted(merged._parts.items()) if k[0] == robot]
    if not keyed:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
    parts = [p for _, p in keyed]
    keys = np.concatenate([p.keys_world for p in parts])
    ticks = np.concatenate([p.first_tick for p in parts])
    points = np.concatenate([
        transform_points(store.submaps[k].T_world_submap, store.submaps[k].points[: p.n])
        for k, p in keyed])
    order = np.lexsort((ticks, keys))
    first = np.r_[True, keys[order][1:] != keys[order][:-1]]
    idx = order[first]
    colors = np.concatenate([p.colors for p in parts])[idx]
    return points[idx], colors


def test_robot_cloud_kept_up_to_date_equals_from_scratch() -> None:
    """A robot's own map, extended between queries and rebuilt when one of its submaps moves,
    equals one built from all of its parts (points and first-observer colours), whatever the
    query timing."""
    rng = np.random.default_rng(0)
    store, merged = SubmapStore(V), MergedMap(V)
    seq = {0: 0, 1: 0}
    poses = {(r, s): T_from_xyyaw(0.1 * s, 0.05 * r, 0.0) for r in (0, 1) for s in range(3)}
    rebuilds = 0
    for tick in range(1, 40):
        for _ in range(3):  # deltas: overlapping voxels, one colour per message
            robot, sub = int(rng.integers(2)), int(rng.integers(3))
            idx = rng.integers(0, 12, (int(rng.integers(1, 15)), 3))
            means = voxel_centres(idx) + rng.uniform(-0.02, 0.02, idx.shape)  # off-centre
            store.apply(make_submap(robot, sub, seq[robot], tick, poses[robot, sub],
                                    means, color=int(rng.integers(256))))
            seq[robot] += 1
        if rng.random() < 0.15:  # a corrected pose
            key = next(iter(sorted(store.submaps)))
            store.set_pose(key, T_from_xyyaw(rng.uniform(-0.2, 0.2), 0.0, rng.uniform(0, 1)))
            rebuilds += 1
        merged.update(store)
        if rng.random() < 0.6:  # the sampler does not query at every plan
            for robot in (0, 1):
                got, want = merged.robot_cloud(robot), robot_cloud_from_parts(merged, store, robot)
                np.testing.assert_allclose(got[0], want[0], atol=1e-6)
                np.testing.assert_array_equal(got[1], want[1])
    assert rebuilds > 0 and len(merged.robot_cloud(0)[0]) > 100


class Mirror:
    """A reader's copy of one map kept by `cloud_view` deltas (as the live sampler keeps it)."""

    def __init__(self) -> None:
        self.version, self.keys, self.points = -1, np.zeros(0, np.int64), np.zeros((0, 3))
        self.wholes = self.deltas = 0

    def sync(self, merged: MergedMap, robot: int) -> None:
        view = merged.cloud_view(robot, self.version)
        assert np.all(np.diff(view.keys) > 0)
        if view.delta:
            self.deltas += 1
            pos = np.searchsorted(self.keys, view.keys)
            held = pos < self.keys.size
            held[held] = self.keys[pos[held]] == view.keys[held]
            self.points[pos[held]] = view.points_world[held]
            self.keys = np.insert(self.keys, pos[~held], view.keys[~held])
            self.points = np.insert(self.points, pos[~held], view.points_world[~held], axis=0)
        else:
            self.wholes += 1
            self.keys, self.points = view.keys, view.points_world.astype(np.float64)
        self.version = view.version


def test_cloud_view_deltas_rebuild_the_whole_map() -> None:
    """A reader that applies each answer's changes holds exactly the whole map, through
    appended voxels, refined means and corrected poses, for P* and each robot's own map,
    whatever the query timing; and a delta is smaller than the map."""
    rng = np.random.default_rng(1)
    store, merged = SubmapStore(V), MergedMap(V)
    seq = {0: 0, 1: 0}
    poses = {(r, s): T_from_xyyaw(0.1 * s, 0.05 * r, 0.0) for r in (0, 1) for s in range(3)}
    mirrors = {robot: Mirror() for robot in (-1, 0, 1)}
    small = 0
    for tick in range(1, 60):
        for _ in range(3):
            robot, sub = int(rng.integers(2)), int(rng.integers(3))
            idx = rng.integers(0, 12, (int(rng.integers(1, 15)), 3))
            means = voxel_centres(idx) + rng.uniform(-0.02, 0.02, idx.shape)
            store.apply(make_submap(robot, sub, seq[robot], tick, poses[robot, sub], means))
            seq[robot] += 1
        if rng.random() < 0.1:
            key = next(iter(sorted(store.submaps)))
            store.set_pose(key, T_from_xyyaw(rng.uniform(-0.2, 0.2), 0.0, rng.uniform(0, 1)))
        merged.update(store)
        for robot, mirror in mirrors.items():
            if rng.random() < 0.5:
                continue
            before = merged.cloud_view(robot, mirror.version)
            small += before.delta and len(before.keys) < len(mirror.keys)
            mirror.sync(merged, robot)
            whole = merged.cloud_view(robot, -1)
            assert not whole.delta
            np.testing.assert_array_equal(mirror.keys, whole.keys)
            np.testing.assert_array_equal(mirror.points, whole.points_world)
    assert all(m.deltas > 5 for m in mirrors.values())
    assert mirrors[-1].wholes > 1 and mirrors[0].wholes > 1  # (0, 0) moved: rebuilds
    assert small > 10
    later = merged.cloud_view(-1, merged.cloud_version + 5)  # a version this edge never had
    assert not later.delta and len(later.keys) == len(merged)


def test_grid_from_free_cells_and_obstacles() -> None:
    config = EdgeConfig(grid_margin_m=0.5, grid_chunk_m=0.5)
    store, merged, grid = SubmapStore(V), MergedMap(V), MergedGrid(config)
    free = np.array([[i, j] for i in range(20) for j in range(10)])
    wall = voxel_centres([[10, j, k] for j in range(10) for k in range(1, 8)])  # z 0.075..0.375
    ceiling = voxel_centres([[5, 5, 30]])  # above the band: not an obstacle
    T = T_from_xyyaw(2.0, 3.0, 0.0)
    store.apply(make_submap(0, 0, 0, 1, T, np.concatenate([wall, ceiling]), free))
    merged.update(store)
    snap = grid.update(store, merged)
    assert snap is not None and snap.cells.dtype == np.int8
    spec = snap.spec
    def at(x: float, y: float) -> int:
        r, c = spec.cell_of(np.array([[x, y]]))[0]
        return int(snap.cells[r, c])
    assert at(2.0 + 0.125, 3.0 + 0.125) == FREE
    assert at(2.0 + 10.5 * V, 3.0 + 0.125) == OCCUPIED  # occupied wins over free
    assert at(2.0 + 5.5 * V, 3.0 + 5.5 * V) == FREE
    assert at(2.0 - 0.3, 3.0) == UNKNOWN
    assert (snap.cells == FREE).sum() == 200 - 10
    assert spec.origin_x <= 1.5 and spec.origin_x + spec.width * V >= 3.5


def test_merged_points_are_the_first_observers_latest_means() -> None:
    """P*'s point of a voxel is its first observer's mean point as last sent (not the voxel
    centre, which stair-steps surfaces); the keys, and so the grid, stay on the lattice."""
    store, merged = SubmapStore(V), MergedMap(V)
    store.apply(make_submap(0, 0, 0, 1, np.eye(4), np.array([[0.012, 0.013, 0.111]])))
    store.apply(make_submap(1, 0, 0, 2, np.eye(4), np.array([[0.040, 0.040, 0.140]])))
    merged.update(store)
    np.testing.assert_allclose(merged.points_world, [[0.012, 0.013, 0.111]], atol=1e-6)
    np.testing.assert_allclose(merged.centres_world, [[0.025, 0.025, 0.125]])
    store.apply(make_submap(0, 0, 1, 3, np.eye(4), np.array([[0.020, 0.021, 0.120]])))
    assert not merged.update(store)  # no new voxel ...
    np.testing.assert_allclose(merged.points_world, [[0.020, 0.021, 0.120]], atol=1e-6)  # refined
    np.testing.assert_allclose(merged.robot_cloud(1)[0], [[0.040, 0.040, 0.140]], atol=1e-6)
    store.set_pose((0, 0), T_from_xyyaw(1.0, 0.0, 0.0))  # moved: the point moves with it
    merged.update(store)
    np.testing.assert_allclose(merged.points_world, [[0.04, 0.04, 0.14], [1.02, 0.021, 0.12]],
                               atol=1e-6)


def test_grid_free_cells_cached_union_equals_from_scratch() -> None:
    """The stable submaps' free-cell union, kept incrementally, is the union of all of them
    after growth, new submaps, a late delta to an old submap and a pose correction."""
    rng = np.random.default_rng(3)
    store, grid = SubmapStore(V), MergedGrid(EdgeConfig())
    seq = {0: 0, 1: 0}

    def send(robot: int, submap: int, tick: int) -> None:
        T = T_from_xyyaw(0.3 * submap, 0.2 * robot, 0.1 * submap)
        store.apply(make_submap(robot, submap, seq[robot], tick, T, np.zeros((0, 3)),
                                rng.integers(-30, 30, (40, 2))))
        seq[robot] += 1

    def cells_of(g: MergedGrid) -> np.ndarray:
        newest = g._all_free_rc(store)
        counts = g._stable_counts
        held = np.argwhere(counts.counts > 0) + counts.origin
        return np.unique(np.concatenate([held, *newest]), axis=0)

    def from_scratch() -> np.ndarray:
        res = EdgeConfig().grid_resolution_m
        return np.unique(np.concatenate([world_cells(free_cells_world(sm), res)
                                         for sm in store.ordered()]), axis=0)

    merged, drawn = MergedMap(V), MergedGrid(EdgeConfig())

    def same_drawing() -> bool:
        """The grid drawn with the cached union's mask equals one drawn from scratch."""
        merged.update(store)
        snap, fresh = drawn.update(store, merged), MergedGrid(EdgeConfig()).update(store, merged)
        return snap.spec == fresh.spec and np.array_equal(snap.cells, fresh.cells)

    steps = [(0, 0), (1, 0), (0, 0), (0, 1), (1, 1), (0, 2), (0, 1), (1, 2), (1, 0)]
    for tick, (robot, submap) in enumerate(steps):
        send(robot, submap, tick)
        assert np.array_equal(cells_of(grid), from_scratch())
        assert same_drawing()
    store.set_pose((0, 1), T_from_xyyaw(0.5, -0.4, 0.7))  # a stable submap moves
    assert np.array_equal(cells_of(grid), from_scratch())
    assert same_drawing()
    send(0, 3, len(steps))  # the stable set gains a submap: drawn in, not redrawn
    assert same_drawing()
    assert len(grid._stable) == 4  # all but each robot's newest


def test_first_observer_is_the_earliest_tick_then_robot_then_entry() -> None:
    rng = np.random.default_rng(5)
    for n in (0, 1, 7, 5000):
        keys = rng.integers(0, max(n // 3, 1), n).astype(np.int64) * 7919  # many repeats
        ticks = rng.integers(0, 4, n).astype(np.int32)  # ... and ties on (tick, robot)
        robots = rng.integers(0, 3, n).astype(np.uint8)
        uniq, idx = _first_observed(keys, ticks, robots)
        order = np.lexsort((np.arange(n), robots, ticks, keys))  # the rule, spelled out
        first = np.ones(n, bool)
        first[1:] = keys[order][1:] != keys[order][:-1]
        assert np.array_equal(uniq, keys[order][first])
        assert np.array_equal(idx, order[first])


def test_merged_map_through_moves_equals_one_built_afresh() -> None:
    """P* kept by deltas and re-judged from the sorted observations when submaps move equals
    a map built from the store in one go: keys, first observers, colours, sources."""
    rng = np.random.default_rng(1)
    store, merged = SubmapStore(V), MergedMap(V)
    seq = {0: 0, 1: 0, 2: 0}
    moves = 0
    for tick in range(1, 60):
        for _ in range(4):
            robot, sub = int(rng.integers(3)), int(rng.integers(4))
            idx = rng.integers(0, 10, (int(rng.integers(1, 20)), 3))
            pose = T_from_xyyaw(0.05 * sub, 0.05 * robot, 0.1 * sub)
            store.apply(make_submap(robot, sub, seq[robot], tick, pose,  # ties within a tick
                                    voxel_centres(idx), color=int(rng.integers(256))))
            seq[robot] += 1
        if rng.random() < 0.3:  # a merger correction moves one or two submaps
            for key in rng.permutation(sorted(store.submaps))[: int(rng.integers(1, 3))]:
                store.set_pose(tuple(key), T_from_xyyaw(*rng.uniform(-0.2, 0.2, 2),
                                                        rng.uniform(-1, 1)))
            moves += 1
        merged.update(store)
        fresh = MergedMap(V)
        fresh.update(store)
        for name in ("keys", "robot_ids", "src_idx"):
            np.testing.assert_array_equal(getattr(merged, name), getattr(fresh, name), name)
        # uids number parts in the order each map first saw them
        assert sources(merged) == sources(fresh)
        # a voxel's colour is its first observer's as the part took it (later deltas of a
        # known voxel refresh the store's colour, not the part's)
        parts = {p.uid: p for p in merged._parts.values()}
        want = np.array([parts[u].colors[i] for u, i in zip(merged.src_uid, merged.src_idx,
                                                            strict=True)]).reshape(-1, 3)
        np.testing.assert_array_equal(merged.colors, want)
    assert moves > 5 and len(merged) > 300


def sources(merged: MergedMap) -> list[tuple[int, int, int]]:
    key_of = {u: k for k, u in merged._uids.items()}
    return [(*key_of[int(u)], int(i)) for u, i in zip(merged.src_uid, merged.src_idx,
                                                       strict=True)]
