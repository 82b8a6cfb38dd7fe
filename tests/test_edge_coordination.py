"""The coordinated `space` scorer's pieces (coordination.py), each on a case it must decide."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from services.common.grid import GridSpec
from services.config import SpacemapConfig
from services.edge_server.assignment import greedy_match, make_scorer
from services.edge_server.config import EdgeConfig
from services.edge_server.coordination import (
    RobotStates,
    joint_match,
    partition_factor,
    teammate_factor,
    travel_time_s,
    view_information,
)
from services.edge_server.frontiers import FrontierSet, frontier_length_near


def regions(centroid_xy: list[tuple[float, float]], gain: list[float]) -> FrontierSet:
    """Regions whose goal f′ is their centroid (labels unused by the scorers)."""
    xy = np.array(centroid_xy, np.float64)
    n = len(xy)
    return FrontierSet(labels=np.zeros((1, 1), np.int32), sizes=np.full(n, 10),
                       centroid_xy=xy, anchor_rc=np.zeros((n, 2), np.int64), anchor_xy=xy,
                       goal_rc=np.zeros((n, 2), np.int64), goal_xy=xy,
                       weak=np.zeros(n, bool), gain=np.array(gain, np.float64),
                       importance=np.ones(n))


def test_view_information_counts_every_region_a_goal_sees() -> None:
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0]])
    view = view_information(xy, xy, np.array([1.0, 2.0, 4.0]), radius_m=1.5)
    np.testing.assert_allclose(view, [3.0, 3.0, 4.0])
    alone = view_information(xy, xy, np.array([1.0, 2.0, 4.0]), radius_m=0.0)
    np.testing.assert_allclose(alone, [1.0, 2.0, 4.0])  # a goal always sees its own region


def test_teammate_goal_discounts_what_it_will_see() -> None:
    xy = np.array([[0.0, 0.0], [3.0, 0.0]])
    np.testing.assert_allclose(teammate_factor(xy, np.array([[0.5, 0.0]]), 1.0, 0.25),
                               [0.25, 1.0])
    np.testing.assert_allclose(teammate_factor(xy, np.zeros((0, 2)), 1.0, 0.25), [1.0, 1.0])


def test_travel_time_charges_the_turn() -> None:
    goals = np.array([[1.0, 0.0], [-1.0, 0.0]])
    t = travel_time_s(np.array([[1.0, 1.0]]), np.zeros((1, 2)), np.zeros(1), goals, 0.5,
                      math.pi / 4)
    np.testing.assert_allclose(t, [[2.0, 2.0 + 4.0]])  # 180° at π/4 rad/s


def test_joint_match_maximises_the_total_where_greedy_does_not() -> None:
    scores = np.array([[10.0, 9.0], [8.0, -np.inf]])
    assert greedy_match(scores) == {0: 0}  # robot 1 left without a goal
    assert joint_match(scores) == {0: 1, 1: 0}
    assert joint_match(np.full((2, 3), -np.inf)) == {}
    assert joint_match(np.array([[1.0, 2.0], [-np.inf, -np.inf]])) == {0: 1}
    three = joint_match(np.array([[5.0, 4.0, 1.0], [4.0, 1.0, -np.inf], [2.0, -np.inf, 3.0]]))
    assert three == {0: 1, 1: 0, 2: 2}


def test_space_prefers_the_region_ahead_and_a_cluster_over_a_lone_region() -> None:
    scorer = make_scorer("space", EdgeConfig(space_view_radius_m=1.0))
    robot = RobotStates(np.zeros((1, 2)), np.zeros(1), np.zeros((0, 2)))
    ahead_behind = regions([(2.0, 0.0), (-2.0, 0.0)], [1.0, 1.0])
    s = scorer.score(np.array([[2.0, 2.0]]), ahead_behind, robot)
    assert s[0, 0] > s[0, 1]
    paper = make_scorer("space-paper", EdgeConfig())
    p = paper.score(np.array([[2.0, 2.0]]), ahead_behind, robot)
    assert p[0, 0] == p[0, 1]  # the paper's h counts metres only
    lone_vs_cluster = regions([(2.0, 0.0), (2.0, 3.0), (2.5, 3.0), (2.0, 3.5)], [1.0] * 4)
    path = np.hypot(lone_vs_cluster.goal_xy[:, 0], lone_vs_cluster.goal_xy[:, 1])[None, :]
    s = scorer.score(path, lone_vs_cluster, robot)
    assert int(np.argmax(s[0])) in (1, 2, 3)


def test_space_steers_a_robot_away_from_a_teammate_goal() -> None:
    fs = regions([(2.0, 0.0), (0.0, 2.6)], [1.0, 1.0])
    path = np.array([[2.0, 2.6]])
    scorer = make_scorer("space", EdgeConfig(space_view_radius_m=1.0))
    alone = RobotStates(np.zeros((1, 2)), np.array([math.pi / 4]), np.zeros((0, 2)))
    assert int(np.argmax(scorer.score(path, fs, alone)[0])) == 0
    teammate = RobotStates(np.zeros((1, 2)), np.array([math.pi / 4]), np.array([[2.2, 0.0]]))
    assert int(np.argmax(scorer.score(path, fs, teammate)[0])) == 1
    unreachable = scorer.score(np.array([[np.inf, 1.0]]), fs, alone)
    assert unreachable[0, 0] == -np.inf


def test_a_wider_teammate_radius_keeps_a_robot_out_of_a_teammates_room() -> None:
    # the near region is 3 m from a teammate's goal: outside the view radius, inside 4 m
    fs = regions([(2.0, 0.0), (0.0, 2.6)], [1.0, 1.0])
    path = np.array([[2.0, 2.6]])
    robot = RobotStates(np.zeros((1, 2)), np.array([math.pi / 4]), np.array([[5.0, 0.0]]))
    narrow = make_scorer("space", EdgeConfig(space_view_radius_m=1.0))
    assert int(np.argmax(narrow.score(path, fs, robot)[0])) == 0
    wide = make_scorer("space", EdgeConfig(space_view_radius_m=1.0, space_teammate_radius_m=4.0))
    assert int(np.argmax(wide.score(path, fs, robot)[0])) == 1


def test_partition_counts_a_goal_in_full_only_for_the_robot_nearest_it() -> None:
    goals = np.array([[-4.0, 0.0], [4.0, 0.0], [0.0, 3.0]])
    robots = np.array([[-1.0, 0.0], [1.0, 0.0]])
    f = partition_factor(goals, robots, np.array([[0.0, 5.0]]), 0.5)
    np.testing.assert_allclose(f, [[1.0, 0.5, 0.5], [0.5, 1.0, 0.5]])  # (0, 3) is the goal's
    np.testing.assert_allclose(partition_factor(goals, robots, np.zeros((0, 2)), 1.0), 1.0)
    alone = partition_factor(goals, robots[:1], np.zeros((0, 2)), 0.5)
    np.testing.assert_allclose(alone, 1.0)  # no teammate, no partition


def test_a_team_that_starts_together_fans_out_with_the_partition() -> None:
    """Two robots side by side, a rich region just left of both and a poorer one far right:
    without the partition the two share the near ones and nobody goes right; with it the
    right-hand robot takes the far right region, its own side."""
    fs = regions([(-1.0, 0.0), (-0.5, 1.0), (6.0, 0.0)], [1.0, 0.9, 0.8])
    robots = RobotStates(np.array([[-0.2, 0.0], [0.2, 0.0]]), np.zeros(2), np.zeros((0, 2)))
    path = np.hypot(*(fs.goal_xy[None, :, :] - robots.xy_world[:, None, :]).transpose(2, 0, 1))
    plain = make_scorer("space", EdgeConfig(space_view_radius_m=0.0))
    assert sorted(plain.match(plain.score(path, fs, robots)).values()) == [0, 1]
    part = make_scorer("space", EdgeConfig(space_view_radius_m=0.0,
                                           space_partition_discount=0.2))
    matched = part.match(part.score(path, fs, robots))
    assert matched[1] == 2 and matched[0] in (0, 1)


def test_mission_config_gives_the_edge_the_agents_speeds() -> None:
    c = SpacemapConfig.model_validate({"agent": {"max_v_mps": 0.3, "max_omega_radps": 0.5}})
    assert (c.edge.nav_v_mps, c.edge.nav_omega_radps) == (0.3, 0.5)
    own = SpacemapConfig.model_validate({"agent": {"max_v_mps": 0.3}, "edge": {"nav_v_mps": 0.4}})
    assert own.edge.nav_v_mps == 0.4
    assert SpacemapConfig().edge.nav_v_mps == SpacemapConfig().agent.max_v_mps


def test_grid_border_near_a_goal_counts_only_free_unknown_border() -> None:
    """The floor a goal looks into: free cells next to unknown ones within the square, in
    metres; unknown space behind a wall (no free border) counts nothing."""
    spec = GridSpec(0.0, 0.0, 0.05, 100, 100)
    known = np.zeros((100, 100), bool)
    known[:, :50] = True
    free = known.copy()
    free[40:, 40:50] = False  # rows 40+ end at a wall (occupied) before the unknown
    cells = np.array([[20, 45], [80, 35], [20, 5]])
    near = frontier_length_near(free, known, cells, spec, 1.0, 5)
    np.testing.assert_allclose(near, [40 * 0.05, 0.0, 0.0], atol=1e-6)


def test_space_with_grid_gain_goes_where_the_unknown_floor_is() -> None:
    """Two equal regions at equal distance: without the grid term it is a tie broken by
    order; with it the one at a long border to unknown floor wins, unless a teammate's goal
    is already there."""
    fs = replace(regions([(2.0, 0.0), (-2.0, 0.0)], [1.0, 1.0]),
                 grid_frontier_m=np.array([0.0, 3.0]))
    path = np.array([[2.0, 2.0]])
    robot = RobotStates(np.zeros((1, 2)), np.array([math.pi / 2]), np.zeros((0, 2)))
    plain = make_scorer("space", EdgeConfig()).score(path, fs, robot)
    assert plain[0, 0] == plain[0, 1]
    scorer = make_scorer("space", EdgeConfig(space_grid_gain_per_m=0.3))
    assert int(np.argmax(scorer.score(path, fs, robot)[0])) == 1
    held = RobotStates(np.zeros((1, 2)), np.array([math.pi / 2]), np.array([[-2.5, 0.0]]))
    assert int(np.argmax(scorer.score(path, fs, held)[0])) == 0


def test_a_large_region_outbids_a_speck_nearer_only_when_sizes_count() -> None:
    """AWS house seed 1: a robot 6 m from a 1211-voxel region took a 394-voxel one 2 m away;
    the mean entropy alone (the paper's I_g) is blind to size, and teammates drove back
    across the house for the large one 100 s later."""
    robot = RobotStates(np.zeros((1, 2)), np.zeros(1), np.zeros((0, 2)))
    fs = replace(regions([(2.0, 0.0), (6.0, 0.0)], [0.3, 0.3]), sizes=np.array([8, 1211]))
    path = np.array([[2.0, 6.0]])
    plain = make_scorer("space", EdgeConfig(space_size_exponent=0)).score(path, fs, robot)
    assert int(np.argmax(plain[0])) == 0
    sized = make_scorer("space", EdgeConfig(space_size_exponent=0.5, space_size_ref_voxels=0)
                        ).score(path, fs, robot)
    assert int(np.argmax(sized[0])) == 1
    # the weight is relative to the smallest region the detector keeps: a minimal one × 1
    np.testing.assert_allclose(sized[0, 0], plain[0, 0])


def test_sizes_under_the_reference_keep_their_information() -> None:
    """With `space_size_ref_voxels`, regions up to that size score as without sizes, a larger
    F_u region × (size / ref)^exponent, and a weak region of any size as without sizes."""
    robot = RobotStates(np.zeros((1, 2)), np.zeros(1), np.zeros((0, 2)))
    fs = replace(regions([(2.0, 0.0), (6.0, 0.0), (-6.0, 0.0)], [0.3, 0.3, 0.3]),
                 sizes=np.array([150, 800, 800]), weak=np.array([False, False, True]))
    path = np.array([[2.0, 6.0, 6.0]])
    plain = make_scorer("space", EdgeConfig(space_size_exponent=0)).score(path, fs, robot)
    sized = make_scorer("space", EdgeConfig(space_size_exponent=0.5, space_size_ref_voxels=200)
                        ).score(path, fs, robot)
    np.testing.assert_allclose(sized[0, [0, 2]], plain[0, [0, 2]])
    np.testing.assert_allclose(sized[0, 1], plain[0, 1] * 2.0)


def test_a_lower_time_exponent_lets_a_far_cluster_outbid_a_near_speck() -> None:
    """One region 1 m ahead against three within view of a goal 6 m ahead: per second of
    travel the near one wins; with the time counted at power 0.5 the far cluster does."""
    robot = RobotStates(np.zeros((1, 2)), np.zeros(1), np.zeros((0, 2)))
    fs = regions([(1.0, 0.0), (6.0, 0.0), (6.0, 0.5), (6.0, -0.5)], [1.0] * 4)
    fs = replace(fs, goal_xy=np.array([[1.0, 0.0], [6.0, 0.0], [6.0, 0.0], [6.0, 0.0]]))
    path = np.array([[1.0, 6.0, 6.0, 6.0]])
    per_second = make_scorer("space", EdgeConfig()).score(path, fs, robot)
    assert int(np.argmax(per_second[0])) == 0
    damped = make_scorer("space", EdgeConfig(space_time_exponent=0.5)).score(path, fs, robot)
    assert int(np.argmax(damped[0])) in (1, 2, 3)
    # exponent 1 is the plain ratio, to the bit
    np.testing.assert_array_equal(
        make_scorer("space", EdgeConfig(space_time_exponent=1.0)).score(path, fs, robot),
        per_second)
