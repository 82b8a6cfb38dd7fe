"""Mutual awareness: the paper's inequality and the partial-view variant."""

from __future__ import annotations

import math

import numpy as np

from services.robot_agent.awareness import (
    angle_to_targets,
    in_view_partial,
    normalize_angle,
    visible_paper,
)

FOV = math.radians(84.1)
KW = {"radius_m": 0.306, "fov_rad": FOV, "range_m": 5.0, "c": 0.25}


def test_in_front_behind_and_out_of_range() -> None:
    targets = np.array([[2.0, 0.0], [-2.0, 0.0], [6.0, 0.0]])
    assert visible_paper((0.0, 0.0, 0.0), targets, **KW).tolist() == [True, False, False]
    assert in_view_partial((0.0, 0.0, 0.0), targets, **KW).tolist() == [True, False, False]


def test_fov_edge_paper_needs_the_whole_robot_partial_takes_any_part() -> None:
    d = 2.0
    alpha = math.atan(0.306 / d)
    just_in = FOV / 2 - alpha - 0.25 / d - 0.01  # whole buffered robot inside
    at_edge = FOV / 2  # centre on the border: half the robot in view
    just_out = FOV / 2 + alpha + 0.25 / d + 0.01  # buffered circle entirely outside
    xy = np.array([[d * math.cos(a), d * math.sin(a)] for a in (just_in, at_edge, just_out)])
    assert visible_paper((0.0, 0.0, 0.0), xy, **KW).tolist() == [True, False, False]
    assert in_view_partial((0.0, 0.0, 0.0), xy, **KW).tolist() == [True, True, False]


def test_angle_wraps_at_pi() -> None:
    # observer looking at ψ = 179°, target at θ = −179°: Δθ is 2°, not −358°
    obs = (0.0, 0.0, math.radians(179.0))
    target = np.array([[2 * math.cos(math.radians(-179.0)), 2 * math.sin(math.radians(-179.0))]])
    b = angle_to_targets(obs, target, 0.306)
    assert math.isclose(float(b.dtheta[0]), math.radians(2.0), abs_tol=1e-9)
    assert visible_paper(obs, target, **KW)[0]
    # ψ given unnormalised (ψ + 4π) changes nothing
    obs_big = (0.0, 0.0, math.radians(179.0) + 4 * math.pi)
    assert math.isclose(float(angle_to_targets(obs_big, target, 0.306).dtheta[0]),
                        math.radians(2.0), abs_tol=1e-9)
    assert np.allclose(normalize_angle(np.array([math.pi, -math.pi, 3 * math.pi])), -math.pi)


def test_vectorized_and_distance_term() -> None:
    b = angle_to_targets((1.0, 1.0, 0.0), np.array([[1.0, 3.0], [4.0, 5.0]]), 0.306)
    assert np.allclose(b.d, [2.0, 5.0])
    assert np.allclose(b.alpha, np.arctan(0.306 / np.array([2.0, 5.0])))


def test_partial_range_is_depth_not_distance() -> None:
    # at 40° off the axis, 6 m away is 4.6 m of depth: the camera sees it within γ = 5 m
    a = math.radians(40.0)
    xy = np.array([[6.0 * math.cos(a), 6.0 * math.sin(a)], [7.5 * math.cos(a), 7.5 * math.sin(a)]])
    assert in_view_partial((0.0, 0.0, 0.0), xy, **KW).tolist() == [True, False]
    assert not visible_paper((0.0, 0.0, 0.0), xy, **KW).any()  # the paper's test keeps d ≤ γ
