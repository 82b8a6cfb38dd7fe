"""Absolute heading from wall directions (wall_heading.py)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import small_gicp
from pydantic import ValidationError

from schemas.messages import Pose2D, RobotPose
from services.common.geometry import T_from_xyyaw, invert, transform_points, xyyaw_from_T
from services.robot_agent.agent import AgentCore
from services.robot_agent.config import AgentConfig
from services.robot_agent.wall_heading import (
    WallHeading,
    WallHeadingParams,
    fold,
    fuse_heading,
    gicp_covariance_terms,
    team_direction,
    wall_direction,
)
from tests.test_agent_localization import _wall

PARAMS = WallHeadingParams()


def _rotated(points: np.ndarray, yaw_deg: float) -> np.ndarray:
    return transform_points(T_from_xyyaw(0.0, 0.0, math.radians(yaw_deg)), points)


def _room(rng: np.random.Generator, noise_m: float = 0.005) -> np.ndarray:
    pts = np.concatenate([_wall(-3, -2, 3, -2, rng), _wall(-3, 2, 3, 2, rng),
                          _wall(-3, -2, -3, 2, rng), _wall(3, -2, 3, 2, rng)])
    return pts + rng.normal(0.0, noise_m, pts.shape)


def _frame(points_world: np.ndarray, xyyaw: tuple[float, float, float],
           ) -> tuple[np.ndarray, np.ndarray]:
    """The points a robot at `xyyaw` sees (all around, 4 m), downsampled as the registrar
    does: base-frame points (N, 3) and their normals (N, 3)."""
    p = transform_points(invert(T_from_xyyaw(*xyyaw)), points_world)
    p = p[np.linalg.norm(p[:, :2], axis=1) < 4.0]
    cloud, _ = small_gicp.preprocess_points(p, 0.08, num_neighbors=10, num_threads=1)
    return cloud.points()[:, :3], cloud.normals()[:, :3]


def test_the_covariance_terms_from_normals_are_small_gicps_covariances() -> None:
    rng = np.random.default_rng(3)
    pts = np.concatenate([_room(rng), rng.uniform(-2, 2, (300, 3))])
    cloud, _ = small_gicp.preprocess_points(pts, 0.08, num_neighbors=10, num_threads=1)
    covs = np.asarray(cloud.covs())[:, :3, :3]
    cxx, cyy, cxy, czz = gicp_covariance_terms(cloud.normals()[:, :3])
    for got, want in ((cxx, covs[:, 0, 0]), (cyy, covs[:, 1, 1]), (cxy, covs[:, 0, 1]),
                      (czz, covs[:, 2, 2])):
        np.testing.assert_allclose(got, want, atol=1e-12)
    assert np.ptp(czz) > 0.5  # walls and scattered points: the terms are not all alike


def test_a_frame_gives_its_walls_direction_modulo_90_degrees() -> None:
    rng = np.random.default_rng(0)
    room = _rotated(_room(rng), 17.0)
    for yaw_deg in (0.0, 31.0, -100.0):
        d = wall_direction(*_frame(room, (0.3, -0.2, math.radians(yaw_deg))), PARAMS)
        assert d is not None
        expected = fold(math.radians(17.0 - yaw_deg))
        assert abs(math.degrees(fold(d.angle_rad - expected))) < 0.05


def test_floor_only_gives_nothing() -> None:
    rng = np.random.default_rng(1)
    floor = np.column_stack([rng.uniform(-3, 3, 20000), rng.uniform(-3, 3, 20000),
                             rng.normal(0.0, 0.003, 20000) + 0.2])
    assert wall_direction(*_frame(floor, (0.0, 0.0, 0.0)), PARAMS) is None


def test_one_long_rotated_thing_does_not_set_the_direction() -> None:
    """Short walls and a long straight cabinet 2° off them: the segments' fit follows the
    cabinet, the points' directions do not, and a frame they disagree on gives nothing."""
    rng = np.random.default_rng(2)
    corner = np.concatenate([_wall(1.0, 1.0, 2.0, 1.0, rng), _wall(2.0, -0.2, 2.0, 1.0, rng)])
    a = math.radians(2.0)
    cabinet = _wall(-1.5, -1.5, -1.5 + 3.5 * math.cos(a), -1.5 + 3.5 * math.sin(a), rng)
    pts = np.concatenate([corner, cabinet])
    pts = pts + rng.normal(0.0, 0.003, pts.shape)
    assert wall_direction(*_frame(pts, (0.0, 0.0, 0.0)), PARAMS) is None
    # the same walls without the cabinet do give one
    alone = wall_direction(*_frame(corner + rng.normal(0, 0.003, corner.shape), (0.0, 0.0, 0.0)),
                           PARAMS)
    assert alone is not None and abs(math.degrees(alone.angle_rad)) < 0.1


def test_two_walls_in_line_metres_apart_are_two_segments() -> None:
    """Two wall patches 4.6 m apart along one line, 2.3 cm apart across it (two walls in
    line, or one seen past an obstacle, with depth noise): fitted as one segment they turn
    the direction by their offset over their distance; split at the gap each gives its own."""
    rng = np.random.default_rng(0)
    pts = np.concatenate([_wall(2.0, -3.0, 2.0, -2.3, rng), _wall(2.023, 2.3, 2.023, 3.0, rng)])
    frame = _frame(pts + rng.normal(0.0, 0.003, pts.shape), (0.0, 0.0, 0.0))
    joined = wall_direction(*frame, replace(PARAMS, along_gap_m=0.0))
    assert joined is not None and abs(math.degrees(joined.angle_rad)) > 0.2
    split = wall_direction(*frame, PARAMS)
    assert split is not None and abs(math.degrees(split.angle_rad)) < 0.05


def test_a_heading_pulls_yaw_and_the_position_its_error_swung() -> None:
    P = np.array([[1e-4, 0.0, 0.0], [0.0, 1e-4, 2e-4], [0.0, 2e-4, math.radians(1.0) ** 2]])
    out = fuse_heading(np.zeros(3), P, math.radians(0.8), math.radians(0.1), 10.83)
    assert out.accepted
    assert math.radians(0.7) < out.xyyaw[2] < math.radians(0.8)
    assert out.xyyaw[1] > 0.005 and out.xyyaw[0] == 0.0  # y correlated with yaw, x not
    assert out.P[2, 2] < math.radians(0.1) ** 2
    far = fuse_heading(np.zeros(3), P, math.radians(10.0), math.radians(0.1), 10.83)
    assert not far.accepted and np.all(far.xyyaw == 0.0)


def test_learned_at_the_start_the_walls_bring_a_lost_turn_back() -> None:
    """The start pose is known: the world's direction is learned there. After a 90° turn that
    odometry got 1° wrong, the walls give the heading back to a few hundredths of a degree;
    the whole room turned 10° (not this world's walls) is rejected."""
    rng = np.random.default_rng(3)
    room = _rotated(_room(rng), 5.0)
    walls = WallHeading(PARAMS)
    start = np.array([0.0, 0.0, 0.0])
    xyyaw, P = walls.update(start, np.zeros((3, 3)), *_frame(room, tuple(start)))
    assert walls.world_rad is not None and abs(math.degrees(walls.world_rad) - 5.0) < 0.05
    for _ in range(PARAMS.learn_frames):  # the rest of the frames it learns from
        walls.update(start, np.zeros((3, 3)), *_frame(room, tuple(start)))
    truth = (0.5, 0.3, math.radians(90.0))
    guess = np.array([0.5, 0.3, math.radians(91.0)])
    P = np.diag([1e-4, 1e-4, math.radians(1.0) ** 2])
    xyyaw, P = walls.update(guess, P, *_frame(room, truth))
    assert abs(math.degrees(xyyaw[2] - truth[2])) < 0.05
    other = _rotated(_room(rng), 15.0)
    kept, _ = walls.update(guess, np.diag([1e-4, 1e-4, math.radians(1.0) ** 2]),
                           *_frame(other, truth))
    assert np.all(kept == guess) and walls.n_rejected == 1


def test_the_team_outvotes_a_robot_that_learned_the_walls_off() -> None:
    """Warehouse, 24 robots: three learned the walls 0.5-1.3° off in the crowded start. The
    median of the robots' directions ignores them; those near it are averaged; the robot's
    own wins a tie; angles wrap at ±45°."""
    deg = np.radians
    team = [deg(x) for x in (-0.05, 0.03, 0.12, -0.18, 0.79, 0.49, 0.1)]
    world = team_direction(deg(1.31), team, deg(0.3))
    assert world is not None and abs(math.degrees(world) - 0.004) < 0.01
    assert abs(team_direction(deg(1.0), [deg(0.0)], deg(0.3)) - deg(1.0)) < 1e-12
    assert abs(math.degrees(team_direction(deg(0.1), [deg(0.0)], deg(0.3))) - 0.05) < 1e-9
    wrapped = team_direction(deg(44.9), [deg(-44.9), deg(44.8)], deg(0.3))
    assert abs(math.degrees(fold(wrapped - deg(44.933333))) ) < 1e-4
    assert team_direction(None, [], deg(0.3)) is None
    assert abs(team_direction(None, [deg(2.0)], deg(0.3)) - deg(2.0)) < 1e-12


def test_a_robot_that_learned_off_takes_the_team_direction_and_its_heading_back() -> None:
    """A robot whose odometry lost 1° before it learned holds its heading 1° off (its own
    direction agrees with its error); its teammates' directions reveal the error: the world
    direction moves to theirs, P grows by the change, and the next frame pulls the heading
    to the truth instead of being rejected."""
    rng = np.random.default_rng(5)
    room = _rotated(_room(rng), 0.0)
    walls = WallHeading(PARAMS)
    truth = (0.0, 0.0, 0.0)
    believed = np.array([0.0, 0.0, math.radians(1.0)])  # 1° off all through learning
    P_small = np.diag([1e-6, 1e-6, math.radians(0.1) ** 2])
    for _ in range(PARAMS.learn_frames):
        walls.update(believed, P_small, *_frame(room, truth))
    assert walls.own_rad is not None and abs(math.degrees(walls.own_rad) - 1.0) < 0.05
    assert abs(math.degrees(walls.shared(math.radians(2.0))) - 3.0) < 0.05  # world frame
    alone = WallHeading(PARAMS)  # no teammates: the 1° stays
    alone._learned, alone.n_frames, alone.world_rad = walls._learned, walls.n_frames, \
        walls.world_rad
    kept, _ = alone.update(believed, P_small, *_frame(room, truth))
    assert abs(math.degrees(kept[2]) - 1.0) < 0.05
    for rid, direction_deg in ((1, 0.02), (2, -0.03)):
        walls.receive(rid, math.radians(direction_deg + 2.0), math.radians(2.0))
    xyyaw, P = walls.update(believed, P_small, *_frame(room, truth))
    assert abs(math.degrees(walls.world_rad)) < 0.05
    assert walls.n_rejected == 0 and abs(math.degrees(xyyaw[2])) < 0.1
    assert P[2, 2] < math.radians(0.2) ** 2


def test_teammates_directions_travel_with_their_poses() -> None:
    """An agent keeps each teammate's learned direction from its pose messages (in its own
    frame) and sends none of its own before it has learned one; the message bounds it."""
    core = AgentCore(AgentConfig(), 0, 0.1, team_size=2)
    pose = Pose2D(x=1.0, y=0.0, yaw=0.0)
    core.on_pose(RobotPose(robot_id=1, tick=3, stamp_ns=3, pose_world=pose,
                           wall_direction_rad=0.01))
    core.on_pose(RobotPose(robot_id=2, tick=3, stamp_ns=3, pose_world=pose))
    assert core.localizer.walls is not None and list(core.localizer.walls.team) == [1]
    assert abs(core.localizer.walls.team[1] - 0.01) < 1e-12
    assert core.localizer.walls.shared(0.0) is None
    for bad in (1.0, float("nan")):
        with pytest.raises(ValidationError):
            RobotPose(robot_id=1, tick=3, stamp_ns=3, pose_world=pose, wall_direction_rad=bad)


def test_a_robot_that_agrees_with_the_team_keeps_its_own_direction() -> None:
    """Within the inlier window nothing changes: the robot fuses against what it learned,
    as it would alone (3-robot missions run exactly as without teammates)."""
    rng = np.random.default_rng(6)
    room = _rotated(_room(rng), 0.1)
    walls = WallHeading(PARAMS)
    start = np.zeros(3)
    for _ in range(PARAMS.learn_frames):
        walls.update(start, np.zeros((3, 3)), *_frame(room, (0.0, 0.0, 0.0)))
    own = walls.own_rad
    assert own is not None and abs(math.degrees(own) - 0.1) < 0.1
    walls.receive(1, own - math.radians(0.2), 0.0)  # the median: own is 0.2° off it
    walls.receive(2, own - math.radians(0.25), 0.0)
    walls.update(start, np.diag([1e-6, 1e-6, 1e-6]), *_frame(room, (0.0, 0.0, 0.0)))
    assert walls.world_rad == own


def test_a_jump_of_the_edge_correction_does_not_move_the_team_direction() -> None:
    """AWS house, seed 4 (view gain): the edge's correction of robot 1 rotated by a wrong
    +0.73°; converted with it, both teammates' directions sat 0.57° from robot 1's own, the
    team outvoted it and the agent turned its heading to the edge's error. A teammate's
    direction is kept as it first arrived, so the robot keeps its own."""
    rng = np.random.default_rng(6)
    room = _rotated(_room(rng), 0.1)
    walls = WallHeading(PARAMS)
    start = np.zeros(3)
    for _ in range(PARAMS.learn_frames):
        walls.update(start, np.zeros((3, 3)), *_frame(room, (0.0, 0.0, 0.0)))
    own = walls.own_rad
    assert own is not None
    for rid in (1, 2):
        walls.receive(rid, own + math.radians(0.1), 0.0)
    for rid in (1, 2):  # the same directions, this robot's correction now +0.73° off
        walls.receive(rid, own + math.radians(0.1), math.radians(0.73))
    assert all(abs(math.degrees(v - own) - 0.1) < 1e-9 for v in walls.team.values())
    walls.update(start, np.diag([1e-6, 1e-6, 1e-6]), *_frame(room, (0.0, 0.0, 0.0)))
    assert walls.world_rad == own


def test_walls_that_disagree_alike_frame_after_frame_take_a_confident_wrong_heading_back(
) -> None:
    """Warehouse, seed 0: a robot turned into new ground with 1-7° of yaw error, registered
    every frame to the map it built meanwhile, and the gate (its yaw σ 0.1°) rejected all 125
    wall headings that would have brought it back. With `reacquire_frames` the walls win once
    that many in a row agree; walls that disagree among themselves never do."""
    rng = np.random.default_rng(11)
    room = _room(rng)
    params = WallHeadingParams(reacquire_frames=4)
    truth = (0.0, 0.0, 0.0)
    P_small = np.diag([1e-6, 1e-6, math.radians(0.1) ** 2])

    def learned(p: WallHeadingParams) -> WallHeading:
        walls = WallHeading(p)
        for _ in range(p.learn_frames):
            walls.update(np.zeros(3), P_small, *_frame(room, truth))
        return walls

    walls, never = learned(params), learned(WallHeadingParams(reacquire_frames=None))
    wrong = np.array([0.0, 0.0, math.radians(3.0)])
    for _ in range(3):
        kept, P = walls.update(wrong, P_small, *_frame(room, truth))
        assert np.all(kept == wrong) and P[2, 2] == P_small[2, 2]
    back, P = walls.update(wrong, P_small, *_frame(room, truth))
    assert walls.n_reacquired == 1 and abs(math.degrees(back[2])) < 0.05
    assert P[2, 2] < math.radians(0.25) ** 2
    for _ in range(10):
        kept, _ = never.update(wrong, P_small, *_frame(room, truth))
        assert np.all(kept == wrong)
    assert never.n_rejected == 10
    # the frames' walls disagree among themselves (rooms turned ±1°): no re-acquisition
    other = learned(params)
    for yaw_deg in (1.0, -1.0, 1.0, -1.0, 1.0, -1.0):
        kept, _ = other.update(wrong, P_small, *_frame(_rotated(room, yaw_deg), truth))
        assert np.all(kept == wrong)
    assert other.n_rejected == 6 and other.n_reacquired == 0


def _heading_after_reacquiring(reset: bool) -> list[float]:
    """Yaw (deg) per frame of a localizer whose registration map was built 3° off, standing
    still in a room while its walls say so; the walls re-acquire after 3 frames."""
    from services.robot_agent.drift_filter import FilterParams
    from services.robot_agent.localization import Localizer
    from services.robot_agent.registrar import RegistrationParams
    rng = np.random.default_rng(2)
    room = _room(rng, 0.002)
    params = RegistrationParams(
        map_voxel_m=0.05, min_points=30, filter=FilterParams(),
        wall_heading=WallHeadingParams(reacquire_frames=3), reset_on_wall_reacquire=reset)
    loc = Localizer(params)
    still = T_from_xyyaw(0.0, 0.0, 0.0)
    points = transform_points(invert(still), room)
    points = points[np.linalg.norm(points[:, :2], axis=1) < 4.0]
    for _ in range(PARAMS.learn_frames + 1):  # the start pose is known: walls learned there
        loc.update(points, still)
    wrong = T_from_xyyaw(0.0, 0.0, math.radians(3.0))  # a bad turn's heading, map built there
    loc.registrar.reset()
    loc.registrar.insert(loc.registrar.cloud_tree(points)[0], wrong)
    loc.T_loc_odom = wrong
    loc.P = np.diag([1e-6, 1e-6, math.radians(0.1) ** 2])
    return [math.degrees(xyyaw_from_T(loc.update(points, still).T_loc_base)[2])
            for _ in range(12)]


def test_a_heading_the_walls_took_back_stays_once_the_map_built_off_is_forgotten() -> None:
    """Without forgetting the map built at the wrong heading, registration against it pulls
    the heading back after the walls re-acquired it (the two took turns 9 times for one
    warehouse robot, whose estimate wandered 0.6 m while it stood still)."""
    forgetting = _heading_after_reacquiring(reset=True)
    assert abs(forgetting[0] - 3.0) < 0.1  # the walls are rejected at first
    assert all(abs(yaw) < 0.1 for yaw in forgetting[3:])
    keeping = _heading_after_reacquiring(reset=False)
    assert any(abs(yaw) > 1.0 for yaw in keeping[4:])


def _after_the_team_corrects(reset_rad: float) -> list[np.ndarray]:
    """(x, y, yaw°) per frame of a localizer that learned the walls while 1° off (its map
    built there too), standing still in a room, once two teammates' directions arrive."""
    from services.robot_agent.drift_filter import FilterParams
    from services.robot_agent.localization import Localizer
    from services.robot_agent.registrar import RegistrationParams
    rng = np.random.default_rng(4)
    room = _room(rng, 0.002)
    params = RegistrationParams(
        map_voxel_m=0.05, min_points=30, filter=FilterParams(reacquire_frames=3),
        wall_heading=WallHeadingParams(), reset_on_wall_conflict_rad=reset_rad)
    loc = Localizer(params)
    still = T_from_xyyaw(0.0, 0.0, 0.0)
    points = transform_points(invert(still), room)
    points = points[np.linalg.norm(points[:, :2], axis=1) < 4.0]
    off = T_from_xyyaw(0.0, 0.0, math.radians(1.0))  # a turn on odometry alone lost 1°
    loc.T_loc_odom = off
    loc.P = np.diag([1e-6, 1e-6, math.radians(0.05) ** 2])
    for _ in range(PARAMS.learn_frames + 1):  # learned (and mapped) 1° off
        loc.update(points, still)
    assert abs(math.degrees(loc.walls.own_rad) - 1.0) < 0.1
    for rid in (1, 2):
        loc.walls.receive(rid, 0.0, 0.0)
    out = []
    for _ in range(10):
        x, y, yaw = xyyaw_from_T(loc.update(points, still).T_loc_base)
        out.append(np.array([x, y, math.degrees(yaw)]))
    return out


def test_a_heading_the_team_corrects_stays_once_the_map_built_off_is_forgotten() -> None:
    """The team's direction overrules a robot's own by 1° and turns its heading back in one
    frame, and the frame's registration sides with the old heading: forgetting the map built
    there keeps the correction (yaw within 0.1° from then on); keeping the map,
    registrations against it take the heading back."""
    forgetting = _after_the_team_corrects(math.radians(0.5))
    assert all(abs(p[2]) < 0.1 for p in forgetting[1:])
    assert all(np.hypot(p[0], p[1]) < 0.01 for p in forgetting)
    keeping = _after_the_team_corrects(0.0)
    assert any(abs(p[2]) > 0.5 for p in keeping[1:])


def test_a_map_that_agrees_with_the_walls_correction_is_kept() -> None:
    """A heading lost behind teammates (the map is right, the filter 1° off with a wide σ):
    the walls turn it back, the frame's registration agrees, and the map stays."""
    from services.robot_agent.drift_filter import FilterParams
    from services.robot_agent.localization import Localizer
    from services.robot_agent.registrar import RegistrationParams
    rng = np.random.default_rng(6)
    room = _room(rng, 0.002)
    loc = Localizer(RegistrationParams(
        map_voxel_m=0.05, min_points=30, filter=FilterParams(),
        wall_heading=WallHeadingParams(), reset_on_wall_conflict_rad=math.radians(0.5)))
    still = T_from_xyyaw(0.0, 0.0, 0.0)
    points = transform_points(invert(still), room)
    points = points[np.linalg.norm(points[:, :2], axis=1) < 4.0]
    for _ in range(PARAMS.learn_frames + 1):
        loc.update(points, still)
    inserted = loc.registrar.n_inserted
    loc.T_loc_odom = T_from_xyyaw(0.0, 0.0, math.radians(1.0))
    loc.P = np.diag([1e-6, 1e-6, math.radians(1.5) ** 2])
    yaw = xyyaw_from_T(loc.update(points, still).T_loc_base)[2]
    assert abs(math.degrees(yaw)) < 0.1
    assert loc.outcomes["map reset by the walls"] == 0
    assert loc.registrar.n_inserted >= inserted
