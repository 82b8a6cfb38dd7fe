"""The recorders without a mission: synthetic bus messages into mission.mcap / mission.rrd,
read back with the reference decoders (the whole-mission checks are in
test_mission_multiprocess.py, on its run folder)."""

from __future__ import annotations

import io
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from rich.console import Console

from schemas import messages as m
from services.evaluator.plots import plot_label, world_label
from services.launcher import ros2_defs
from services.launcher.config import RecordConfig, parse_view
from services.launcher.monitor import RobotTrack
from services.launcher.panel import current_goal, mission_panel
from services.launcher.recorders import MCAP_NAME, RRD_NAME, Recorders, Throttle, open_recorders
from tests.recording_checks import (
    cloud_points,
    grid_cells,
    mcap_messages,
    pose_xyyaw,
    rrd_blueprint_views,
    rrd_entities,
)

TICK_S = 0.1
RNG = np.random.default_rng(7)


def _grid(tick: int) -> m.OccupancyGrid:
    cells = RNG.choice(np.array([-1, 0, 100], dtype=np.int8), size=(12, 17))
    return m.OccupancyGrid(tick=tick, resolution_m=0.05, origin_x=-1.25, origin_y=2.5,
                           cells=cells)


def _cloud(tick: int, n: int = 500, robot_id: int = -1) -> m.Cloud:
    return m.Cloud(tick=tick, robot_id=robot_id,
                   points_world=RNG.uniform(-5, 5, (n, 3)).astype(np.float32),
                   colors=RNG.integers(0, 256, (n, 3), dtype=np.uint8),
                   robot_ids=RNG.integers(0, 2, n, dtype=np.uint8))


def _frontiers(tick: int) -> m.Frontiers:
    fr = [m.Frontier(frontier_id=i, frontier_class="unexplored" if i % 2 else "weak",
                     centroid=(float(i), 1.0, 0.5), goal_xy=(float(i), 0.5), size=3 + i,
                     gain=1.0, importance=0.5) for i in range(4)]
    return m.Frontiers(tick=tick, frontiers=fr, complete=False, assigned={0: 1, 1: 2})


def _mission(recorders: Recorders, tracks: dict[int, RobotTrack], ticks: int = 40) -> dict:
    """Feed `ticks` ticks of two robots' poses, truths, grids, frontiers, goals and samples
    the way the monitor and the sampler do; return what was fed."""
    fed: dict[str, Any] = {"poses": {0: [], 1: []}, "grids": []}
    for tick in range(ticks):
        stamp = tick * 100_000_000
        for robot in (0, 1):
            pose = m.Pose2D(x=0.1 * tick + robot, y=-0.05 * tick, yaw=0.2 * tick - 3.0)
            truth = m.Pose2D(x=pose.x + 0.01, y=pose.y, yaw=pose.yaw)
            tracks[robot].est_stamps_ns.append(stamp)
            tracks[robot].est_xyyaw.append((pose.x, pose.y, pose.yaw))
            tracks[robot].gt_xyyaw.append((truth.x, truth.y, truth.yaw))
            recorders.on_message(m.GtPose(robot_id=robot, tick=tick, stamp_ns=stamp,
                                          pose_world=truth))
            recorders.on_message(m.RobotPose(robot_id=robot, tick=tick, stamp_ns=stamp,
                                             pose_world=pose, state="goal"))
            fed["poses"][robot].append((stamp, pose.x, pose.y, pose.yaw))
        if tick % 10 == 0:
            grid = _grid(tick)
            fed["grids"].append(grid)
            recorders.on_message(grid)
            recorders.on_message(_frontiers(tick))
            recorders.on_message(m.Goal(robot_id=0, tick=tick, goal_id=tick, x=1.0, y=2.0,
                                        frontier_class="weak", revenue=1.0))
            recorders.on_sample({"coverage_3d_pct": tick / 4, "bounding_volume_pct": 0.0},
                                _cloud(tick))
    final, robot_maps = _cloud(ticks - 1), [_cloud(ticks - 1, 50).points_world, np.zeros((0, 3))]
    recorders.finish(final, robot_maps, fed["grids"][-1], tracks)
    recorders.close()
    fed.update(final=final, robot_maps=robot_maps)
    return fed


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("rec")
    tracks = {0: RobotTrack(), 1: RobotTrack()}
    cfg = RecordConfig(cloud_every_s=1.0, grid_every_s=0.0)
    return out, _mission(open_recorders(out, 2, cfg, TICK_S, tracks), tracks)


def test_mcap_decodes_with_the_ros2_decoder_into_what_was_recorded(recorded) -> None:
    out, fed = recorded
    topics = mcap_messages(out / MCAP_NAME)
    assert {t: s for t, [(s, _), *_] in topics.items()} == {
        "/map_cloud": "sensor_msgs/msg/PointCloud2",
        "/robot_0/map_cloud": "sensor_msgs/msg/PointCloud2",
        "/robot_1/map_cloud": "sensor_msgs/msg/PointCloud2",
        "/map": "nav_msgs/msg/OccupancyGrid",
        "/robot_0/odom": "nav_msgs/msg/Odometry", "/robot_1/odom": "nav_msgs/msg/Odometry",
        "/robot_0/ground_truth": "nav_msgs/msg/Odometry",
        "/robot_1/ground_truth": "nav_msgs/msg/Odometry",
        "/tf": "tf2_msgs/msg/TFMessage", "/frontiers": "visualization_msgs/msg/MarkerArray"}
    # clouds: every sample 1 s apart (ticks 0..30) and the final one; exact float32 points
    clouds = [msg for _, msg in topics["/map_cloud"]]
    assert len(clouds) == 5
    np.testing.assert_array_equal(cloud_points(clouds[-1]), fed["final"].points_world)
    rgb = np.frombuffer(bytes(clouds[-1].data), np.uint8).reshape(-1, 16)[:, 12:15][:, ::-1]
    np.testing.assert_array_equal(rgb, fed["final"].colors)  # 0x00RRGGBB little endian
    np.testing.assert_array_equal(cloud_points(topics["/robot_0/map_cloud"][0][1]),
                                  fed["robot_maps"][0])
    assert topics["/robot_1/map_cloud"][0][1].width == 0
    # grids: each one fed (grid_every_s = 0) and the final again, cells and geometry exact
    grids = [msg for _, msg in topics["/map"]]
    assert len(grids) == len(fed["grids"]) + 1
    for msg, grid in zip(grids, [*fed["grids"], fed["grids"][-1]], strict=True):
        np.testing.assert_array_equal(grid_cells(msg), grid.cells)
        assert math.isclose(msg.info.resolution, grid.resolution_m, rel_tol=1e-6)
        assert (msg.info.origin.position.x, msg.info.origin.position.y) == (grid.origin_x,
                                                                            grid.origin_y)
    for robot in (0, 1):
        got = np.array([pose_xyyaw(msg) for _, msg in topics[f"/robot_{robot}/odom"]])
        want = np.array(fed["poses"][robot])
        np.testing.assert_array_equal(got[:, 0], want[:, 0])
        np.testing.assert_allclose(got[:, 1:3], want[:, 1:3], atol=1e-12)
        dyaw = np.angle(np.exp(1j * (got[:, 3] - want[:, 3])))
        assert np.abs(dyaw).max() < 1e-9
    tf = topics["/tf"][-1][1].transforms[0]
    assert tf.header.frame_id == "map" and tf.child_frame_id == "robot_1/base_link"
    markers = {mk.ns: mk for mk in topics["/frontiers"][0][1].markers}
    assert markers[""].action == 3  # DELETEALL first
    fed_fr = _frontiers(0).frontiers
    for cls in ("unexplored", "weak"):
        got = [(p.x, p.y, p.z) for p in markers[f"frontiers/{cls}"].points]
        assert got == [f.centroid for f in fed_fr if f.frontier_class == cls]
    assert [(p.x, p.y) for p in markers["goals"].points] == [f.goal_xy for f in fed_fr]
    # robot 0 → f1, robot 1 → f2, from each robot's last pose (tick 0 here)
    line = [(p.x, p.y) for p in markers["assignments"].points]
    assert line == [(0.0, 0.0), fed_fr[1].goal_xy, (1.0, 0.0), fed_fr[2].goal_xy]


def test_schema_text_names_every_dependency_once() -> None:
    text = ros2_defs.schema_text("visualization_msgs/Marker")
    deps = [line[5:] for line in text.splitlines() if line.startswith("MSG: ")]
    assert len(deps) == len(set(deps))
    assert {"std_msgs/Header", "geometry_msgs/Pose", "geometry_msgs/Point",
            "sensor_msgs/CompressedImage", "visualization_msgs/UVCoordinate",
            "visualization_msgs/MeshFile", "builtin_interfaces/Duration"} <= set(deps)


def test_rrd_loads_back_with_the_expected_entities_and_time_range(recorded) -> None:
    out, _ = recorded
    rows, span = rrd_entities(out / RRD_NAME)
    for entity in ("/world/map/cloud", "/world/robots/0", "/world/robots/1",
                   "/world/robots/0/body", "/world/trajectories/1/estimate",
                   "/world/trajectories/1/ground_truth", "/world/frontiers/unexplored",
                   "/world/frontiers/weak", "/world/goals", "/grid/image", "/grid/frontiers",
                   "/plots/coverage_3d_pct", "/events"):
        assert rows.get(entity, 0) > 0, entity
    assert rows["/world/robots/0"] == 40  # every pose, sent in column batches
    assert span is not None and span[0] == 0.0 and math.isclose(span[1], 3.9)


def test_rrd_holds_the_default_blueprint(recorded) -> None:
    """`rerun mission.rrd` opens on spacemap's layout: the blueprint travels in the file."""
    out, _ = recorded
    found = rrd_blueprint_views(out / RRD_NAME)
    assert found is not None
    app_id, views = found
    assert app_id == "spacemap"
    assert {("3D", "map (3D)", "world"), ("2D", "grid (2D)", "grid"),
            ("TimeSeries", "coverage (%)", "plots"), ("TextLog", "goal events", "events"),
            ("2D", "camera 0", "cameras/0"), ("2D", "camera 1", "cameras/1")} <= views


def test_a_failing_recorder_is_dropped_and_counted_the_others_go_on() -> None:
    class Broken:
        def on_message(self, msg: m.Message) -> None:
            raise RuntimeError("disk full")

    class Counting:
        n = 0

        def on_message(self, msg: m.Message) -> None:
            self.n += 1

    ok = Counting()
    recs = Recorders([Broken(), ok])  # type: ignore[list-item]
    for tick in range(3):
        recs.on_message(m.EdgeAck(tick=tick))
    assert recs.failures == 1 and ok.n == 3 and len(recs.recorders) == 1


def test_throttle_lets_one_event_per_period_through() -> None:
    t = Throttle(1.0)
    assert [s for s in (0.0, 0.4, 1.0, 1.5, 2.1, 2.2) if t.due(s)] == [0.0, 1.0, 2.1]
    every = Throttle(0.0)
    assert all(every.due(s) for s in (0.0, 0.0, 0.1))


def test_a_world_path_is_shown_by_its_short_name() -> None:
    assert world_label("../shared/worlds/aws_small_house/small_house.xml") == "small_house"
    assert world_label("house") == "house"
    metrics = {"world": "/long/path/to/bookstore.xml", "robots": 3, "planner": "space",
               "drf": False}
    assert plot_label(metrics) == "bookstore, 3 robots, space, no DRF"


def test_the_panel_shows_each_robots_state_and_goal() -> None:
    track = RobotTrack(state="goal", goals_assigned=2, goals_reached=1)
    track.events += [{"kind": "goal", "goal_id": 7, "x": 1.0, "y": 2.0,
                      "frontier_class": "unexplored", "cancel": False}]
    idle = RobotTrack(state="idle")
    idle.events += [{"kind": "goal", "goal_id": 3, "x": 0.0, "y": 0.0,
                     "frontier_class": "weak", "cancel": False},
                    {"kind": "status", "goal_id": 3, "status": "reached"}]
    assert current_goal(track) == "#7 (1.0, 2.0) F_u"
    assert current_goal(idle) == "- (#3 reached)"
    monitor = SimpleNamespace(sim_time_s=42.0, frontiers=_frontiers(420), series=[],
                              grid=None, tracks={0: track, 1: idle}, robots=2,
                              complete_tick=None)
    console = Console(width=100, record=True, file=io.StringIO())
    console.print(mission_panel(monitor, "../worlds/bookstore.xml", 300.0, 21.0,  # type: ignore[arg-type]
                                {"coverage_3d_pct": 55.5, "bounding_volume_pct": 0.001}))
    text = console.export_text()
    for part in ("bookstore", "42.0", "2.00×", "55.5 %", "F_u 2", "F_w 2", "#7 (1.0, 2.0) F_u",
                 "idle"):
        assert part in text, part
    assert "worlds/" not in text


def test_a_live_view_target_is_checked_before_the_mission_starts() -> None:
    assert parse_view("spawn") == ("spawn", 9876)
    assert parse_view("serve:9000") == ("serve", 9000)
    assert parse_view("rerun+http://10.0.0.2:9876/proxy") == ("url",
                                                              "rerun+http://10.0.0.2:9876/proxy")
    for bad in ("serve:port", "serve:0", "http://host:9876", "show"):
        with pytest.raises(ValueError):
            parse_view(bad)
