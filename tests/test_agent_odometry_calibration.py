"""Online odometry calibration: the error model learned from good registrations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.robot_agent.config import AgentConfig
from services.robot_agent.odometry_calibration import (
    CalibratedOdometry,
    Calibration,
    CalibrationParams,
    OdometryErrors,
    Segment,
    corrected_increment,
    is_good_registration,
)
from services.robot_agent.params import registration_params
from services.simulator.odometry import OdometryNoise, WheelOdometry

NOISE = OdometryNoise(scale_error=0.02, yaw_scale_error=0.01, heading_bias_rad_per_m=0.005,
                      noise_m_per_sqrt_m=0.01, noise_rad_per_sqrt_rad=0.01)


def _path(n: int) -> list[tuple[float, float, float]]:
    """A lawnmower drive as between shelf rows: 4 m straight at 0.4 m/s, a quarter turn in
    place, a short leg, a quarter turn back the other way, and a little reversing."""
    x = y = yaw = 0.0
    poses = [(x, y, yaw)]
    legs = [(0.4, 0.0, 100), (0.0, 0.5, 31), (0.3, 0.0, 10), (0.0, 0.5, 31), (-0.1, 0.0, 10),
            (0.4, 0.0, 100), (0.0, -0.5, 31), (0.3, 0.0, 10), (0.0, -0.5, 31)]
    while len(poses) <= n:
        for v, w, ticks in legs:
            for _ in range(ticks):
                yaw += w * 0.1
                x += v * 0.1 * math.cos(yaw)
                y += v * 0.1 * math.sin(yaw)
                poses.append((x, y, yaw))
    return poses[: n + 1]


def _drive(errors_known: bool, n: int = 4000) -> tuple[CalibratedOdometry, float, float]:
    """Feed the simulator's odometry along a path, with registrations (truth + 3 mm / 0.1°
    noise) every second tick; returns the calibration and the final raw and corrected
    position errors."""
    rng = np.random.default_rng(3)
    truth = _path(n)
    wheels = WheelOdometry(truth[0], NOISE, np.random.default_rng(7))
    cal = CalibratedOdometry(CalibrationParams())
    raw = np.array(truth[0])
    for k, true in enumerate(truth):
        if k:
            raw = np.array(wheels.update(true, 0.1)[0])
        cal.observe(raw)
        if errors_known and k % 2 == 0:
            meas = np.array(true) + rng.normal(0, [0.003, 0.003, 0.0017])
            cal.registered(meas)
    corrected = cal.observe(raw)
    err = lambda p: float(np.hypot(p[0] - truth[-1][0], p[1] - truth[-1][1]))  # noqa: E731
    return cal, err(raw), err(corrected)


def test_the_error_model_is_learned_from_registrations() -> None:
    cal, _, _ = _drive(True)
    e = cal.calibration.errors
    assert cal.calibration.n_used > 50
    assert abs(e.scale - 0.02) < 0.003
    assert abs(e.turn_scale - 0.01) < 0.004
    assert abs(e.heading_bias_rad_per_m - 0.005) < 0.0015


def test_corrected_odometry_drifts_less_than_raw() -> None:
    _, raw_err, corrected_err = _drive(True)
    assert raw_err > 0.3
    assert corrected_err < 0.5 * raw_err


def test_without_registrations_the_odometry_is_unchanged() -> None:
    cal, raw_err, corrected_err = _drive(False, n=500)
    assert cal.calibration.errors == OdometryErrors()
    assert corrected_err == pytest.approx(raw_err, abs=1e-9)


def test_a_segment_ended_by_a_slid_registration_is_left_out() -> None:
    cal = CalibratedOdometry(CalibrationParams())
    for k in range(12):  # straight 1 m segments, odometry exact
        cal.observe(np.array([float(k), 0.0, 0.0]))
        cal.registered(np.array([float(k), 0.0, 0.0]))
    before = cal.calibration.errors
    cal.observe(np.array([12.0, 0.0, 0.0]))
    cal.registered(np.array([11.7, 0.0, 0.0]))  # slid 30 cm along an aisle
    assert cal.calibration.n_rejected == 1
    assert cal.calibration.errors == before


def test_correction_inverts_the_error_model() -> None:
    errors = OdometryErrors(scale=0.02, turn_scale=0.01, heading_bias_rad_per_m=0.005)
    true = np.array([0.05, 0.001, 0.02])
    d = math.hypot(true[0], true[1])
    measured = np.array([1.02 * true[0], 1.02 * true[1], 1.01 * true[2] + 0.005 * d])
    np.testing.assert_allclose(corrected_increment(measured, errors), true, atol=1e-12)


def test_frames_of_one_wall_or_new_ground_end_no_segment() -> None:
    params = CalibrationParams()
    round_R = np.diag([1e-4, 1e-4, 1e-5])
    aisle_R = np.diag([1e-2, 1e-4, 1e-5])
    assert is_good_registration(0.9, round_R, params)
    assert not is_good_registration(0.9, aisle_R, params)
    assert not is_good_registration(0.5, round_R, params)


def test_how_weak_a_segment_end_may_be_is_the_agent_config() -> None:
    half_aisle_R = np.diag([2e-3, 1e-4, 1e-5])  # 20 times weaker along x
    for ratio, good in ((10.0, False), (30.0, True)):
        params = registration_params(AgentConfig(odom_calibration_max_weak_ratio=ratio))
        assert params.calibration is not None
        assert bool(is_good_registration(0.9, half_aisle_R, params.calibration)) is good


def test_the_localizer_learns_the_scale_of_wheels_that_over_read() -> None:
    """Back and forth across a room on wheels that read 5 % long: the localizer's
    registrations teach it the scale, and its odometry guess is then corrected."""
    from services.common.geometry import T_from_xyyaw, xyyaw_from_T
    from services.robot_agent.drift_filter import FilterParams
    from services.robot_agent.localization import Localizer
    from services.robot_agent.registrar import RegistrationParams
    from tests.test_agent_localization import _room, _seen

    room = _room(np.random.default_rng(4))
    loc = Localizer(RegistrationParams(map_voxel_m=0.05, min_points=30, filter=FilterParams(),
                                       calibration=CalibrationParams()))
    raw = np.zeros(3)
    true_prev = np.array([-1.5, 0.3, 0.0])
    for k in range(241):  # twelve 2 m legs out and back, 10 cm a frame
        x = -1.5 + 0.1 * (k % 20 if (k // 20) % 2 == 0 else 20 - k % 20)
        true = np.array([x, 0.3, 0.0])
        raw = raw + 1.05 * (true - true_prev) if k else np.array([-1.5, 0.3, 0.0])
        true_prev = true
        loc.update(_seen(room, T_from_xyyaw(*true)), T_from_xyyaw(*raw))
    assert abs(loc.odometry.calibration.errors.scale - 0.05) < 0.01
    # one more metre on the wheels alone: the guess follows the truth, not the wheels
    guess = xyyaw_from_T(loc.guess(T_from_xyyaw(*(raw + np.array([1.05, 0.0, 0.0])))))
    assert abs(guess[0] - (true[0] + 1.0)) < 0.02


def _segments(seed: int, n: int, scale: float = 0.02) -> list:
    """Segments of a wheel with the simulator's errors (distance `scale` long),
    registrations 1 cm / 0.2° noisy."""
    from services.robot_agent.odometry_calibration import segment_between

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        d, turn = rng.uniform(0.5, 2.0), rng.uniform(-1.0, 1.0)
        reg_to = np.array([d * math.cos(turn / 2), d * math.sin(turn / 2), turn])
        odom_turn = turn * 1.01 + 0.005 * d
        k = 1.0 + scale
        odom_to = np.array([k * reg_to[0], k * reg_to[1], odom_turn])
        noisy = reg_to + rng.normal(0, [0.01, 0.01, 0.0035])
        out.append(segment_between(np.zeros(3), odom_to, np.zeros(3), noisy, odom_turn,
                                   k * d, k * d, abs(odom_turn)))
    return out


def test_a_fleet_pool_counts_teammates_segments_as_its_own() -> None:
    """With fleet_weight 1, a robot with few segments of its own and its teammates' sums fits
    as one robot that had every segment; with 0 it keeps its own estimate; a robot with none
    of its own drives on the fleet's."""
    from services.robot_agent.odometry_calibration import Calibration

    params = CalibrationParams(fleet_weight=1.0, min_segments_for_outliers=10**6)
    mine, theirs, everything = Calibration(params), Calibration(params), Calibration(params)
    own, other = _segments(1, 2), _segments(2, 30)
    for seg in own:
        mine.add(seg)
        everything.add(seg)
    for seg in other:
        theirs.add(seg)
        everything.add(seg)
    alone = mine.errors
    mine.set_fleet(theirs.own_stats())
    for got, want in ((mine.errors.scale, everything.errors.scale),
                      (mine.errors.turn_scale, everything.errors.turn_scale),
                      (mine.errors.heading_bias_rad_per_m,
                       everything.errors.heading_bias_rad_per_m)):
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12)
    assert abs(mine.errors.scale - 0.02) < abs(alone.scale - 0.02)
    assert mine.own_stats() == pytest.approx(Calibration(params).own_stats() + sum(
        _stats_of(params, s) for s in own))
    solo = Calibration(CalibrationParams(fleet_weight=0.0))
    for seg in own:
        solo.add(seg)
    before = solo.errors
    solo.set_fleet(theirs.own_stats())
    assert solo.errors == before
    newcomer = Calibration(params)
    newcomer.set_fleet(theirs.own_stats())
    assert newcomer.errors.scale == pytest.approx(0.02, abs=0.004)


def test_a_fleet_prior_starts_a_robot_on_the_fleets_wheels_and_yields_to_its_own() -> None:
    """With fleet_prior_segments, a robot with no segment drives on its teammates' fit; one
    whose wheels differ (1 % long against the fleet's 3 %) ends near its own as its segments
    outnumber the prior, where full pooling keeps it on the fleet's."""
    from services.robot_agent.odometry_calibration import Calibration

    fleet = Calibration(CalibrationParams(min_segments_for_outliers=10**6))
    for seg in _segments(2, 60, scale=0.03):
        fleet.add(seg)
    hier = CalibrationParams(fleet_prior_segments=8.0, min_segments_for_outliers=10**6)
    newcomer = Calibration(hier)
    newcomer.set_fleet(fleet.own_stats())
    for got, want in ((newcomer.errors.scale, fleet.errors.scale),
                      (newcomer.errors.turn_scale, fleet.errors.turn_scale),
                      (newcomer.errors.heading_bias_rad_per_m,
                       fleet.errors.heading_bias_rad_per_m)):
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12)
    assert Calibration(hier).shared() is not None
    prior, pooled = Calibration(hier), Calibration(
        CalibrationParams(fleet_weight=1.0, min_segments_for_outliers=10**6))
    for cal in (prior, pooled):
        cal.set_fleet(fleet.own_stats())
    for k, seg in enumerate(_segments(3, 80, scale=0.01)):
        prior.add(seg)
        pooled.add(seg)
        if k == 3:  # a few segments: still near the fleet's
            assert prior.errors.scale > 0.02
    assert prior.errors.scale == pytest.approx(0.01, abs=0.003)
    assert pooled.errors.scale > 0.015
    assert prior.errors.turn_scale == pytest.approx(0.01, abs=0.004)


def _stats_of(params: CalibrationParams, seg: object) -> np.ndarray:
    from services.robot_agent.odometry_calibration import Calibration

    one = Calibration(params)
    one.add(seg)  # type: ignore[arg-type]
    return one.own_stats()


def test_pose_messages_carry_seven_finite_calibration_sums() -> None:
    from schemas import decode, encode
    from schemas.messages import Pose2D, RobotPose

    pose = RobotPose(robot_id=1, tick=3, stamp_ns=300, pose_world=Pose2D(x=0, y=0, yaw=0),
                     odometry_stats=[1.0, 2.0, 3.0, 0.5, 4.0, 0.1, -0.2])
    assert decode(encode(pose), RobotPose).odometry_stats == pose.odometry_stats
    for bad in ([1.0] * 6, [1.0] * 6 + [float("nan")]):
        with pytest.raises(ValueError):
            RobotPose(robot_id=1, tick=3, stamp_ns=300, pose_world=Pose2D(x=0, y=0, yaw=0),
                      odometry_stats=bad)


def _learned_scale_against_a_map_that_pulls(frame_pairs: bool) -> float:
    """Back and forth across a room on wheels that read 5 % long, with every registration
    against the map reading each distance 1 % long too (as a map built on the uncorrected
    wheels pulls a frame back toward them): the scale the localizer learns (no prior)."""
    from services.common.geometry import T_from_xyyaw
    from services.robot_agent.drift_filter import FilterParams
    from services.robot_agent.localization import Localizer
    from services.robot_agent.registrar import RegistrationParams
    from tests.test_agent_localization import _room, _seen

    room = _room(np.random.default_rng(4))
    loc = Localizer(RegistrationParams(map_voxel_m=0.05, min_points=30, filter=FilterParams(),
                                       calibration=CalibrationParams(frame_pairs=frame_pairs,
                                                                     prior_segments=0.0)))
    align = loc.registrar.align

    def pulled(cloud, guess):  # noqa: ANN001, ANN202
        out = align(cloud, guess)
        if isinstance(out, str):
            return out
        T = out[0].copy()
        T[0, 3] = -1.5 + 1.01 * (T[0, 3] + 1.5)
        return T, out[1], out[2]

    loc.registrar.align = pulled
    raw = np.zeros(3)
    true_prev = np.array([-1.5, 0.3, 0.0])
    for k in range(241):
        x = -1.5 + 0.1 * (k % 20 if (k // 20) % 2 == 0 else 20 - k % 20)
        true = np.array([x, 0.3, 0.0])
        raw = raw + 1.05 * (true - true_prev) if k else np.array([-1.5, 0.3, 0.0])
        true_prev = true
        loc.update(_seen(room, T_from_xyyaw(*true)), T_from_xyyaw(*raw))
    assert loc.odometry.calibration.n_used >= 5
    return loc.odometry.calibration.errors.scale


def test_frame_pairs_learn_the_wheels_where_the_map_pulls_toward_them() -> None:
    assert _learned_scale_against_a_map_that_pulls(frame_pairs=False) < 0.04
    assert abs(_learned_scale_against_a_map_that_pulls(frame_pairs=True) - 0.05) < 0.003


def test_a_frame_pair_locked_on_the_wrong_shelf_is_refused() -> None:
    """The end frame aligned to the segment's first gives the true motion from a guess a
    few centimetres off, and nothing from a guess further off than the map can be (a pair
    that converged there would have jumped to another, identical shelf)."""
    from services.common.geometry import T_from_xyyaw, invert, xyyaw_from_T
    from services.robot_agent.localization import Localizer
    from services.robot_agent.registrar import FrameRegistrar, RegistrationParams
    from tests.test_agent_localization import _room, _seen

    room = _room(np.random.default_rng(5))
    reg = FrameRegistrar(RegistrationParams(min_points=30))
    T_a, T_b = T_from_xyyaw(-1.0, 0.2, 0.1), T_from_xyyaw(0.0, 0.3, 0.3)
    first = reg.cloud_tree(_seen(room, T_a))
    cloud = reg.cloud_tree(_seen(room, T_b))[0]
    truth = invert(T_a) @ T_b
    params = CalibrationParams()
    near = Localizer._pair_motion(first, cloud, truth @ T_from_xyyaw(0.03, -0.02, 0.01), params)
    assert near is not None
    assert np.allclose(xyyaw_from_T(near), xyyaw_from_T(truth), atol=5e-3)
    assert Localizer._pair_motion(first, cloud, truth @ T_from_xyyaw(0.15, 0.0, 0.0),
                                  params) is None


def test_a_given_up_segment_opens_again_at_the_next_good_frame() -> None:
    odo = CalibratedOdometry(CalibrationParams(segment_m=1.0))
    assert not odo.due()  # no odometry yet
    odo.observe(np.zeros(3))
    assert odo.due() and odo.anchor_xyyaw is None
    odo.registered(np.zeros(3))
    odo.observe(np.array([0.5, 0.0, 0.0]))
    assert not odo.due()
    odo.observe(np.array([1.2, 0.0, 0.0]))
    assert odo.due()
    odo.drop_segment()
    assert odo.anchor_xyyaw is None
    odo.registered(np.array([1.18, 0.0, 0.0]))
    assert odo.calibration.n_used == 0 and np.allclose(odo.anchor_xyyaw, [1.18, 0, 0])


def test_no_prior_and_straight_segments_only_learn_the_scale_without_failing() -> None:
    """`odom_calibration_prior_segments` may be 0: before any turn the turn scale and the
    heading bias cannot be told apart, and the fit must still give the scale."""
    cal = Calibration(CalibrationParams(prior_segments=0.0))
    for _ in range(3):
        assert cal.add(Segment(odom_chord_m=1.02, reg_chord_m=1.0, odom_turn_rad=0.0,
                               reg_turn_rad=0.0, signed_distance_m=0.0, driven_m=1.02,
                               turned_rad=0.0))
    assert abs(cal.errors.scale - 0.02) < 1e-9
    assert np.isfinite(cal.errors.turn_scale) and np.isfinite(cal.errors.heading_bias_rad_per_m)


def _teammates(scales: list[float], n: int) -> list:
    from services.robot_agent.odometry_calibration import Calibration

    out = []
    for k, scale in enumerate(scales):
        cal = Calibration(CalibrationParams(min_segments_for_outliers=10**6))
        for seg in _segments(100 + k, n, scale=scale):
            cal.add(seg)
        out.append(cal.own_stats())
    return out


def test_the_fleet_spread_sets_the_priors_weight_heavy_for_alike_wheels_light_otherwise() -> None:
    """Eight teammates on the same wheels: the between-robot variance is their noise alone
    and the prior weighs near the cap; eight whose wheels are 1-4 % long: no heavier than
    the configured floor's order; too few teammates: the configured weight."""
    from services.robot_agent.odometry_calibration import (
        Calibration,
        between_variance,
        fleet_prior_weights,
    )

    params = CalibrationParams(fleet_prior_segments=8.0, fleet_prior_from_spread=True,
                               min_segments_for_outliers=10**6)
    alike = np.array(_teammates([0.02] * 8, 60))
    differ = np.array(_teammates([0.01, 0.04, 0.02, 0.03, 0.015, 0.035, 0.01, 0.04], 60))
    assert fleet_prior_weights(alike, params)[0] > 500
    assert fleet_prior_weights(differ, params)[0] < 40
    assert between_variance(np.array([0.01]), np.array([1.0])) == np.inf
    # a robot of the alike fleet with a few noisy segments of its own stays on the fleet's
    # scale; the same robot among the differing fleet follows its own
    mine = _segments(7, 6, scale=0.035)
    for fleet, near in ((alike, 0.02), (differ, None)):
        cal = Calibration(params)
        for r, stats in enumerate(fleet):
            cal.receive(r, list(stats))
        for seg in mine:
            cal.add(seg)
        if near is not None:
            assert cal.errors.scale == pytest.approx(near, abs=0.002)
        else:
            assert cal.errors.scale > 0.028
    few = Calibration(params)
    for r, stats in enumerate(alike[:3]):
        few.receive(r, list(stats))
    fixed = Calibration(CalibrationParams(fleet_prior_segments=8.0,
                                          min_segments_for_outliers=10**6))
    for r, stats in enumerate(alike[:3]):
        fixed.receive(r, list(stats))
    for seg in mine:
        few.add(seg)
        fixed.add(seg)
    assert few.errors == fixed.errors


def _corners(n_corners: int) -> list[tuple[float, float, float]]:
    """Twelve quarter turns in place (a robot looking round at its start), then 1.5 m
    straight, a quarter turn on a 0.5 m arc (left, then right, ...), 1.5 m straight: one
    corner per 76 ticks, as a robot drives round the ends of shelf rows."""
    x = y = yaw = 0.0
    poses = [(x, y, yaw)]
    for _ in range(12 * 16):
        yaw += 0.1 * (math.pi / 2) / 1.6
        poses.append((x, y, yaw))
    for i in range(n_corners):
        w = 1.0 if i % 2 == 0 else -1.0
        for v, omega, ticks in ((0.5, 0.0, 30), (0.5, w, 16), (0.5, 0.0, 30)):
            for _ in range(ticks):
                yaw += omega * 0.1 * (math.pi / 2) / 1.6  # 16 ticks make a quarter turn
                x += v * 0.1 * math.cos(yaw)
                y += v * 0.1 * math.sin(yaw)
                poses.append((x, y, yaw))
    return poses


@pytest.mark.parametrize("turn_corrected", [True, False])
def test_segments_round_a_corner_learn_the_wheels_scale_with_the_turns_taken_out(
        turn_corrected: bool) -> None:
    """Wheels 2 % long that over-turn by 5 %: each segment's raw odometry path bends more
    than the true one, so its chord is short of 1.02 × the true chord (about 4 % here). Taken
    from the increments with the learned turn errors out (learned first, from the turns in
    place), the chord gives the wheels' scale; from the raw poses, far less."""
    truth = _corners(40)
    wheels = WheelOdometry(truth[0], OdometryNoise(scale_error=0.02, yaw_scale_error=0.05,
                                                   heading_bias_rad_per_m=0.0),
                           np.random.default_rng(0))
    cal = CalibratedOdometry(CalibrationParams(turn_corrected_chords=turn_corrected))
    for k, true in enumerate(truth):
        raw = np.array(wheels.update(true, 0.1)[0]) if k else np.array(true)
        cal.observe(raw)
        # registrations after each turn in place, then only between corners
        if (k <= 192 and k % 16 == 0) or (k > 192 and (k - 192) % 76 == 0):
            cal.registered(np.array(true))
    e = cal.calibration.errors
    assert cal.calibration.n_used >= 45
    assert abs(e.turn_scale - 0.05) < 0.005
    if turn_corrected:
        assert abs(e.scale - 0.02) < 0.003
    else:
        assert e.scale < 0.0


def test_turn_corrected_chords_are_the_agent_config() -> None:
    assert AgentConfig().odom_calibration_turn_corrected_chords
    assert registration_params(AgentConfig()).calibration.turn_corrected_chords
    params = registration_params(AgentConfig(odom_calibration_turn_corrected_chords=False))
    assert params.calibration is not None
    assert not params.calibration.turn_corrected_chords
