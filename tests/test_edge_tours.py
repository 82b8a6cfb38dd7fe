"""Min-max tours over the frontier regions (`edge.space_tour`, tours.py), and goal keeping."""

from __future__ import annotations

import numpy as np

from services.common.grid import GridSpec
from services.edge_server.assignment import make_scorer
from services.edge_server.config import EdgeConfig
from services.edge_server.frontiers import FrontierSet
from services.edge_server.goals import ActiveGoal, GoalBook
from services.edge_server.robot_fields import RobotFields
from services.edge_server.tours import coarse_paths_m, min_max_routes, route_length_s, two_opt

CELL = 0.1


def test_coarse_paths_go_around_a_wall_and_not_through_a_sealed_one() -> None:
    trav = np.ones((40, 40), bool)
    trav[:30, 20:22] = False  # a wall from the top, open below row 30
    src = np.array([[5, 10]])
    dst = np.array([[5, 30], [5, 12]])
    d = coarse_paths_m(trav, src, dst, 2, CELL)
    assert d.shape == (1, 2)
    assert 4.0 < d[0, 0] < 7.0  # down to row 30, across, back up: far more than the 2 m
    assert d[0, 1] < 0.5
    trav[30:, 20:22] = False  # sealed
    assert np.isinf(coarse_paths_m(trav, src, dst, 2, CELL)[0, 0])


def test_routes_split_a_line_between_robots_at_its_two_ends() -> None:
    xs = np.arange(1.0, 11.0)
    start = np.stack([xs, 11.0 - xs])
    leg = np.abs(xs[:, None] - xs[None, :])
    routes = min_max_routes(start, np.zeros(2), leg, 0.0)
    assert sorted(routes[0] + routes[1]) == list(range(10))
    assert routes[0][0] == 0 and routes[1][0] == 9  # each starts at its own end
    ends = [route_length_s(r, start[i], 0.0, leg, 0.0) for i, r in enumerate(routes)]
    assert max(ends) <= 5.0 + 1e-9


def test_routes_leave_out_what_nobody_reaches_and_weigh_a_late_start() -> None:
    xs = np.arange(1.0, 5.0)
    start = np.stack([xs, xs])
    leg = np.abs(xs[:, None] - xs[None, :])
    start[:, 3] = leg[3, :3] = leg[:3, 3] = np.inf  # region 3: nobody gets there
    routes = min_max_routes(start, np.array([0.0, 100.0]), leg, 1.0)
    assert routes[1] == []  # a robot busy for 100 s more takes nothing
    assert sorted(routes[0]) == [0, 1, 2]


def corridor(cols: list[int]) -> tuple[np.ndarray, FrontierSet, GridSpec]:
    """A 3-cell-wide corridor 60 cells long; one region per column given."""
    trav = np.zeros((5, 60), bool)
    trav[1:4, :] = True
    rc = np.array([[2, c] for c in cols], np.int64)
    xy = (rc[:, ::-1] + 0.5) * CELL
    n = len(cols)
    labels = np.zeros(trav.shape, np.int32)
    labels[rc[:, 0], rc[:, 1]] = np.arange(1, n + 1)
    fs = FrontierSet(labels=labels, sizes=np.full(n, 10), centroid_xy=xy, anchor_rc=rc,
                     anchor_xy=xy, goal_rc=rc, goal_xy=xy, weak=np.zeros(n, bool),
                     gain=np.ones(n), importance=np.ones(n))
    return trav, fs, GridSpec(0.0, 0.0, CELL, *trav.shape)


def plan(config: EdgeConfig, robots_col: dict[int, int], book: GoalBook | None = None
         ) -> dict[int, int]:
    trav, fs, spec = corridor([6, 8, 10, 12, 55])
    book = book or GoalBook(config)
    starts = {r: np.array([2, c]) for r, c in robots_col.items()}
    fields = RobotFields(trav, starts, 3.0)
    poses = np.array([[(c + 0.5) * CELL, 0.25, 0.0] for c in robots_col.values()])
    return book.plan(1, list(robots_col), fields, fs, spec, make_scorer("space", config),
                     poses).assigned


def test_a_tour_sends_one_robot_to_the_far_region_the_revenue_leaves_for_last() -> None:
    # two robots at the corridor's start, four regions close by and one 5 m away
    base = EdgeConfig(space_view_radius_m=0.05)
    assert 4 not in plan(base, {0: 2, 1: 3}).values()  # best per second: the near ones
    got = plan(base.model_copy(update={"space_tour": True}), {0: 2, 1: 3})
    assert sorted(got) == [0, 1] and 4 in got.values()


def test_a_tour_counts_a_teammate_on_its_way_to_the_far_region() -> None:
    config = EdgeConfig(space_view_radius_m=0.05, space_tour=True)
    book = GoalBook(config)
    far = (55.5 * CELL, 0.25)
    book.active[1] = ActiveGoal(7, far, far, 1.0)  # robot 1 keeps the far region
    got = plan(config, {0: 2, 1: 30}, book)
    assert got[1] == 4 and got[0] in (0, 1, 2, 3)
    assert got[0] == 0  # the near ones in order, from the nearest


def test_two_opt_undoes_a_crossing() -> None:
    xs = np.array([1.0, 2.0, 3.0, 4.0])
    leg = np.abs(xs[:, None] - xs[None, :])
    assert two_opt([0, 2, 1, 3], xs, leg) == [0, 1, 2, 3]
    assert two_opt([3, 2, 1, 0], xs, leg) == [0, 1, 2, 3]  # the end is free: start near


def test_a_robot_whose_goal_cell_was_taken_keeps_its_region_at_the_new_goal() -> None:
    # robot 0 heads for the region at column 40; its old goal cell (column 42) is now blocked
    # and the region's f′ is column 40. A nearer region (column 10) would win a new assignment.
    config = EdgeConfig(space_view_radius_m=0.05, keep_radius_m=0.3)
    trav, fs, spec = corridor([40, 10])
    trav[:, 42] = False
    old = (42.5 * CELL, 0.25)
    for retarget, expected in ((False, 1), (True, 0)):
        book = GoalBook(config.model_copy(update={"retarget_goals": retarget}))
        book.active[0] = ActiveGoal(7, old, (40.5 * CELL, 0.25), 1.0)
        book.next_goal_id = 8
        fields = RobotFields(trav, {0: np.array([2, 30])}, 3.0)
        result = book.plan(1, [0], fields, fs, spec, make_scorer("space", config),
                           np.array([[3.05, 0.25, np.pi]]))
        assert result.assigned == {0: expected}
        assert [g.goal_id for g in result.new_goals] == [8]  # a new goal either way
        assert np.isclose(result.new_goals[0].x, fs.goal_xy[expected, 0])
