"""Until the fleet knows its wheels' scale, a registration's weak direction keeps another
power's weight against them (`agent.reg_weak_inflation_power_uncalibrated`)."""

from __future__ import annotations

import numpy as np
import pytest

from services.robot_agent.config import AgentConfig
from services.robot_agent.drift_filter import measurement_cov
from services.robot_agent.localization import Localizer
from services.robot_agent.odometry_calibration import Calibration, CalibrationParams, Segment
from services.robot_agent.params import registration_params


def _unit_segment() -> Segment:
    """1 m registered, 1.02 m on the wheels: one unit segment of the scale's evidence."""
    return Segment(odom_chord_m=1.02, reg_chord_m=1.0, odom_turn_rad=0.0, reg_turn_rad=0.0,
                   signed_distance_m=1.0, driven_m=1.0, turned_rad=0.0)


def test_pooled_segments_count_this_robots_and_its_teammates_unit_segments() -> None:
    params = CalibrationParams(fleet_prior_segments=8.0, min_segments_for_outliers=10**6)
    mine, teammate = Calibration(params), Calibration(params)
    assert mine.pooled_segments() == 0.0
    for _ in range(3):
        assert mine.add(_unit_segment())
    for _ in range(5):
        assert teammate.add(_unit_segment())
    assert mine.pooled_segments() == pytest.approx(3.0)
    mine.receive(7, [float(v) for v in teammate.own_stats()])
    assert mine.pooled_segments() == pytest.approx(8.0)


def _localizer(power_uncalibrated: float, segments: float) -> Localizer:
    cfg = AgentConfig(reg_weak_inflation_power_uncalibrated=power_uncalibrated,
                      reg_weak_inflation_calibrated_segments=segments)
    return Localizer(registration_params(cfg))


def test_the_uncalibrated_power_holds_until_the_fleet_has_its_segments_then_never_again(
) -> None:
    loc = _localizer(1.0, 4.0)
    filt = loc.registrar.params.filter
    assert filt.weak_inflation_power == 2.0  # the default
    cal = loc.odometry.calibration
    for k in range(4):
        assert loc._fusion_params(filt).weak_inflation_power == 1.0
        cal.add(_unit_segment())
        assert cal.pooled_segments() == pytest.approx(k + 1)
    assert loc._fusion_params(filt) is filt
    assert loc.frames_uncalibrated == -1
    # a teammate's reset cannot take it back: calibrated stays calibrated
    cal.receive(3, [0.0] * 7)
    assert loc._fusion_params(filt) is filt


def test_power_1_by_default_and_0_turns_it_off() -> None:
    loc = Localizer(registration_params(AgentConfig()))
    filt = loc.registrar.params.filter
    assert filt.calibrated_segments == 40.0
    assert loc._fusion_params(filt).weak_inflation_power == 1.0
    off = _localizer(0.0, 40.0)
    assert off._fusion_params(off.registrar.params.filter) is off.registrar.params.filter


def test_the_power_is_what_weighs_an_aisles_registration() -> None:
    filt = _localizer(0.0, 40.0).registrar.params.filter
    early = _localizer(1.0, 40.0)
    early_filt = early._fusion_params(early.registrar.params.filter)
    # an aisle: along x a hundred times weaker than across (small_gicp's H: rx ry rz tx ty tz)
    H6 = np.diag([1e3, 1e3, 1e3, 1.0, 100.0, 100.0])
    along_default = measurement_cov(H6, 0.0, filt)[0, 0]
    along_early = measurement_cov(H6, 0.0, early_filt)[0, 0]
    assert along_default == pytest.approx(100.0 * along_early)
