"""Ghost sources found in missions (docs/agent.md "Ghost-free map"); each fails without its fix."""

from __future__ import annotations

import math

import numpy as np

from schemas.messages import Pose2D, RobotPose
from services.robot_agent.agent import AgentCore
from services.robot_agent.config import AgentConfig
from services.robot_agent.drf import DrfParams, filter_mask
from services.robot_agent.synthetic import T_world_cam_of, render
from services.robot_agent.teammates import predict_xy, teammates_in_view
from tests.test_agent_core import _frame, _odom
from tests.test_agent_drf import ROOM, T_BASE_CAM, K, _robot_box
from tests.test_agent_yield import yield_command


def _pose(rid: int, k: int, x: float, y: float) -> RobotPose:
    return RobotPose(robot_id=rid, tick=k, stamp_ns=k, pose_world=Pose2D(x=x, y=y, yaw=0.0),
                     state="idle")


def _mapped_voxels(core: AgentCore) -> int:
    return sum(n for _, n in core.mapper.published()) + (
        len(core.mapper.current) if core.mapper.current is not None else 0)


def test_no_mapping_before_every_teammate_pose_is_known() -> None:
    core = AgentCore(AgentConfig(), 0, 0.1, team_size=2)
    core.on_rgbd(_frame(0, (0.0, 0.0, 0.0)))
    core.on_odometry(_odom(0, (0.0, 0.0, 0.0)))
    assert core.frames_skipped == 1 and _mapped_voxels(core) == 0
    core.on_pose(_pose(1, 0, 9.0, 9.0))
    core.on_pose(_pose(2, 0, 9.0, -9.0))
    core.on_rgbd(_frame(2, (0.0, 0.0, 0.0)))
    core.on_odometry(_odom(2, (0.0, 0.0, 0.0)))
    assert core.frames_skipped == 1 and _mapped_voxels(core) > 0


def test_a_silent_teammate_blocks_mapping_only_for_the_bounded_wait() -> None:
    cfg = AgentConfig(map_wait_ticks=6)
    core = AgentCore(cfg, 0, 0.1, team_size=2)
    core.on_pose(_pose(1, 0, 9.0, 9.0))  # teammate 2 never comes up
    for k in range(0, 10, 2):
        core.on_rgbd(_frame(k, (0.0, 0.0, 0.0)))
        core.on_odometry(_odom(k, (0.0, 0.0, 0.0)))
    assert core.frames_skipped == 3 and _mapped_voxels(core) > 0


def test_teammate_predicted_forward_by_its_last_motion() -> None:
    prev, last = _pose(1, 4, 1.0, 2.0), _pose(1, 5, 1.05, 2.0)
    assert np.allclose(predict_xy(last, prev, 6, 3), [1.10, 2.0])
    assert np.allclose(predict_xy(last, prev, 20, 3), [1.20, 2.0])  # capped
    assert np.allclose(predict_xy(last, None, 6, 3), [1.05, 2.0])
    core = AgentCore(AgentConfig(), 0, 0.1, team_size=1)
    core.on_pose(prev)
    core.on_pose(last)
    seen = teammates_in_view(core.teammates, core.teammates_prev, (0.0, 2.0, 0.0),
                             _frame(6, (0.0, 2.0, 0.0)), 6, core.config)
    assert np.allclose(seen, [[1.10, 2.0]])


def test_teammate_touching_a_wall_is_removed() -> None:
    """One DBSCAN cluster of robot + wall fails the size test; the footprint still goes."""
    obs, mate = (0.0, 0.0, 0.8), (2.5, 2.83)  # robot's side 0.02 m from the wall at y = 3
    T_wc = T_world_cam_of(*obs, T_BASE_CAM)
    world = ROOM.with_box(_robot_box(*mate))
    depth, _ = render(world, K, (120, 160), T_wc, 5.0)
    empty, _ = render(ROOM, K, (120, 160), T_wc, 5.0)
    teammate = (depth > 0) & (np.abs(depth - empty) > 1e-4)
    assert teammate.sum() > 20
    est = np.array([[mate[0] + 0.06, mate[1] - 0.05]])  # a few cm of relative pose error
    without = filter_mask(depth, K, T_BASE_CAM, obs, est, DrfParams(margin_m=0.0,
                                                                     footprint_m=0.0))
    mask = filter_mask(depth, K, T_BASE_CAM, obs, est, DrfParams())
    assert (without & teammate).sum() < 0.9 * teammate.sum()  # the leak the footprint closes
    assert (mask & teammate).sum() == teammate.sum()
    assert (mask & ~teammate).sum() <= 0.02 * (~teammate & (depth > 0)).sum()


def test_footprint_never_reaches_beyond_the_grown_circle() -> None:
    obs = (0.0, 0.0, math.radians(30))
    depth, _ = render(ROOM, K, (120, 160), T_world_cam_of(*obs, T_BASE_CAM), 5.0)
    mask = filter_mask(depth, K, T_BASE_CAM, obs, np.array([[2.0, 0.5]]), DrfParams())
    assert not mask.any()  # only floor in the footprint: nothing above the floor removed


def _points_base(pose: tuple[float, float, float]) -> np.ndarray:
    from services.robot_agent.projection import cam_to_base, depth_to_points

    frame = _frame(0, pose)
    cam = depth_to_points(frame.depth_m, frame.K, 1, frame.range_max_m)
    return cam_to_base(cam.points_cam, frame.T_base_cam)


def test_registration_gate_follows_the_odometry_error_model() -> None:
    """A 4 cm correction right after an accepted one is a GICP slide, not drift: rejected;
    after 0.5 m of odometry since the last acceptance, drift can explain it: accepted."""
    from services.common.geometry import T_from_xyyaw
    from services.robot_agent.registrar import FrameRegistrar, RegistrationParams

    pose = (0.5, 0.3, 0.4)
    pts = _points_base(pose)
    T_true, T_off = T_from_xyyaw(*pose), T_from_xyyaw(pose[0] + 0.04, pose[1], pose[2])
    for moved_m, accepted in ((0.0, False), (0.5, True)):
        reg = FrameRegistrar(RegistrationParams())
        assert reg.register(pts, T_true, T_true).reason == "empty map"
        T_odom = T_from_xyyaw(pose[0] + moved_m, pose[1], pose[2])  # odometry moved on
        out = reg.register(pts, T_off, T_odom)
        assert out.accepted is accepted, out.reason
        if accepted:
            assert np.allclose(out.T_loc_base[:2, 3], T_true[:2, 3], atol=0.01)
    reg.T_odom_accepted = T_from_xyyaw(-50.0, 0.0, 0.0)  # long run of rejections: capped
    assert reg.gate(T_from_xyyaw(*pose)) == (reg.params.cap_m, reg.params.cap_rad)


def test_robot_does_not_drive_into_a_teammate_the_drf_hides() -> None:
    from services.robot_agent.navigation import Command

    core = AgentCore(AgentConfig(), 0, 0.1, team_size=1)
    core.on_pose(_pose(1, 10, 0.5, 0.1))
    ahead = yield_command(core, (0.0, 0.0, 0.0), Command(0.3, 0.2), 11)
    assert ahead == Command(0.0, 0.2)
    behind = yield_command(core, (0.0, 0.0, math.pi), Command(0.3, 0.2), 11)
    assert behind == Command(0.3, 0.2)
    stale = yield_command(core, (0.0, 0.0, 0.0), Command(0.3, 0.2), 100)
    assert stale == Command(0.3, 0.2)


def test_frame_mostly_hidden_by_a_teammate_keeps_the_odometry_guess() -> None:
    from services.common.geometry import T_from_xyyaw

    core = AgentCore(AgentConfig(), 0, 0.1)
    pts, T = _points_base((0.5, 0.3, 0.4)), T_from_xyyaw(0.5, 0.3, 0.4)
    core._register(pts, T, removed_frac=0.5)
    registrar = core.localizer.registrar
    assert registrar.n_inserted == 1  # the first frame anchors the map whatever it shows
    core._register(pts, T, removed_frac=0.5)
    assert registrar.n_inserted == 1  # not registered, not inserted in the local map
    assert core.localizer.outcomes["hidden by teammates"] == 1
    core._register(pts, T, removed_frac=0.1)
    assert registrar.n_inserted == 2
