"""AgentCore on synthetic frames: tick handshake order, submap seq, corrections, a goal run."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from schemas import decode, encode
from schemas.messages import CmdVel, Correction, Goal, Odometry, Pose2D, RgbdFrame, Submap
from services.common.geometry import T_from_xyyaw
from services.robot_agent.agent import AgentCore
from services.robot_agent.config import AgentConfig
from services.robot_agent.projection import T_base_cam_forward, intrinsics
from services.robot_agent.synthetic import BoxWorld, T_world_cam_of, render

K = intrinsics(160, 120, math.radians(84.1))
T_BASE_CAM = T_base_cam_forward(0.35)
WORLD = BoxWorld.room(-3.0, 5.0, -3.0, 3.0).with_box((1.5, 1.8, -3.0, 1.0, 0.0, 1.0))


def _frame(k: int, pose: tuple[float, float, float]) -> RgbdFrame:
    depth, rgb = render(WORLD, K, (120, 160), T_world_cam_of(*pose, T_BASE_CAM), 5.0)
    return RgbdFrame(robot_id=0, tick=k, stamp_ns=k * 10**8, depth_m=depth, rgb=rgb, K=K,
                     T_base_cam=T_BASE_CAM, range_max_m=5.0)


def _odom(k: int, pose: tuple[float, float, float]) -> Odometry:
    return Odometry(robot_id=0, tick=k, stamp_ns=k * 10**8,
                    pose_odom=Pose2D(x=pose[0], y=pose[1], yaw=pose[2]), v_mps=0.0, omega_radps=0.0)


def _run(core: AgentCore, ticks: int, goal_at: int | None = None):
    pose = (0.0, 0.0, 0.0)
    outs_per_tick = []
    for k in range(ticks):
        if goal_at is not None and k == goal_at:
            core.on_goal(Goal(robot_id=0, tick=k, goal_id=7, x=3.5, y=-1.5,
                              frontier_class="unexplored", revenue=1.0))
        if k % 2 == 0:
            core.on_rgbd(_frame(k, pose))
        outs = core.on_odometry(_odom(k, pose))
        outs_per_tick.append(outs)
        cmd = outs[-1].message
        assert isinstance(cmd, CmdVel)
        x, y, yaw = pose
        pose = (x + cmd.v_mps * math.cos(yaw) * 0.1, y + cmd.v_mps * math.sin(yaw) * 0.1,
                yaw + cmd.omega_radps * 0.1)
    return pose, outs_per_tick


def test_tick_outputs_in_handshake_order_and_submap_seq_without_gaps() -> None:
    core = AgentCore(AgentConfig(), 0, 0.1)
    _, ticks = _run(core, 40)
    seqs = []
    for k, outs in enumerate(ticks):
        topics = [o.topic for o in outs]
        assert topics[0] == "pose" and topics[-1] == "cmd_vel" and topics.count("cmd_vel") == 1
        assert outs[-1].message.tick == k
        for o in outs:
            if o.topic == "submap":
                msg = decode(encode(o.message), Submap)  # valid on the wire
                seqs.append(msg.seq)
                assert msg.points_mm.shape[0] == 3 and msg.free_cells.shape[0] == 2
    assert seqs == list(range(len(seqs))) and len(seqs) >= 4
    assert core.mapper.next_id >= 2  # spinning 40 ticks at 0.4 rad/s crosses 45°


def test_correction_moves_the_pose_estimate() -> None:
    core = AgentCore(AgentConfig(), 0, 0.1)
    core.on_rgbd(_frame(0, (0.0, 0.0, 0.0)))
    core.on_odometry(_odom(0, (0.0, 0.0, 0.0)))
    core.on_correction(Correction(robot_id=0, tick=1, submap_ids=np.array([0], np.int32),
                                  T_world_submap=T_from_xyyaw(0.5, 0.0, 0.0)[None]))
    pose = core.on_odometry(_odom(1, (1.0, 0.0, 0.0)))[0].message.pose_world
    assert math.isclose(pose.x, 1.5) and math.isclose(pose.y, 0.0, abs_tol=1e-12)


def test_submaps_carry_the_agents_own_frame_which_a_correction_does_not_move() -> None:
    core = AgentCore(AgentConfig(), 0, 0.1)
    pose = (0.0, 0.0, 0.0)
    sent = []
    for k in range(21):
        if k == 1:
            core.on_correction(Correction(robot_id=0, tick=1, submap_ids=np.array([0], np.int32),
                                          T_world_submap=T_from_xyyaw(0.5, 0.2, 0.1)[None]))
        if k % 2 == 0:
            core.on_rgbd(_frame(k, pose))
        sent += [o.message for o in core.on_odometry(_odom(k, pose)) if o.topic == "submap"]
    first, later = sent[0], sent[-1]
    assert first.tick == 0 and later.tick >= 10 and later.submap_id == first.submap_id
    assert np.array_equal(first.T_odom_submap, later.T_odom_submap)  # the agent's frame
    assert np.allclose(first.T_world_submap, first.T_odom_submap)  # before the correction
    assert np.allclose(later.T_world_submap, T_from_xyyaw(0.5, 0.2, 0.1) @ later.T_odom_submap)


def test_reaches_a_goal_behind_a_wall_from_its_own_depth_frames() -> None:
    core = AgentCore(AgentConfig(), 0, 0.1)
    pose, ticks = _run(core, 400, goal_at=20)
    statuses = [o.message.status for outs in ticks for o in outs if o.topic == "goal_status"]
    assert statuses == ["active", "reached"], statuses
    assert math.hypot(pose[0] - 3.5, pose[1] + 1.5) <= 0.4


def test_submap_epoch_and_ids_unique_across_restarts() -> None:
    first = AgentCore(AgentConfig(), 0, 0.1)
    restarted = AgentCore(AgentConfig(), 0, 0.1)
    pose = (0.0, 0.0, 0.0)
    first.on_rgbd(_frame(0, pose))
    a = [o.message for o in first.on_odometry(_odom(0, pose)) if o.topic == "submap"]
    restarted.on_rgbd(_frame(250, pose))
    b = [o.message for o in restarted.on_odometry(_odom(250, pose)) if o.topic == "submap"]
    assert a and b and a[0].epoch == 0 and b[0].epoch == 250
    assert {m.submap_id for m in a}.isdisjoint({m.submap_id for m in b})


def test_edge_away_explores_own_frontiers_and_resends_on_return() -> None:
    core = AgentCore(AgentConfig(), 0, 0.1)
    _run(core, 6)  # some map first, edge present: idle spin, no goal
    assert core.nav.goal is None
    core.on_edge_presence(False)
    _, ticks = _run(core, 4)
    assert core.nav.goal is not None and core.nav.goal.goal_id >= (1 << 30)
    assert not any(o.topic == "goal_status" for outs in ticks for o in outs)  # own goals only
    sent_before = core.outbox.seq
    core.on_edge_presence(True)
    outs = core.on_odometry(_odom(100, (0.0, 0.0, 0.0)))
    full = [o.message for o in outs if o.topic == "submap"]
    assert full and core.outbox.seq > sent_before
    n_voxels = sum(len(s) for s in [*core.mapper.done, core.mapper.current])
    assert sum(m.points_mm.shape[1] for m in full) >= n_voxels  # every voxel again
    assert outs[-1].topic == "cmd_vel"


def test_cancel_drops_the_goal() -> None:
    core = AgentCore(AgentConfig(), 0, 0.1)
    _run(core, 22, goal_at=20)
    assert core.nav.goal is not None
    core.on_goal(Goal(robot_id=0, tick=22, goal_id=7, x=3.5, y=-1.5, frontier_class="unexplored",
                      revenue=1.0, cancel=True))
    core.on_odometry(_odom(23, (0.0, 0.0, 0.0)))
    assert core.nav.goal is None


def test_stays_still_until_the_first_frame_anchors_the_map() -> None:
    """Odometry drifts only with motion: a spin before the first frame would rotate the map."""
    core = AgentCore(AgentConfig(), 0, 0.1)
    for k in range(3):  # idle spins, but no frame yet
        cmd = core.on_odometry(_odom(k, (0.0, 0.0, 0.0)))[-1].message
        assert isinstance(cmd, CmdVel) and (cmd.v_mps, cmd.omega_radps) == (0.0, 0.0)
    core.on_rgbd(_frame(4, (0.0, 0.0, 0.0)))
    cmd = core.on_odometry(_odom(4, (0.0, 0.0, 0.0)))[-1].message
    assert cmd.omega_radps != 0.0  # the idle spin once the map is anchored


def test_an_idle_robot_holds_still_while_teammates_hide_its_view() -> None:
    """A turn no frame can register keeps odometry's turn error in the map (warehouse, 24
    robots: BV 43.3 → 29.1 %, docs/agent.md); once the view clears, the idle spin resumes."""
    for spin_when_hidden in (False, True):
        core = AgentCore(AgentConfig(idle_spin_when_hidden=spin_when_hidden), 0, 0.1)
        core.on_rgbd(_frame(0, (0.0, 0.0, 0.0)))
        core.on_odometry(_odom(0, (0.0, 0.0, 0.0)))  # the first frame anchors the map
        core._drf_removed_frac = lambda frame: 0.9  # a teammate in front of the lens
        core.on_rgbd(_frame(2, (0.0, 0.0, 0.0)))
        cmd = core.on_odometry(_odom(2, (0.0, 0.0, 0.0)))[-1].message
        assert core.view_hidden and core.nav.state == "idle"
        assert (cmd.omega_radps != 0.0) == spin_when_hidden
        core._drf_removed_frac = lambda frame: 0.0
        core.on_rgbd(_frame(4, (0.0, 0.0, 0.0)))
        cmd = core.on_odometry(_odom(4, (0.0, 0.0, 0.0)))[-1].message
        assert not core.view_hidden and cmd.omega_radps != 0.0


def test_the_fleet_pools_odometry_calibration_through_pose_messages() -> None:
    """With the fleet's prior (the default) or fleet_weight > 0 an agent's poses carry its
    calibration sums and a teammate's sums move its estimate; with both off neither happens
    (the messages are as they were before the fleet pooled)."""
    from schemas.messages import RobotPose

    sums = [1.0e6 * 0.02, 1.0e6, 100.0, 0.0, 100.0, 1.0, 0.5]  # 2 % scale, well measured
    teammate = RobotPose(robot_id=1, tick=1, stamp_ns=10**8, pose_world=Pose2D(x=1, y=0, yaw=0),
                         odometry_stats=sums)
    assert AgentConfig().odom_calibration_fleet_prior_segments > 0
    for weight, prior in ((0.0, 0.0), (1.0, 0.0), (0.0, 8.0)):
        core = AgentCore(AgentConfig(odom_calibration_fleet_weight=weight,
                                     odom_calibration_fleet_prior_segments=prior), 0, 0.1)
        _, outs = _run(core, 3)
        pose = next(o.message for o in outs[0] if o.topic == "pose")
        pooled = weight > 0 or prior > 0
        assert (pose.odometry_stats is None) == (not pooled)
        core.on_pose(decode(encode(teammate), RobotPose))
        scale = core.localizer.odometry.calibration.errors.scale
        assert scale == (pytest.approx(0.02, abs=0.002) if pooled else 0.0)


def test_poses_carry_the_odometry_statistics_when_they_change_and_every_refresh() -> None:
    """Teammates keep the last statistics they got, so a pose carries them on the first tick,
    when they changed, and every STATS_REFRESH_TICKS (a teammate that starts late), and
    otherwise none: the same knowledge at every teammate for a tenth of the bytes."""
    from services.robot_agent.outbox import STATS_REFRESH_TICKS

    core = AgentCore(AgentConfig(), 0, 0.1)
    calibration = core.localizer.odometry.calibration
    own = [0.0] * 7
    calibration.shared = lambda: list(own)  # the statistics this robot would share now
    sent = []
    for tick in range(31 + 2 * STATS_REFRESH_TICKS):
        if tick == 30:
            own[0] = 0.5  # a calibration segment closed
        sent.append(core.outbox.stats_to_send(calibration.shared(), tick))
    ticks = [k for k, stats in enumerate(sent) if stats is not None]
    assert ticks == [0, 30, 30 + STATS_REFRESH_TICKS, 30 + 2 * STATS_REFRESH_TICKS]
    assert sent[30] == [0.5] + [0.0] * 6
    assert core.outbox.stats_to_send(None, 500) is None  # not pooled: never


def _turn_cmds(core: AgentCore, removed: float, ticks: int) -> list[CmdVel]:
    """Commands of `ticks` ticks from the start pose, a goal behind the robot, with the DRF
    taking `removed` of every frame after the first."""
    core.on_rgbd(_frame(0, (0.0, 0.0, 0.0)))
    core.on_odometry(_odom(0, (0.0, 0.0, 0.0)))  # the first frame anchors the map
    core._drf_removed_frac = lambda frame: removed
    core.on_goal(Goal(robot_id=0, tick=1, goal_id=3, x=-2.0, y=0.5,
                      frontier_class="unexplored", revenue=1.0))
    cmds = []
    for k in range(1, ticks + 1):
        if k % 2 == 0:
            core.on_rgbd(_frame(k, (0.0, 0.0, 0.0)))
        cmds.append(core.on_odometry(_odom(k, (0.0, 0.0, 0.0)))[-1].message)
    return cmds


def test_a_turn_in_place_waits_while_teammates_hide_the_view() -> None:
    """A turn on odometry alone ends 1-1.5° off (AWS house, 6 robots): it is held while the
    view is hidden, for at most `hidden_turn_hold_s`, and never when the view is clear."""
    held = _turn_cmds(AgentCore(AgentConfig(hidden_turn_hold_s=1.0), 0, 0.1), 0.9, 20)
    still = [i for i, c in enumerate(held) if (c.v_mps, c.omega_radps) == (0.0, 0.0)]
    assert still[:10] == list(range(1, 11))  # tick 1 plans; then 1 s held
    assert held[11].omega_radps != 0.0 and held[11].v_mps == 0.0  # then the turn goes on
    for config, removed in ((AgentConfig(hidden_turn_hold_s=1.0), 0.0),
                            (AgentConfig(), 0.9)):
        cmds = _turn_cmds(AgentCore(config, 0, 0.1), removed, 4)
        assert any(c.omega_radps != 0.0 for c in cmds[:3])


def test_driving_behind_teammates_is_held_only_where_asked() -> None:
    """`hidden_hold_driving` holds driving too while the view is hidden; without it only turns
    in place wait."""
    moved = {}
    for hold_driving in (False, True):
        core = AgentCore(AgentConfig(hidden_turn_hold_s=2.0, hidden_hold_driving=hold_driving),
                         0, 0.1)
        core.on_rgbd(_frame(0, (0.0, 0.0, 0.0)))
        core.on_odometry(_odom(0, (0.0, 0.0, 0.0)))
        core._drf_removed_frac = lambda frame: 0.9
        core.on_goal(Goal(robot_id=0, tick=1, goal_id=4, x=3.0, y=0.0,  # straight ahead
                          frontier_class="unexplored", revenue=1.0))
        cmds = []
        for k in range(1, 12):
            if k % 2 == 0:
                core.on_rgbd(_frame(k, (0.0, 0.0, 0.0)))
            cmds.append(core.on_odometry(_odom(k, (0.0, 0.0, 0.0)))[-1].message)
        moved[hold_driving] = [c.v_mps > 0.0 for c in cmds[2:]]
    assert all(moved[False]) and not any(moved[True])


def test_a_frame_whose_heading_is_unsure_maps_only_its_near_points() -> None:
    """`map_heading_tolerance_m`: at a heading σ of 2° a wall 5 m away could be 17 cm out (a
    ghost); the frame's points join the 3D map only within 0.03 m / σ (0.86 m here). The
    frame still registers and still clears the grid; a sure heading maps every point."""
    ranges = {}
    for sigma_deg in (0.0, 2.0):
        core = AgentCore(AgentConfig(), 0, 0.1)  # the default tolerance, 0.03 m
        core.localizer.P[2, 2] = math.radians(sigma_deg) ** 2
        core.on_rgbd(_frame(0, (0.0, 0.0, 0.0)))
        core.on_odometry(_odom(0, (0.0, 0.0, 0.0)))
        points = core.mapper.current.mean_points()
        ranges[sigma_deg] = np.hypot(points[:, 0], points[:, 1])
    assert ranges[0.0].max() > 4.5  # the far wall at x = 5 m
    assert len(ranges[2.0]) and ranges[2.0].max() < 0.03 / math.radians(2.0) + 0.1
    assert len(ranges[2.0]) < 0.5 * len(ranges[0.0])


def _drive(core: AgentCore, ticks: int, mode: str) -> list[list[tuple[str, bytes]]]:
    """(topic, encoded message) per tick of a run with a goal and a correction; `mode`:
    'inline', 'deferred' (on_odometry(defer=True), then finish_tick), 'ahead' (finish_tick
    stopped at random steps, as the node's is by its next input; a last entry holds what
    finishing after the last tick sends) or 'unfinished' (finish_tick never called)."""
    stop = random.Random(3)
    pose = (0.0, 0.0, 0.0)
    per_tick = []
    for k in range(ticks):
        if k == 4:
            core.on_goal(Goal(robot_id=0, tick=k, goal_id=7, x=3.5, y=-1.5,
                              frontier_class="unexplored", revenue=1.0))
        if k == 31:
            core.on_correction(Correction(robot_id=0, tick=k, submap_ids=np.array([0], np.int32),
                                          T_world_submap=T_from_xyyaw(0.3, -0.2, 0.05)[None]))
        if k % 2 == 0:
            core.on_rgbd(_frame(k, pose))
        outs = core.on_odometry(_odom(k, pose), defer=mode != "inline")
        cmd = outs[-1].message
        assert isinstance(cmd, CmdVel) and cmd.tick == k  # the command is out first
        if mode in ("deferred", "ahead"):
            late = core.finish_tick(until=(lambda: stop.random() < 0.5) if mode == "ahead"
                                    else None)
            assert all(o.topic == "submap" for o in late)
            outs = outs + late
        per_tick.append([(o.topic, encode(o.message)) for o in outs])
        x, y, yaw = pose
        pose = (x + cmd.v_mps * math.cos(yaw) * 0.1, y + cmd.v_mps * math.sin(yaw) * 0.1,
                yaw + cmd.omega_radps * 0.1)
    if mode == "ahead":
        per_tick.append([(o.topic, encode(o.message)) for o in core.finish_tick()])
    return per_tick


def test_odometry_ticks_run_ahead_of_unfinished_mapping_and_move_no_message() -> None:
    """The node finishes a frame's mapping step by step until its next input waits; an
    odometry-only tick then goes ahead of what is left (AgentCore._runs_ahead). Stopping
    at random steps changes no message: each tick's command and pose are the inline run's,
    and every topic's messages over the run come in the same order."""
    ticks = 90
    inline = _drive(AgentCore(AgentConfig(), 0, 0.1), ticks, "inline")
    core = AgentCore(AgentConfig(), 0, 0.1)
    ahead = _drive(core, ticks, "ahead")
    assert core.ran_ahead >= 10 and not core.unfinished
    for topic in ("cmd_vel", "pose"):
        assert [_by_topic(t).get(topic) for t in ahead[:ticks]] == \
            [_by_topic(t).get(topic) for t in inline]
    assert _by_topic([m for t in ahead for m in t]) == _by_topic([m for t in inline for m in t])


def _by_topic(messages: list[tuple[str, bytes]]) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    for topic, payload in messages:
        out.setdefault(topic, []).append(payload)
    return out


def test_mapping_deferred_past_the_command_changes_no_message_and_no_state() -> None:
    ticks = 90
    inline = _drive(AgentCore(AgentConfig(), 0, 0.1), ticks, "inline")
    deferred = _drive(AgentCore(AgentConfig(), 0, 0.1), ticks, "deferred")
    # the same messages each tick (poses and commands depend on the registration map, the
    # submaps on the voxels integrated); only the periodic delta moves behind the command
    assert [_by_topic(t) for t in deferred] == [_by_topic(t) for t in inline]
    assert sum(t == "submap" for tick in inline for t, _ in tick) >= 6
    moved = [k for k, tick in enumerate(deferred) if tick and tick[-1][0] == "submap"]
    assert moved and all(k % AgentConfig().submap_every_ticks == 0 for k in moved)
    # a caller that never finishes a tick loses nothing: the late delta leads the next tick
    unfinished = _drive(AgentCore(AgentConfig(), 0, 0.1), ticks, "unfinished")
    got = _by_topic([m for tick in unfinished for m in tick])
    want = _by_topic([m for tick in inline for m in tick])
    assert got["cmd_vel"] == want["cmd_vel"] and got["pose"] == want["pose"]
    assert got["submap"] == want["submap"][:len(got["submap"])]
    assert len(got["submap"]) >= len(want["submap"]) - 1  # the last tick's may still wait
