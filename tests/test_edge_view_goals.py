"""Far views of high frontier regions (services/edge_server/view_goals.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.common.grid import GridSpec
from services.edge_server.view_goals import ViewGeometry, region_top_z, view_goals

RES = 0.05
GEOMETRY = ViewGeometry(camera_height_m=0.35, half_vfov_rad=math.radians(34.08), range_m=5.0)


def _room(h: int = 120, w: int = 160) -> tuple[GridSpec, np.ndarray]:
    """A 6 × 8 m room of free cells with a 0.4 m deep shelf along the middle (rows 58-65,
    cols 20-139): the shelf's cells are occupied, not free."""
    spec = GridSpec(0.0, 0.0, RES, h, w)
    free = np.ones((h, w), bool)
    free[[0, -1], :] = free[:, [0, -1]] = False
    free[58:66, 20:140] = False
    return spec, free


def test_needed_distance_is_where_the_top_of_the_fov_reaches_above_the_region() -> None:
    d = GEOMETRY.needed_m(np.array([1.4, -0.1]))
    assert d[0] == pytest.approx((1.4 + 0.4 - 0.35) / math.tan(math.radians(34.08)))
    assert d[1] == 0.0  # a margin below the camera: any distance sees it


def test_region_top_z_is_the_quantile_of_each_region() -> None:
    labels = np.array([0, 0, 0, 0, 0, 2, 2])
    z = np.array([0.1, 0.5, 0.3, 0.9, 0.7, 1.0, 2.0])
    top = region_top_z(labels, z, 3, 0.75)
    assert top[0] == pytest.approx(0.7)  # sorted 0.1 0.3 0.5 0.7 0.9, rank round(0.75·4) = 3
    assert np.isnan(top[1])
    assert top[2] == pytest.approx(2.0)


def test_a_high_region_gets_a_goal_far_enough_back_on_its_own_side_in_sight() -> None:
    spec, free = _room()
    anchor = np.array([[66, 80]])  # on the shelf's north face
    near_goal = np.array([[70, 80]])  # the nearest reachable cell, 0.2 m north of it
    z_top = np.array([1.4])
    goal, moved = view_goals(anchor, near_goal, z_top, free, free, spec, GEOMETRY)
    assert moved[0]
    dist = np.hypot(*(goal[0] - anchor[0])) * RES
    need = GEOMETRY.needed_m(z_top)[0]
    assert need <= dist <= need + GEOMETRY.extra_m + RES
    assert goal[0, 0] > 66  # north of the shelf, where the robots are
    assert free[goal[0, 0], goal[0, 1]]
    # straight out from the face is the smallest angle off its normal
    assert abs(goal[0, 1] - 80) <= 3


def test_a_low_region_keeps_its_goal() -> None:
    spec, free = _room()
    anchor, near_goal = np.array([[66, 80]]), np.array([[70, 80]])
    goal, moved = view_goals(anchor, near_goal, np.array([0.1]), free, free, spec, GEOMETRY)
    assert not moved[0]
    np.testing.assert_array_equal(goal, near_goal)


def test_no_view_through_walls_or_beyond_the_incidence_limit() -> None:
    spec, free = _room()
    # an aisle 0.8 m wide north of the shelf, closed 1.5 m out: no cell 2 m+ back in sight
    free[82:86, :] = False
    anchor, near_goal = np.array([[66, 80]]), np.array([[70, 80]])
    goal, moved = view_goals(anchor, near_goal, np.array([1.4]), free, free, spec, GEOMETRY)
    # the only lines of sight left run along the aisle, more than 75° off the face's normal
    # within the needed distance... unless they clear it: whatever is chosen is in the aisle
    if moved[0]:
        assert 66 < goal[0, 0] < 82
        off = math.degrees(math.atan2(abs(goal[0, 1] - 80), goal[0, 0] - 66))
        assert off <= 75.0 + 1e-6
    # with the incidence limit at 45° nothing along the aisle qualifies
    strict = ViewGeometry(0.35, math.radians(34.08), 5.0, max_incidence_rad=math.radians(45))
    goal, moved = view_goals(anchor, near_goal, np.array([1.4]), free, free, spec, strict)
    assert not moved[0]
    np.testing.assert_array_equal(goal, near_goal)


def test_goals_only_on_allowed_cells() -> None:
    spec, free = _room()
    goal_ok = free.copy()
    goal_ok[66:, :] = False  # the north side may not hold goals
    anchor, near_goal = np.array([[66, 80]]), np.array([[70, 80]])
    goal, moved = view_goals(anchor, near_goal, np.array([1.4]), free, goal_ok, spec, GEOMETRY)
    assert not moved[0]  # the south side is behind the shelf: no line of sight through it


def test_a_view_goal_faces_its_region_and_once_reached_sets_the_region_aside() -> None:
    from schemas.messages import GoalStatus
    from services.edge_server.assignment import make_scorer
    from services.edge_server.config import EdgeConfig
    from services.edge_server.frontiers import FrontierSet
    from services.edge_server.goals import GoalBook
    from services.edge_server.robot_fields import RobotFields

    spec, free = _room()
    anchor = np.array([[66, 80]])
    goal_rc = np.array([[100, 80]])  # the far view, 1.7 m north of the face
    labels = np.zeros(free.shape, np.int32)
    labels[66, 70:90] = 1
    fs = FrontierSet(labels=labels, sizes=np.array([40]), centroid_xy=spec.centre_of(anchor),
                     anchor_rc=anchor, anchor_xy=spec.centre_of(anchor), goal_rc=goal_rc,
                     goal_xy=spec.centre_of(goal_rc), weak=np.zeros(1, bool),
                     gain=np.ones(1), importance=np.ones(1), view=np.ones(1, bool))
    config = EdgeConfig(space_view_goals=True)
    book = GoalBook(config)
    fields = RobotFields(free, {0: np.array([20, 20])}, 3.0)
    poses = np.array([[1.0, 1.0, 0.0]])
    out = book.plan(1, [0], fields, fs, spec, make_scorer("space", config), poses)
    assert out.assigned == {0: 0}
    goal = out.new_goals[0]
    assert goal.look_xy == pytest.approx(tuple(spec.centre_of(anchor)[0]))
    book.on_status(GoalStatus(robot_id=0, tick=5, goal_id=goal.goal_id, status="reached"))
    # the region comes back with its goal elsewhere (another far cell): it is set aside,
    # by its anchor, for good
    moved = FrontierSet(**{**fs.__dict__, "goal_rc": np.array([[100, 40]]),
                           "goal_xy": spec.centre_of(np.array([[100, 40]]))})
    assert not book.allowed(moved, 10**6)[0]


@pytest.mark.parametrize("keep_by_anchor", [True, False])
def test_a_goal_is_kept_while_its_region_keeps_its_anchor_under_a_weak_one(
        keep_by_anchor: bool) -> None:
    from services.edge_server.assignment import make_scorer
    from services.edge_server.config import EdgeConfig
    from services.edge_server.frontiers import FrontierSet
    from services.edge_server.goals import GoalBook
    from services.edge_server.robot_fields import RobotFields

    spec, free = _room()
    # region 0 (F_u, a far view) has lost all its label cells to region 1 (F_w) drawn over
    # it 0.6 m away; region 2 is a fresh F_u region as good as region 0 by its score
    anchors = np.array([[66, 80], [66, 92], [100, 20]])
    goals = np.array([[100, 80], [70, 92], [104, 20]])
    labels = np.zeros(free.shape, np.int32)
    labels[66, 92:104] = 2
    labels[100, 15:25] = 3

    def regions() -> FrontierSet:
        return FrontierSet(labels=labels, sizes=np.array([40, 40, 40]),
                           centroid_xy=spec.centre_of(anchors), anchor_rc=anchors,
                           anchor_xy=spec.centre_of(anchors), goal_rc=goals,
                           goal_xy=spec.centre_of(goals), weak=np.array([False, True, False]),
                           gain=np.array([1.0, 0.01, 1.0]), importance=np.ones(3),
                           view=np.array([True, False, False]))

    config = EdgeConfig(space_view_goals=True, keep_by_anchor=keep_by_anchor)
    book = GoalBook(config)
    fields = RobotFields(free, {0: np.array([90, 80])}, 3.0)
    poses = np.array([[*spec.centre_of(np.array([[90, 80]]))[0], math.pi / 2]])  # facing f′
    scorer = make_scorer("space", config)
    first = book.plan(1, [0], fields, regions(), spec, scorer, poses)
    assert first.assigned == {0: 0}  # the nearest goal
    second = book.plan(2, [0], fields, regions(), spec, scorer, poses)
    if keep_by_anchor:
        assert second.assigned == {0: 0} and second.new_goals == []
    else:  # the window search finds no cell of region 0 within the keep radius
        assert book.drops["region gone"] == 1


def test_the_edge_takes_the_camera_from_the_sim_section_unless_it_sets_its_own() -> None:
    from services.config import load_config
    from services.evaluator.world_truth import eval_config_for

    config = load_config(overrides={"sim.hfov_deg": 90.0, "sim.camera_height_m": 0.5,
                                    "sim.range_m": 4.0})
    assert config.edge.camera_height_m == 0.5
    assert config.edge.camera_range_m == 4.0
    # the same vertical half-FoV the evaluator's observable truth uses
    assert config.edge.camera_half_vfov_deg == pytest.approx(
        eval_config_for(config.sim).max_elevation_deg)
    default = load_config()
    assert default.edge.camera_half_vfov_deg == pytest.approx(
        eval_config_for(default.sim).max_elevation_deg, abs=1e-3)
    own = load_config(overrides={"sim.camera_height_m": 0.5, "edge.camera_height_m": 0.3})
    assert own.edge.camera_height_m == 0.3
