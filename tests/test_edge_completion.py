"""Completion rules: visited F_w regions, repeated strikes, and the cropped distance fields."""

from __future__ import annotations

import math

import numpy as np

from schemas.messages import GoalStatus
from services.common.grid import GridSpec
from services.common.planning import distance_fields
from services.edge_server.completion import CompletionJudge, VisitLog
from services.edge_server.config import EdgeConfig
from services.edge_server.frontiers import FrontierSet, frontier_set
from services.edge_server.goals import GoalBook
from services.edge_server.planner import EdgePlanner
from services.edge_server.robot_fields import all_fields as robot_fields
from tests.test_edge_map import make_submap, voxel_centres


def test_visit_log_needs_range_and_field_of_view() -> None:
    log = VisitLog(range_m=2.0, fov_rad=math.radians(84.1))
    pts = np.array([[1.5, 0.0], [0.0, 1.5], [3.0, 0.0], [-1.0, 0.0]])
    assert not log.seen(pts).any()
    log.record(0, 0.0, 0.0, 0.0)  # facing +x
    assert log.seen(pts).tolist() == [True, False, False, False]
    log.record(0, 0.05, 0.0, 0.05)  # near-duplicate viewpoint: not stored
    assert len(log.views) == 1
    log.record(0, 0.0, 0.0, math.pi / 2)  # turned to +y
    assert log.seen(pts).tolist() == [True, True, False, False]


def test_the_tail_completes_when_its_regions_are_a_small_enough_fraction_of_the_map() -> None:
    def verdicts(config: EdgeConfig, fractions: list[float | None]) -> list[bool]:
        judge = CompletionJudge(config, tick_s=0.1)
        return [judge.update(100 + 10 * k, 5, 10_000, f) for k, f in enumerate(fractions)]

    tail = [0.01, 0.0008, 0.0009, None, 0.0005, 0.0004, 0.001, 0.02]
    off = EdgeConfig(complete_unexplored_fraction=0.0)
    assert not any(verdicts(off, tail))  # assignable frontiers left and the rule off
    on = off.model_copy(update={"complete_unexplored_fraction": 0.001,
                                "complete_unexplored_plans": 3})
    # a grid-fallback plan (None) breaks the run; the third plan in a row at or under it ends
    assert verdicts(on, tail) == [False] * 6 + [True, True]
    small = CompletionJudge(on, tick_s=0.1)  # the map's minimum size still holds
    assert not any(small.update(100 + 10 * k, 5, 10, 0.0) for k in range(5))


def _one_frontier_at(xy: tuple[float, float]):
    spec = GridSpec(0.0, 0.0, 0.05, 40, 40)
    mask = np.zeros(spec.shape, bool)
    r, c = spec.cell_of(np.array([xy]))[0]
    mask[r - 1 : r + 2, c - 1 : c + 2] = True
    return frontier_set(mask, np.ones(spec.shape, bool), spec, 1, 1.0)


def test_third_strike_at_one_place_sets_it_aside_for_good() -> None:
    book = GoalBook(EdgeConfig(planner="space-paper", blacklist_strikes=3, blacklist_ticks=50,
                               reached_blacklist_ticks=50))
    fs = _one_frontier_at((1.0, 1.0))
    for goal_id, (tick, status) in enumerate([(0, "invalid"), (100, "reached")]):
        book.issued[goal_id] = (1.0, 1.0, False)
        book.on_status(GoalStatus(robot_id=0, tick=tick, goal_id=goal_id, status=status))
        assert not book.allowed(fs, tick + 10)[0]
        assert book.allowed(fs, tick + 60)[0]  # two strikes: still expires
    book.issued[2] = (1.1, 1.0, False)  # the same place, within blacklist_radius_m
    book.on_status(GoalStatus(robot_id=0, tick=200, goal_id=2, status="unreachable"))
    assert not book.allowed(fs, 10**8)[0]
    assert book.allowed(_one_frontier_at((1.8, 1.8)), 300)[0]  # elsewhere unaffected


def test_space_sets_a_reached_place_aside_for_good_the_paper_for_a_while() -> None:
    fs = _one_frontier_at((1.0, 1.0))
    for planner, later in (("space", False), ("space-paper", True)):
        book = GoalBook(EdgeConfig(planner=planner, reached_blacklist_ticks=50))
        book.issued[0] = (1.0, 1.0, False)
        book.on_status(GoalStatus(robot_id=0, tick=0, goal_id=0, status="reached"))
        assert not book.allowed(fs, 10)[0]
        assert book.allowed(fs, 10**6)[0] == later, planner


def test_second_look_moves_the_goal_off_the_place_already_looked_from() -> None:
    """With space_second_look_m the region stays a target, seen from another place only."""
    spec = GridSpec(0.0, 0.0, 0.1, 40, 40)
    reachable = np.ones(spec.shape, bool)
    book = GoalBook(EdgeConfig(planner="space", space_second_look_m=0.8))
    book.issued[0] = (1.0, 1.0, False)
    book.on_status(GoalStatus(robot_id=0, tick=0, goal_id=0, status="reached"))
    assert book.allowed(_one_frontier_at((1.0, 1.0)), 10)[0]  # not set aside ...
    cells = book.goal_cells(reachable, spec)
    xy = spec.centre_of(np.argwhere(~cells))
    d = np.hypot(xy[:, 0] - 1.0, xy[:, 1] - 1.0)
    assert d.max() <= 0.8 + 0.1 and 150 < (~cells).sum() < 260  # ... but not from there
    assert not cells[tuple(spec.cell_of(np.array([[1.0, 1.0]]))[0])]


def test_cropped_robot_fields_equal_full_dijkstra() -> None:
    rng = np.random.default_rng(3)
    trav = rng.random((60, 80)) > 0.25
    trav[:, 40] = False  # two components
    starts = {0: np.array([5, 5]), 1: np.array([50, 70]), 2: np.array([30, 10])}
    got = robot_fields(trav, starts, snap_cells=3.0)
    for robot, (r, c) in starts.items():
        off = np.argwhere(trav)
        rr, cc = off[np.argmin(((off - [r, c]) ** 2).sum(1))]  # snapped start
        ref = distance_fields(trav, [(int(rr), int(cc))])[0]
        np.testing.assert_array_equal(got[robot], ref)


def test_inflation_cache_equals_full_inflation() -> None:
    from services.common.planning import inflate
    from services.edge_server.robot_fields import InflationCache

    rng = np.random.default_rng(5)
    cache = InflationCache()
    occ = rng.random((50, 70)) > 0.97
    for _ in range(4):
        np.testing.assert_array_equal(cache(occ, 4), inflate(occ, 4))
        occ = occ | (rng.random(occ.shape) > 0.995)  # grows: incremental path
    occ[:10] = False  # shrinks: full recompute
    np.testing.assert_array_equal(cache(occ, 4), inflate(occ, 4))


def test_lazy_fields_reach_where_finite() -> None:
    from services.edge_server.robot_fields import RobotFields

    rng = np.random.default_rng(4)
    trav = rng.random((40, 40)) > 0.3
    fields = RobotFields(trav, {0: np.array([3, 3]), 1: np.array([100, 100])}, 3.0)
    cells = np.argwhere(np.ones_like(trav))
    np.testing.assert_array_equal(fields.reaches(0, cells),
                                  np.isfinite(fields[0][cells[:, 0], cells[:, 1]]))
    assert not fields.reaches(1, cells).any() and np.isinf(fields[1]).all()


def test_a_robot_on_a_small_island_plans_from_the_mainland_next_to_it() -> None:
    from services.edge_server.robot_fields import RobotFields

    trav = np.zeros((40, 40), bool)
    trav[:, 10:] = True  # the mainland
    trav[20, 5] = True  # the robot's one-cell island: inflated obstacles close it in
    start = {0: np.array([20, 5])}
    far_side = np.array([[0, 39]])
    kept = RobotFields(trav, start, 8.0)
    assert kept.starts[0] == (20, 5) and not kept.reaches(0, far_side).any()
    moved = RobotFields(trav, start, 8.0, island_cells=100)
    assert moved.starts[0] == (20, 10) and moved.reaches(0, far_side).all()
    assert np.isfinite(moved[0][0, 39])
    beyond = RobotFields(trav, start, 3.0, island_cells=100)  # the mainland out of reach
    assert beyond.starts[0] == (20, 5) and not beyond.reaches(0, far_side).any()


def tail_planner(config: EdgeConfig, voxels: int) -> EdgePlanner:
    """A planner whose merged map holds `voxels` voxels."""
    planner = EdgePlanner(config, tick_s=0.1)
    idx = [[i, j, 1] for i in range(voxels // 10) for j in range(10)]
    planner.on_submap(make_submap(0, 0, 0, 1, np.eye(4), voxel_centres(idx)))
    planner.merged.update(planner.store)
    assert len(planner.merged) == voxels
    return planner


def side_by_side(sizes: list[int], weak: list[bool]) -> FrontierSet:
    """Regions side by side on a 10 × 10 grid, each goal at its own reachable cell."""
    n = len(sizes)
    rc = np.array([[5, 2 * i + 1] for i in range(n)])
    return FrontierSet(labels=np.zeros((10, 10), np.int32), sizes=np.array(sizes),
                       centroid_xy=rc[:, ::-1] * 0.05, anchor_rc=rc, anchor_xy=rc * 0.05,
                       goal_rc=rc, goal_xy=rc[:, ::-1] * 0.05, weak=np.array(weak))


def test_the_tail_drops_specks_once_the_regions_are_few() -> None:
    reachable = np.ones((10, 10), bool)
    fs = side_by_side([200, 12, 12], [False, False, True])  # a region, a speck, a weak speck
    base = dict(planner="space", space_tail_min_voxels=20)
    # 212 assignable F_u voxels against 1000 in the map: the tail at 0.3, not at 0.2
    kept = tail_planner(EdgeConfig(**base, space_tail_fraction=0.3), 1000)._without_tail_specks(
        fs, reachable, 10)
    assert kept.sizes.tolist() == [200, 12] and kept.weak.tolist() == [False, True]
    early = tail_planner(EdgeConfig(**base, space_tail_fraction=0.2), 1000)
    assert len(early._without_tail_specks(fs, reachable, 10)) == 3
    off = tail_planner(EdgeConfig(planner="space", space_tail_fraction=0.3,
                                  space_tail_min_voxels=0), 1000)
    assert len(off._without_tail_specks(fs, reachable, 10)) == 3
    # a region no robot reaches does not count towards the tail's share
    far = reachable.copy()
    far[5, 1] = False
    kept = tail_planner(EdgeConfig(**base, space_tail_fraction=0.02), 1000)._without_tail_specks(
        fs, far, 10)
    assert kept.sizes.tolist() == [200, 12]


def test_the_tail_can_leave_weak_regions_to_the_end() -> None:
    """`space_tail_weak=False`: in the tail only F_u regions are goals (completion waits for
    them alone); before the tail, weak regions stay."""
    reachable = np.ones((10, 10), bool)
    fs = side_by_side([200, 12, 40], [False, False, True])  # a region, a speck, a weak region
    base = dict(planner="space", space_tail_min_voxels=20, space_tail_weak=False)
    tail = tail_planner(EdgeConfig(**base, space_tail_fraction=0.3), 1000)
    kept = tail._without_tail_specks(fs, reachable, 10)
    assert kept.sizes.tolist() == [200] and kept.weak.tolist() == [False]
    early = tail_planner(EdgeConfig(**base, space_tail_fraction=0.1), 1000)
    assert len(early._without_tail_specks(fs, reachable, 10)) == 3


def test_the_size_factor_waits_for_the_late_regions() -> None:
    """Sizes count once the assignable F_u voxels are down to `space_size_from_fraction` of
    the map: early on every room is a large region and sizes would pull the team apart."""
    reachable = np.ones((10, 10), bool)
    fs = side_by_side([150, 12, 40], [False, False, True])  # 162 F_u voxels of 1000
    base = dict(planner="space", space_size_exponent=0.5)
    late = tail_planner(EdgeConfig(**base, space_size_from_fraction=0.2), 1000)
    assert late._scorer_for(fs, reachable, 10) is late.scorer
    early = tail_planner(EdgeConfig(**base, space_size_from_fraction=0.1), 1000)
    chosen = early._scorer_for(fs, reachable, 10)
    assert chosen is early.early_scorer and chosen is not early.scorer
    assert early.early_scorer.config.space_size_exponent == 0.0  # type: ignore[attr-defined]
    always = tail_planner(EdgeConfig(**base, space_size_from_fraction=1.0), 1000)
    assert always._scorer_for(fs, reachable, 10) is always.scorer is always.early_scorer


def test_a_plan_that_stands_for_skipped_edge_ticks_counts_them() -> None:
    config = EdgeConfig(complete_after_plans=4, complete_warmup_s=0.0,
                        complete_min_known_cells=1)
    every_tick, every_other = CompletionJudge(config, 0.1), CompletionJudge(config, 0.1)
    assert [every_tick.update(10 * k, 0, 100) for k in range(1, 5)] == [False] * 3 + [True]
    # plans at edge ticks 1, 2 and 4: the last stands for 3 and 4, so the same tick completes
    assert not every_other.update(10, 0, 100)
    assert not every_other.update(20, 0, 100)
    assert every_other.update(40, 0, 100, edge_ticks=2)
    assert every_other.complete_tick == every_tick.complete_tick == 40
