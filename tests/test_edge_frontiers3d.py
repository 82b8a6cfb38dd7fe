"""Bi-variate spatial frontiers (Alg. 1), information gain, importance and the planners."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from services.common.grid import GridSpec
from services.common.voxels import pack
from services.edge_server.config import EdgeConfig
from services.edge_server.frontiers import empty_frontiers
from services.edge_server.frontiers3d import (
    ball_offsets,
    density_variance,
    detect_point_frontiers,
    neg_x_log_x,
)
from services.edge_server.importance import distance_factor, importance, revenue
from services.edge_server.merged_map import MergedMap
from services.edge_server.planner import EdgePlanner
from services.edge_server.spatial_frontiers import detect_spatial_frontiers, near_unknown
from tests.test_edge_map import make_submap, voxel_centres
from tests.test_edge_planning import corridor_planner, pose

V = 0.05


def floor_with_hole_and_noisy_patch() -> np.ndarray:
    """(N, 3) lattice indices: a 4 × 4 m floor with a round hole and a noisy (scattered) patch."""
    rng = np.random.default_rng(3)
    g = np.mgrid[0:80, 0:80].reshape(2, -1).T
    idx = np.c_[g, np.zeros(len(g), int)]
    idx = idx[np.hypot(idx[:, 0] - 20, idx[:, 1] - 20) >= 8]  # hole centred at (1.0, 1.0) m
    patch = (idx[:, 0] >= 50) & (idx[:, 0] < 70) & (idx[:, 1] >= 50) & (idx[:, 1] < 70)
    idx[patch, 2] += rng.integers(-2, 3, int(patch.sum()))  # centred at (3.0, 3.0) m
    return np.unique(idx, axis=0)


def test_density_and_variance_exact_against_kdtree() -> None:
    idx = floor_with_hole_and_noisy_patch()
    rho, var = density_variance(idx, 3.0)
    tree = cKDTree(idx.astype(float))
    for i in range(0, len(idx), 211):
        nb = idx[tree.query_ball_point(idx[i].astype(float), 3.0 + 1e-9)].astype(float)
        assert rho[i] == len(nb)
        assert var[i] == pytest.approx(((nb - nb.mean(0)) ** 2).sum(1).mean(), abs=1e-6)
    assert len(ball_offsets(3.0)) == 123


def test_hole_gives_unexplored_and_noisy_patch_gives_weak() -> None:
    cfg = EdgeConfig()
    pf = detect_point_frontiers(voxel_centres(floor_with_hole_and_noisy_patch()), V,
                                cfg.search_radius_m, cfg.density_threshold,
                                cfg.variance_threshold_m2)
    xy = pf.points_world[:, :2]
    rim = np.abs(np.hypot(xy[:, 0] - 1.025, xy[:, 1] - 1.025) - 0.42) < 0.06
    interior = (np.abs(xy - [2.0, 1.0]).max(axis=1) < 0.3)
    patch = np.abs(xy - [3.0, 3.0]).max(axis=1) < 0.35
    assert pf.unexplored[rim].mean() > 0.9 and not pf.unexplored[interior].any()
    assert not pf.weak[interior].any() and not pf.weak[rim].any()
    assert pf.weak[patch].mean() > 0.2
    # regions: the rim becomes one F_u region, the patch F_w; f′ on allowed cells
    spec = GridSpec(0.0, 0.0, V, 80, 80)
    known = np.ones(spec.shape, bool)
    known[18:23, 18:23] = False  # the hole is unknown floor
    merged = MergedMap(V)
    merged.keys = pack(pf.indices)  # P* as the merged map holds it: sorted voxel keys
    fs, _ = detect_spatial_frontiers(merged, known, known.copy(), spec, cfg)
    assert fs.weak is not None and fs.gain is not None
    cu = fs.centroid_xy[~fs.weak]
    assert len(cu) >= 1 and np.linalg.norm(cu - 1.0, axis=1).min() < 0.15
    cw = fs.centroid_xy[fs.weak]
    assert len(cw) >= 1 and np.linalg.norm(cw - 3.0, axis=1).min() < 0.2
    assert ((fs.gain > 0) & (fs.gain <= 1 / np.e + 1e-9)).all()
    assert known[fs.goal_rc[:, 0], fs.goal_rc[:, 1]].all()
    # F_u far from unknown space (the floor's outer border here is all known) is not kept
    assert np.linalg.norm(cu - [0.0, 0.0], axis=1).min() > 0.5


def test_entropy_is_zero_at_the_ends_and_peaks_at_one_over_e() -> None:
    x = np.array([0.0, 1 / np.e, 1.0, 2.0])
    assert np.allclose(neg_x_log_x(x), [0.0, 1 / np.e, 0.0, 0.0])


def test_importance_shifts_from_unexplored_to_weak_over_time() -> None:
    robots = np.array([[0.0, 0.0], [1.0, 0.0]])
    centroids = np.array([[3.0, 0.0], [0.5, 3.0]])
    weak = np.array([False, True])
    assert distance_factor(robots, centroids, weak) == pytest.approx(2.5 / 3.0)
    early = importance(0.0, robots, centroids, weak, lam=0.01, xi=0.0)
    late = importance(300.0, robots, centroids, weak, lam=0.01, xi=0.0)
    assert early[0] > late[0] and early[1] < late[1]
    assert late[1] > late[0]
    path = np.array([[2.0, 4.0]])
    gain = np.array([0.3, 0.3])
    assert np.argmax(revenue(early, gain, path, 1.0, 0.5)[0]) == 0
    assert np.argmax(revenue(late, gain, path, 1.0, 0.5)[0]) == 1
    assert revenue(early, gain, np.array([[np.inf, 1.0]]), 1.0, 0.5)[0, 0] == -np.inf


def open_room_planner(planner: str) -> EdgePlanner:
    """A 3 × 2 m room with floor and walls, open on its +x side (a doorway into unknown)."""
    p = EdgePlanner(EdgeConfig(planner=planner), tick_s=0.1)
    g = np.mgrid[0:60, 0:40].reshape(2, -1).T
    floor = np.c_[g, np.zeros(len(g), int)]
    walls = [[i, j, k] for i in range(-2, 60) for j in (-2, -1, 40, 41) for k in range(1, 12)]
    walls += [[i, j, k] for i in (-2, -1) for j in range(-2, 42) for k in range(1, 12)]
    pts = voxel_centres(np.concatenate([floor, np.array(walls)]))
    p.on_submap(make_submap(0, 0, 0, 1, np.eye(4), pts, g))
    return p


@pytest.mark.parametrize("planner", ["space", "space-paper", "nearest", "utility", "rrt"])
def test_planners_selectable_and_never_share_a_frontier(planner: str) -> None:
    p = open_room_planner(planner)
    assert p.scorer.name == ("utility" if planner == "rrt" else planner)
    for robot, x in ((0, 0.5), (1, 1.0), (2, 1.5)):
        p.on_pose(pose(robot, x, 1.0))
    out = p.plan(10)
    assert out.frontiers.frontiers, planner
    assigned = out.frontiers.assigned
    assert assigned and len(set(assigned.values())) == len(assigned)
    for g in out.goals:
        assert g.x > 1.5  # the open side
    again = open_room_planner(planner)
    for robot, x in ((0, 0.5), (1, 1.0), (2, 1.5)):
        again.on_pose(pose(robot, x, 1.0))
    repeat = again.plan(10)  # deterministic (the RRT is seeded)
    assert repeat.frontiers == out.frontiers and repeat.goals == out.goals


def test_space_frontiers_report_class_gain_and_importance() -> None:
    p = open_room_planner("space")
    p.on_pose(pose(0, 0.5, 1.0))
    fr = p.plan(10).frontiers.frontiers
    assert {f.frontier_class for f in fr} <= {"unexplored", "weak"}
    assert any(f.frontier_class == "unexplored" for f in fr)
    assert all(0 <= f.importance <= 1 and f.gain >= 0 for f in fr)


def test_dead_agents_frontier_goes_to_another_robot() -> None:
    p = corridor_planner()
    for robot, x in ((0, 0.5), (1, 0.6), (2, 0.7)):
        p.on_pose(pose(robot, x))
    first = p.plan(10)
    assert sorted(first.frontiers.assigned) == [0, 2]  # two frontiers: robot 1 waits
    goal0 = {g.robot_id: g for g in first.goals}[0]
    p.on_agent(0, alive=False)
    out = p.plan(20)
    goal1 = {g.robot_id: g for g in out.goals}[1]
    assert 0 not in out.frontiers.assigned
    assert (goal1.x, goal1.y) == (goal0.x, goal0.y)  # robot 1 takes robot 0's frontier
    p.on_agent(0, alive=True)  # restarted: it plans again
    assert 0 in p.active_robots()


def test_restart_epoch_and_resend_are_accepted() -> None:
    p = corridor_planner()
    store = p.store
    n = store.submaps[(0, 0)].keys.size
    resend = make_submap(0, 0, 0, 5, np.eye(4), voxel_centres([[1, 18, 2]]))
    store.apply(resend)
    store.apply(resend)  # a resend of the same data: idempotent, no gap
    assert store.submaps[(0, 0)].keys.size == n and store.seq_gaps[0] == 0
    restarted = make_submap(0, 7, 0, 50, np.eye(4), voxel_centres([[5, 25, 2]]))
    restarted = restarted.model_copy(update={"epoch": 50})
    store.apply(restarted)  # new epoch, seq starts at 0 again: accepted without a gap
    assert (0, 7) in store.submaps and store.seq_gaps[0] == 0


def test_near_unknown_on_a_window_equals_the_whole_grid_transform() -> None:
    """Regions within `max_m` of unknown space, from the k-d tree of the unknown cells that
    border known ones in a window around them, as from the whole grid's transform (ties at
    `max_m` included); and none when no unknown cell is within reach."""
    rng = np.random.default_rng(11)
    spec = GridSpec(0.0, 0.0, V, 80, 120)
    seen = set()
    for trial in range(150):
        known = np.ones(spec.shape, bool)
        for _ in range(int(rng.integers(0, 4))):  # unknown patches anywhere
            r, c = rng.integers(0, 80), rng.integers(0, 120)
            known[r:r + int(rng.integers(1, 8)), c:c + int(rng.integers(1, 8))] = False
        if trial % 3 == 0:  # scattered unknown cells
            known &= rng.random(spec.shape) > 0.002
        max_m = float(rng.choice([0.15, 0.25, 0.5, 1.0]))
        if trial % 5 == 0:  # a large unknown area: regions deep inside it are at distance 0
            known[20:70, 30:100] = False
        labels = np.zeros(spec.shape, np.int32)
        n = int(rng.integers(1, 6))
        for lab in range(1, n + 1):
            r, c = rng.integers(0, 75), rng.integers(0, 115)
            labels[r:r + 4, c:c + 4] = lab
        fs = replace(empty_frontiers(spec.shape), labels=labels, sizes=np.ones(n, np.int64))
        dist = ndimage.distance_transform_edt(known) * V if not known.all() else None
        want = (np.zeros(n, bool) if dist is None else
                np.bincount(labels[(labels > 0) & (dist <= max_m)] - 1, minlength=n) > 0)
        got = near_unknown(fs, known, spec, max_m)
        assert np.array_equal(got, want)
        seen.update(got.tolist())
    assert seen == {True, False}
