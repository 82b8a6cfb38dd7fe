"""Edge server: frontiers, assignment, blacklist, hysteresis and completion."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from schemas.messages import GoalStatus, Pose2D, RobotPose
from services.common.grid import GridSpec
from services.edge_server.completion import CompletionJudge
from services.edge_server.config import EdgeConfig
from services.edge_server.frontiers import (
    GoalTransform,
    _anchors,
    detect_frontiers,
    frontier_cells,
)
from services.edge_server.planner import EdgePlanner
from tests.test_edge_map import make_submap, voxel_centres

V = 0.05


def room(closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """A 60×60 grid: free square rows/cols 10..39, optionally walled in."""
    free = np.zeros((60, 60), bool)
    free[10:40, 10:40] = True
    occupied = np.zeros_like(free)
    if closed:
        occupied[9:41, 9:41] = True
        occupied[10:40, 10:40] = False
    return free, occupied


def test_frontiers_at_the_boundary_and_none_when_closed() -> None:
    spec = GridSpec(0.0, 0.0, V, 60, 60)
    free, occupied = room(closed=False)
    mask = frontier_cells(free, free | occupied)
    assert mask.sum() == 4 * 30 - 4
    fs = detect_frontiers(free, free | occupied, free, spec, EdgeConfig())
    assert len(fs) == 1 and fs.sizes[0] == 116
    r, c = fs.goal_rc[0]
    assert free[r, c]  # goal f′ is an allowed cell
    free, occupied = room(closed=True)
    assert len(detect_frontiers(free, free | occupied, free, spec, EdgeConfig())) == 0


def test_anchor_is_the_cell_nearest_the_centroid_first_in_row_order_on_a_tie() -> None:
    """Each cluster's anchor is what a stable sort by (cluster, squared distance to its
    centroid) puts first; symmetric clusters tie."""
    rng = np.random.default_rng(8)
    for _ in range(20):
        labels = rng.integers(0, 5, (30, 40)).astype(np.int32)
        labels[rng.random(labels.shape) < 0.5] = 0
        labels[10:13, 10:13] = 5  # a 3×3 square: its centre is the unique nearest
        labels[20, 5], labels[20, 7] = 6, 6  # two cells equally near their centroid
        n = 6
        centroid, anchor = _anchors(labels, n)
        rc = np.argwhere(labels > 0)
        lab = labels[rc[:, 0], rc[:, 1]] - 1
        d2 = ((rc - centroid[lab]) ** 2).sum(axis=1)
        order = np.lexsort((d2, lab))
        first = np.ones(order.size, bool)
        first[1:] = lab[order][1:] != lab[order][:-1]
        assert np.array_equal(anchor, rc[order[first]])
        assert tuple(anchor[4]) == (11, 11) and tuple(anchor[5]) == (20, 5)


def test_nearest_goal_lookup_is_scipys_feature_transform_where_it_is_close_enough() -> None:
    """`GoalTransform.nearest` answers what the whole grid's EDT with indices answers at the
    asked cells (ties included: scipy keeps the smallest column, then row) wherever the
    nearest allowed cell lies within the asked distance, and inf beyond it."""
    rng = np.random.default_rng(3)
    ties = 0
    for trial in range(200):
        shape = tuple(rng.integers(5, 70, 2))
        goal_ok = rng.random(shape) < rng.choice([0.002, 0.02, 0.2, 0.6])
        if trial % 10 == 0:
            goal_ok[:] = False
            goal_ok[rng.integers(0, shape[0]), rng.integers(0, shape[1])] = True
        if not goal_ok.any():
            continue
        dist, idx = ndimage.distance_transform_edt(~goal_ok, return_indices=True)
        rc = np.stack([rng.integers(0, shape[0], 60), rng.integers(0, shape[1], 60)], 1)
        max_cells = float(rng.choice([1.5, 7.0, 20.0, 30.0]))
        got_dist, got_rc = GoalTransform(goal_ok).nearest(rc, max_cells)
        near = dist[rc[:, 0], rc[:, 1]] <= max_cells
        assert np.array_equal(got_dist[near], dist[rc[:, 0], rc[:, 1]][near])
        assert np.array_equal(got_rc[near], np.stack([idx[0], idx[1]], -1)[rc[near, 0],
                                                                           rc[near, 1]])
        assert (got_dist[~near] > max_cells).all()
        feats = np.argwhere(goal_ok)
        for r, c in rc[near]:
            d2 = ((feats - [r, c]) ** 2).sum(1)
            ties += int((d2 == d2.min()).sum() > 1)
    assert ties > 100  # the tie rule was exercised

def test_tiny_clusters_dropped_and_goals_only_on_allowed_cells() -> None:
    spec = GridSpec(0.0, 0.0, V, 60, 60)
    free, occupied = room(closed=True)
    occupied[9, 20:23] = False  # a 3-cell gap: frontier of 3 cells, under the minimum
    free[9, 20:23] = True
    known = free | occupied
    assert len(detect_frontiers(free, known, free, spec, EdgeConfig(frontier_min_cells=5))) == 0
    assert len(detect_frontiers(free, known, free, spec, EdgeConfig(frontier_min_cells=3))) == 1
    goal_ok = np.zeros_like(free)
    goal_ok[30:40, 30:40] = True  # only far from the gap: goal offset too big → dropped
    assert len(detect_frontiers(free, known, goal_ok, spec, EdgeConfig(frontier_min_cells=3))) == 0


def corridor_planner(config: EdgeConfig | None = None) -> EdgePlanner:
    """A 4 m × 0.5 m corridor along x at y 1.0..1.5, walled along y, open (unknown) at both ends."""
    planner = EdgePlanner(config or EdgeConfig(planner="nearest"), tick_s=0.1)
    cols, rows = np.meshgrid(np.arange(0, 80), np.arange(20, 30))
    free = np.stack([cols.ravel(), rows.ravel()], axis=1)
    walls = [[i, j, k] for i in range(-2, 82) for j in (18, 19, 30, 31) for k in (2, 4)]
    planner.on_submap(make_submap(0, 0, 0, 1, np.eye(4), voxel_centres(walls), free))
    return planner


def pose(robot: int, x: float, y: float = 1.25, tick: int = 1) -> RobotPose:
    return RobotPose(robot_id=robot, tick=tick, stamp_ns=0, pose_world=Pose2D(x=x, y=y, yaw=0.0))


def test_no_frontier_assigned_twice_and_goals_reachable() -> None:
    planner = corridor_planner()
    for robot, x in ((0, 0.5), (1, 0.6), (2, 0.7)):
        planner.on_pose(pose(robot, x))
    out = planner.plan(10)
    assert len(out.frontiers.frontiers) == 2
    assigned = out.frontiers.assigned
    # Robot 0 takes the near end; robot 2 is nearer the far end than robot 1; 1 gets nothing.
    assert sorted(assigned) == [0, 2] and len(set(assigned.values())) == 2
    goals = {g.robot_id: g for g in out.goals}
    assert goals[0].x < 1.0 and goals[2].x > 3.0
    snap = planner.last_grid
    assert snap is not None
    for g in goals.values():
        r, c = snap.spec.cell_of(np.array([[g.x, g.y]]))[0]
        assert snap.free[r, c]
    assert out.grid is not None and out.grid.cells.shape == snap.spec.shape


def test_hysteresis_keeps_goals_and_blacklist_sets_aside() -> None:
    planner = corridor_planner(EdgeConfig(planner="nearest", blacklist_ticks=50))
    planner.on_pose(pose(0, 1.5))
    first = planner.plan(10).goals
    assert len(first) == 1 and first[0].x < 1.0
    planner.on_pose(pose(0, 2.6))  # now nearer the right end: the goal is kept anyway
    again = planner.plan(20)
    assert again.goals == [] and again.frontiers.assigned == {0: 0}
    planner.on_goal_status(GoalStatus(robot_id=0, tick=21, goal_id=first[0].goal_id,
                                      status="unreachable", reason="test"))
    swapped = planner.plan(30)
    assert len(swapped.goals) == 1 and swapped.goals[0].x > 3.0  # left end set aside
    planner.on_goal_status(GoalStatus(robot_id=0, tick=31, goal_id=swapped.goals[0].goal_id,
                                      status="invalid"))
    none_left = planner.plan(40)
    assert none_left.goals == [] and none_left.frontiers.assigned == {}
    back = planner.plan(80)  # the first blacklist entry expired at tick 71
    assert len(back.goals) == 1 and back.goals[0].x < 1.0


def test_dead_agent_goal_freed() -> None:
    planner = corridor_planner()
    planner.on_pose(pose(0, 0.5))
    planner.on_pose(pose(1, 0.6))
    planner.plan(10)
    planner.on_agent(0, alive=False)
    out = planner.plan(20)
    assert list(out.frontiers.assigned) == [1]


def test_completion_logic() -> None:
    judge = CompletionJudge(EdgeConfig(complete_after_plans=3, complete_warmup_s=3.5,
                                       complete_min_known_cells=10), tick_s=0.1)
    assert not any(judge.update(t, 0, 100) for t in (10, 20, 30))  # before the warm-up
    assert judge.update(40, 0, 100)  # fourth empty plan, past 3.5 s
    assert judge.update(50, 5, 100) and judge.complete_tick == 40  # sticky
    judge = CompletionJudge(EdgeConfig(complete_min_known_cells=10), tick_s=0.1)
    assert not any(judge.update(t, 0, 5) for t in range(40, 100, 10))  # trivial map
    judge = CompletionJudge(EdgeConfig(), tick_s=0.1)
    assert not judge.update(40, 0, 1000) and not judge.update(50, 1, 1000)
    assert not judge.update(60, 0, 1000) and not judge.update(70, 0, 1000)
    assert judge.update(80, 0, 1000)


def test_closed_room_completes_and_open_one_does_not() -> None:
    planner = EdgePlanner(EdgeConfig(planner="nearest"), tick_s=0.1)
    cols, rows = np.meshgrid(np.arange(0, 40), np.arange(0, 40))
    free = np.stack([cols.ravel(), rows.ravel()], axis=1)
    walls = [[i, j, 3] for i in range(-1, 41) for j in range(-1, 41)
             if i in (-1, 40) or j in (-1, 40)]
    planner.on_submap(make_submap(0, 0, 0, 1, np.eye(4), voxel_centres(walls), free))
    planner.on_pose(pose(0, 1.0, 1.0))
    verdicts = [planner.plan(t).frontiers.complete for t in range(10, 60, 10)]
    assert verdicts == [False, False, True, True, True]
    open_room = corridor_planner()
    open_room.on_pose(pose(0, 1.0))
    assert not any(open_room.plan(t).frontiers.complete for t in range(10, 80, 10))


def test_space_falls_back_to_grid_frontiers_instead_of_completing() -> None:
    """Free floor (its whole rim unknown) but no 3D region (no voxels): without the fallback
    the SPACE planner assigns nothing and completes; with it the grid's frontier is a goal.
    (The endgame's unseen floor would offer the floor itself: off here, see
    test_edge_unseen_floor.py.)"""
    def planner_for(fallback: bool) -> EdgePlanner:
        p = EdgePlanner(EdgeConfig(planner="space", space_grid_fallback=fallback,
                                   floor_unseen_min_m2=0.0), tick_s=0.1)
        cols, rows = np.meshgrid(np.arange(0, 80), np.arange(20, 30))
        free = np.stack([cols.ravel(), rows.ravel()], axis=1)
        p.on_submap(make_submap(0, 0, 0, 1, np.eye(4), np.zeros((0, 3)), free))
        p.on_pose(pose(0, 0.5))
        return p

    plain = planner_for(False)
    outs = [plain.plan(10 * k) for k in range(1, 5)]
    assert not outs[0].goals and not outs[0].frontiers.frontiers
    assert outs[-1].frontiers.complete
    fallback = planner_for(True)
    out = fallback.plan(10)
    assert [(g.robot_id, g.frontier_class) for g in out.goals] == [(0, "unexplored")]
    assert [f.size for f in out.frontiers.frontiers] == [176]  # the rim of the free floor
    assert not any(fallback.plan(10 * k).frontiers.complete for k in range(2, 5))


def test_grid_fallback_ignores_frontiers_shorter_than_its_minimum() -> None:
    p = EdgePlanner(EdgeConfig(planner="space", space_grid_fallback=True,
                               space_grid_fallback_min_cells=200, floor_unseen_min_m2=0.0),
                    tick_s=0.1)
    cols, rows = np.meshgrid(np.arange(0, 80), np.arange(20, 30))
    p.on_submap(make_submap(0, 0, 0, 1, np.eye(4), np.zeros((0, 3)),
                            np.stack([cols.ravel(), rows.ravel()], axis=1)))
    p.on_pose(pose(0, 0.5))
    assert not p.plan(10).goals  # the 176-cell rim is under 200


def test_grid_goals_join_the_regions_worth_the_unknown_floor_they_see() -> None:
    """With `space_grid_goals_min_cells` the grid's long frontier is a goal even with the
    fallback off, worth the unknown floor in sight of it; below the minimum it is not."""
    def planner_for(min_cells: int) -> EdgePlanner:
        p = EdgePlanner(EdgeConfig(planner="space", space_grid_fallback=False,
                                   floor_unseen_min_m2=0.0, space_grid_goals_min_cells=min_cells,
                                   space_view_gain_per_m2=0.05), tick_s=0.1)
        cols, rows = np.meshgrid(np.arange(0, 80), np.arange(20, 30))
        free = np.stack([cols.ravel(), rows.ravel()], axis=1)
        p.on_submap(make_submap(0, 0, 0, 1, np.eye(4), np.zeros((0, 3)), free))
        p.on_pose(pose(0, 0.5))
        return p

    out = planner_for(40).plan(10)
    assert [(g.robot_id, g.frontier_class) for g in out.goals] == [(0, "unexplored")]
    assert [f.size for f in out.frontiers.frontiers] == [176]
    assert not planner_for(200).plan(10).goals
