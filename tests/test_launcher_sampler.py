"""The live sampler against a real merged map: it asks the edge for what changed since its
last sample and still scores every row exactly as `map_quality` scores the whole maps."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from schemas import Keys, decode, encode
from schemas import messages as m
from services.common.geometry import T_from_xyyaw
from services.edge_server.merged_map import MergedMap
from services.edge_server.node import cloud_reply
from services.edge_server.submap_store import SubmapStore
from services.evaluator.scoring import map_quality
from services.launcher.sampler import CoverageSampler
from tests.test_edge_map import V, make_submap
from tests.test_eval_overlap import probe


class MapEdge:
    """Answers `map/cloud` from a real MergedMap with the edge's own reply, through the codec."""

    def __init__(self, merged: MergedMap) -> None:
        self.keys, self.merged, self.tick = Keys(), merged, 0
        self.planner = SimpleNamespace(merged=merged)
        self.replies: list[m.Cloud] = []

    def query(self, key: str, request: m.CloudRequest, model: type, timeout: float) -> m.Cloud:
        assert key == self.keys.map_cloud() and model is m.Cloud
        reply = cloud_reply(self.planner, self.tick, encode(request), 1 << 26)  # type: ignore[arg-type]
        self.replies.append(reply)
        return decode(encode(reply), m.Cloud)


class Monitor:
    def __init__(self, bus: MapEdge, robots: int) -> None:
        self.bus, self.robots, self.recent_grids = bus, robots, {}

    def at_tick(self, tick: int) -> tuple[None, int]:
        return None, 0


def floor_points(rng: np.random.Generator, n: int) -> np.ndarray:
    """Points on the 2 m floor of `probe()` (voxel means off their centres), a few of them
    ghosts 0.3-0.6 m above it."""
    pts = np.c_[rng.uniform(0.0, 0.5, (n, 2)), rng.uniform(0.0, 0.04, n)]
    ghost = rng.random(n) < 0.1
    pts[ghost, 2] = rng.uniform(0.3, 0.6, ghost.sum())
    return pts


def test_samples_of_changes_score_as_the_whole_maps() -> None:
    rng = np.random.default_rng(4)
    pr, store, merged = probe(), SubmapStore(V), MergedMap(V)
    edge = MapEdge(merged)
    monitor = Monitor(edge, 2)
    sampler = CoverageSampler(monitor, pr, 5.0, 0.1)  # type: ignore[arg-type]
    seq = {0: 0, 1: 0}
    poses = {(r, s): T_from_xyyaw(0.5 * s + 0.2 * r, 0.3 * r + 0.4 * s, 0.0)
             for r in (0, 1) for s in range(3)}
    for tick in range(1, 25):
        for _ in range(4):  # new voxels and refined means of ones already held
            robot, sub = int(rng.integers(2)), int(rng.integers(3))
            store.apply(make_submap(robot, sub, seq[robot], tick, poses[robot, sub],
                                    floor_points(rng, int(rng.integers(5, 40)))))
            seq[robot] += 1
        if tick % 7 == 0:  # a corrected pose: that robot's map and P* are rebuilt
            key = sorted(store.submaps)[int(rng.integers(len(store.submaps)))]
            store.set_pose(key, store.submaps[key].T_world_submap @ T_from_xyyaw(0.02, 0, 0.01))
        merged.update(store)
        edge.tick = monitor.recent_grids[tick] = tick
        sampler.sample()
        row = sampler.rows[-1]
        whole = [merged.points_world] + [merged.robot_cloud(r)[0] for r in (0, 1)]
        want = map_quality(pr, *[p.astype(np.float64) for p in whole[:1]], whole[1:])
        for key in ("coverage_3d_pct", "overlap_3d_pct", "bounding_volume_pct"):
            assert row[key] == want[key], (tick, key)
        assert row["map_points"] == len(merged)
        mirror = sampler.merged  # rows in arrival order; by key, the edge's map
        np.testing.assert_array_equal(mirror.cloud.points_world[mirror.rows],
                                      merged.points_world)
        assert mirror.cloud.voxel_keys.size == 0 and len(mirror.keys) == len(merged)
    assert 0 < sampler.rows[-1]["bounding_volume_pct"] < 100
    deltas = [r for r in edge.replies if r.delta]
    assert len(deltas) > 30 and len(edge.replies) - len(deltas) > 6  # rebuilds: whole again
    assert sum(len(r.points_world) for r in deltas) < 0.5 * sum(
        len(merged.robot_cloud(r.robot_id)[0]) if r.robot_id >= 0 else len(merged)
        for r in deltas)


def test_an_edge_without_keys_is_sampled_whole() -> None:
    """An older edge ignores since_version: whole maps, scored by coordinates."""
    rng = np.random.default_rng(5)
    pr, store, merged = probe(), SubmapStore(V), MergedMap(V)
    edge = MapEdge(merged)

    def keyless(key: str, request: m.CloudRequest, model: type, timeout: float) -> m.Cloud:
        old = m.CloudRequest(robot_id=request.robot_id)
        return MapEdge.query(edge, key, old, model, timeout)

    edge.query = keyless  # type: ignore[method-assign]
    monitor = Monitor(edge, 1)
    sampler = CoverageSampler(monitor, pr, 5.0, 0.1)  # type: ignore[arg-type]
    for tick in (1, 2, 3):
        store.apply(make_submap(0, 0, tick, tick, np.eye(4), floor_points(rng, 50)))
        merged.update(store)
        edge.tick = monitor.recent_grids[tick] = tick
        sampler.sample()
        want = map_quality(pr, merged.points_world.astype(np.float64),
                           [merged.robot_cloud(0)[0]])
        assert sampler.rows[-1]["coverage_3d_pct"] == want["coverage_3d_pct"]
    assert not sampler.versions and not any(r.delta for r in edge.replies)
