"""One overlap definition (issue 12): the time series' last row, metrics.json and the run
folder's files give the same 3D overlap, from the robots' own maps, on synthetic clouds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from schemas import Keys, decode, encode
from schemas import messages as m
from services.common.grid import GridSpec
from services.evaluator import metrics as mx
from services.evaluator import run_files as rf
from services.evaluator.config import EvalConfig
from services.evaluator.free_space import FreeGrid
from services.evaluator.ground_truth import GroundTruth
from services.evaluator.scoring import Probe, score
from services.launcher.sampler import (
    OWN_MAPS,
    SPLIT_MAPS,
    CoverageSampler,
    robot_clouds,
    series_row,
)

VOXEL_M = 0.05


def plane_truth() -> np.ndarray:
    """A 2 m × 2 m floor sampled at 1000 points/m², all observable."""
    rng = np.random.default_rng(1)
    return np.c_[rng.uniform(0, 2, (4000, 2)), np.zeros(4000)]


def probe() -> Probe:
    spec = GridSpec(0.0, 0.0, VOXEL_M, 40, 40)
    ones = np.ones(spec.shape, bool)
    gt = plane_truth()
    seen = np.ones(len(gt), bool)
    return Probe(GroundTruth(FreeGrid(spec, ~ones, ones, ones), gt, seen, seen), EvalConfig())


def voxel_centres(x_lo: float, x_hi: float) -> np.ndarray:
    """The floor's 5 cm voxel centres with x in [x_lo, x_hi), as the edge's maps hold them."""
    c = (np.arange(40) + 0.5) * VOXEL_M
    xs, ys = np.meshgrid(c[(c >= x_lo) & (c < x_hi)], c)
    return np.c_[xs.ravel(), ys.ravel(), np.full(xs.size, VOXEL_M / 2)]


def own_maps() -> list[np.ndarray]:
    """Robot 0 maps x < 1.2 m, robot 1 x > 0.8 m: both cover x ≈ 0.73-1.27 m (27 %)."""
    return [voxel_centres(0.0, 1.2), voxel_centres(0.8, 2.0)]


def merged_cloud(maps: list[np.ndarray], tick: int = 50) -> m.Cloud:
    """P* as the edge serves it: each voxel once, tagged with its first observer (robot 0)."""
    pts = np.concatenate(maps)
    ids = np.concatenate([np.full(len(p), r, np.uint8) for r, p in enumerate(maps)])
    _, first = np.unique(pts.round(6), axis=0, return_index=True)
    return m.Cloud(tick=tick, points_world=pts[first].astype(np.float32),
                   colors=np.zeros((len(first), 3), np.uint8), robot_ids=ids[first])


def metrics_json(pr: Probe, cloud: m.Cloud, maps: list[np.ndarray],
                 series: list[dict]) -> dict:
    """metrics.json's content from the same maps (`score`, as `spacemap run` and eval do)."""
    identity = {"robots": len(maps), "world": "floor", "planner": "space", "drf": True,
                "seed": 0}
    return score(pr, cloud.points_world.astype(np.float64), maps, None, None, [], [], series,
                 {}, identity)


def test_overlap_pct_is_truth_covered_twice_of_truth_covered() -> None:
    a = np.array([1, 1, 0, 0], dtype=bool)
    b = np.array([0, 1, 1, 0], dtype=bool)
    assert mx.overlap_pct([a, b]) == pytest.approx(100.0 / 3)
    assert mx.overlap_pct([a, b, b]) == pytest.approx(200.0 / 3)  # 3 robots: ≥ 2 counts
    assert mx.overlap_pct([a]) == 0.0 and mx.overlap_pct([]) == 0.0


def test_time_series_row_and_metrics_json_agree(tmp_path: Path) -> None:
    pr, maps = probe(), own_maps()
    cloud = merged_cloud(maps)
    row = series_row(pr, cloud, None, None, 0.1, 0, maps)
    metrics = metrics_json(pr, cloud, maps, [row])
    truth = pr.gt.observable_points_world
    expected = mx.overlap_3d(maps, truth, pr.ev.coverage_radius_m)
    assert row["overlap_3d_pct"] == metrics["overlap_3d_pct"] == expected
    assert expected == pytest.approx(27.5, abs=2.0)
    assert row["coverage_3d_pct"] == metrics["coverage_3d_pct"]
    # the run folder: metrics.json scores robot_N_map.ply, timeseries.csv keeps 4 decimals
    for robot, points in enumerate(maps):
        rf.write_ply(rf.robot_map_path(tmp_path, robot), points)
    back = [rf.read_ply(rf.robot_map_path(tmp_path, r)) for r in range(len(maps))]
    assert metrics_json(pr, cloud, back, [row])["overlap_3d_pct"] == expected
    rf.write_csv(tmp_path / rf.TIMESERIES, [row], list(row))
    last = rf.read_csv(tmp_path / rf.TIMESERIES)[-1]
    assert last["overlap_3d_pct"] == pytest.approx(expected, abs=1e-4)


def test_merged_cloud_split_by_first_observer_undercounts() -> None:
    """The old time series: a voxel both robots mapped counted for robot 0 only."""
    pr, maps = probe(), own_maps()
    cloud = merged_cloud(maps)
    pts = cloud.points_world.astype(np.float64)
    split = [pts[cloud.robot_ids == r] for r in range(len(maps))]
    truth = pr.gt.observable_points_world
    assert mx.overlap_3d(split, truth) < mx.overlap_3d(maps, truth) - 15.0


class FakeEdge:
    """Answers `map/cloud` like the edge (through the codec); `own_maps=False`: like an
    older edge that ignores CloudRequest.robot_id."""

    def __init__(self, maps: list[np.ndarray], own_maps: bool = True) -> None:
        self.keys, self.maps, self.own_maps = Keys(), maps, own_maps
        self.cloud = merged_cloud(maps)

    def query(self, key: str, request: m.CloudRequest, model: type, timeout: float) -> m.Cloud:
        assert key == self.keys.map_cloud() and model is m.Cloud
        reply = self.cloud
        if request.robot_id >= 0 and self.own_maps:
            pts = self.maps[request.robot_id]
            reply = m.Cloud(tick=self.cloud.tick, robot_id=request.robot_id,
                            points_world=pts.astype(np.float32),
                            colors=np.zeros((len(pts), 3), np.uint8),
                            robot_ids=np.full(len(pts), request.robot_id, np.uint8))
        return decode(encode(reply), m.Cloud)


class FakeMonitor:
    def __init__(self, bus: FakeEdge, robots: int) -> None:
        self.bus, self.robots = bus, robots
        self.recent_grids = {bus.cloud.tick: None}

    def at_tick(self, tick: int) -> tuple[None, int]:
        return None, 0


@pytest.mark.parametrize("own", [True, False])
def test_sampler_row_uses_the_robot_maps_metrics_json_scores(own: bool) -> None:
    """A live sample queries each robot's map; where the edge only has the merged map, the
    sample and the run folder fall back alike (`robot_clouds`)."""
    pr, maps, edge = probe(), own_maps(), FakeEdge(own_maps(), own_maps=own)
    sampler = CoverageSampler(FakeMonitor(edge, len(maps)), pr, 5.0, 0.1)  # type: ignore[arg-type]
    sampler.sample()
    final_maps, source = robot_clouds(edge, edge.cloud, len(maps))  # type: ignore[arg-type]
    assert source == (OWN_MAPS if own else SPLIT_MAPS)
    row = sampler.rows[-1]
    assert row["sim_time_s"] == pytest.approx(5.0)
    metrics = metrics_json(pr, edge.cloud, final_maps, sampler.rows)
    assert row["overlap_3d_pct"] == metrics["overlap_3d_pct"]
    if own:
        assert row["overlap_3d_pct"] == mx.overlap_3d(maps, pr.gt.observable_points_world)


def test_last_row_equals_metrics_json_after_incremental_samples() -> None:
    """The sampler scores each sample incrementally; after maps that grew, lost voxels (a
    pose correction) and grew again, its last row is still metrics.json's."""
    pr = probe()
    stages = [[voxel_centres(0.0, 0.6), voxel_centres(1.5, 2.0)],
              [voxel_centres(0.0, 1.2), voxel_centres(0.8, 2.0)],
              [voxel_centres(0.2, 1.0), voxel_centres(0.9, 2.0)],  # voxels removed
              [voxel_centres(0.1, 1.4), voxel_centres(0.5, 2.0)]]
    edge = FakeEdge(stages[0])
    monitor = FakeMonitor(edge, 2)
    sampler = CoverageSampler(monitor, pr, 5.0, 0.1)  # type: ignore[arg-type]
    for tick, maps in enumerate(stages[:-1], start=1):
        edge.maps, edge.cloud = maps, merged_cloud(maps, tick * 50)
        monitor.recent_grids[tick * 50] = None
        sampler.sample()
    final = stages[-1]
    cloud = merged_cloud(final, 200)
    sampler.add(cloud, final)
    assert len(sampler.rows) == len(stages)
    metrics = metrics_json(pr, cloud, final, sampler.rows)
    for key in ("coverage_3d_pct", "overlap_3d_pct", "bounding_volume_pct"):
        assert sampler.rows[-1][key] == metrics[key], key
    assert sampler.rows[1]["overlap_3d_pct"] > sampler.rows[2]["overlap_3d_pct"]
