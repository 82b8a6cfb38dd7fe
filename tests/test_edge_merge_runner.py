"""The merger's update in a worker process (merge_runner.py): the same poses, the same P*,
the same plans (the planner surveys the map while the worker updates, and again after a
correction)."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from schemas import encode
from schemas.messages import Pose2D, RobotPose
from services.common.geometry import T_from_xyyaw, xyyaw_from_T
from services.edge_server.config import EdgeConfig
from services.edge_server.merge_runner import LocalMerges, WorkerMerges
from services.edge_server.merger import MergerParams, merger_params
from services.edge_server.node import merges_for
from services.edge_server.planner import EdgePlanner
from tests.test_edge_map import make_submap
from tests.test_edge_merger import V, build_store


def _messages() -> list:
    """The submap messages of two robots touring one room, robot 1's drift adding up from
    submap to submap (test_edge_merger: the default merger corrects it); each submap's free
    cells are a disk around where it began, so the grid has frontiers and robots goals."""
    drift = T_from_xyyaw(0.03 * np.cos(0.5), 0.03 * np.sin(0.5), np.deg2rad(0.3))
    store, _ = build_store(drift, growing=True)
    r = int(1.2 / V)
    rc = np.argwhere(np.ones((2 * r + 1,) * 2, bool)) - r
    free = rc[np.hypot(rc[:, 0], rc[:, 1]) <= r]
    return [make_submap(sm.robot_id, sm.submap_id, sm.submap_id, 10 * sm.submap_id + 1,
                        sm.T_reported, sm.points.astype(np.float64), free)
            for sm in sorted(store.ordered(), key=lambda s: (s.submap_id, s.robot_id))]


def _planners(config: EdgeConfig) -> tuple[EdgePlanner, EdgePlanner]:
    params = MergerParams()  # the merger's own defaults correct this scene's drift
    return (EdgePlanner(config, 0.1, LocalMerges(config.voxel_m, params)),
            EdgePlanner(config, 0.1, WorkerMerges(config.voxel_m, params)))


@pytest.mark.parametrize("planner", ["space", "rrt"])
def test_a_worker_plans_what_the_planner_would_in_its_own_thread(planner: str) -> None:
    config = EdgeConfig(planner=planner)
    local, worker = _planners(config)
    messages = _messages()
    corrected = goals = 0
    try:
        for plan in range(14):
            for msg in messages[2 * plan: 2 * plan + 2]:  # two submaps between plans
                x, y, yaw = xyyaw_from_T(msg.T_world_submap)  # the robot where it began it
                pose = RobotPose(robot_id=msg.robot_id, tick=msg.tick, stamp_ns=0,
                                 pose_world=Pose2D(x=x, y=y, yaw=yaw))
                for planner in (local, worker):
                    planner.on_submap(msg)
                    planner.on_pose(pose)
            a, b = local.plan(10 * plan), worker.plan(10 * plan)
            corrected += len(a.corrections)
            assert [encode(c) for c in a.corrections] == [encode(c) for c in b.corrections]
            assert a.grid is not None and b.grid is not None
            assert encode(a.grid) == encode(b.grid)
            assert encode(a.frontiers) == encode(b.frontiers)
            assert [encode(g) for g in a.goals] == [encode(g) for g in b.goals]
            goals += len(a.goals)
            for name in ("keys", "colors", "robot_ids", "points_world"):
                assert np.array_equal(getattr(local.merged, name), getattr(worker.merged, name))
            pa, pb = local._point_frontiers(), worker._point_frontiers()
            assert np.array_equal(pa.rho, pb.rho) and np.array_equal(pa.var_m2, pb.var_m2)
            for key, sm in local.store.submaps.items():
                assert np.array_equal(sm.T_world_submap, worker.store.submaps[key].T_world_submap)
        assert corrected > 0, "the scene must exercise corrections"
        assert goals > 0, "... and plans"
        assert worker.merges.summary() == local.merges.summary()
    finally:
        worker.close()


class ScriptedMerges:
    """A runner without a merger: its first update moves one submap to a given pose."""

    def __init__(self, concurrent: bool, key: tuple[int, int], T: np.ndarray) -> None:
        self.concurrent = concurrent
        self.fix: tuple | None = (key, T)

    def submap(self, msg: object) -> None:
        pass

    def start(self, store: object) -> None:
        pass

    def finish(self, store: object) -> tuple[dict, dict]:
        if self.fix is None:
            return {}, {}
        (key, T), self.fix = self.fix, None
        return {key: T}, {key[0]: ([key[1]], T[None])}

    def summary(self) -> str:
        return ""

    def close(self) -> None:
        pass


def test_a_survey_made_again_after_a_correction_forgets_the_bounds_it_grew() -> None:
    """Robot 1's submap reported 8 m off and corrected home: the grid a concurrent runner's
    plan publishes must not keep the bounds its first survey grew to reach the report."""
    config = EdgeConfig()
    home, far = T_from_xyyaw(1.0, 2.0, 0.0), T_from_xyyaw(9.0, 2.0, 0.0)
    wall = np.array([[1.0, y, z] for y in np.arange(-0.5, 0.5, V) for z in (0.2, 0.4)])
    free = np.argwhere(np.ones((20, 20), bool)) - 10
    grids = []
    for concurrent in (False, True):
        planner = EdgePlanner(config, 0.1, ScriptedMerges(concurrent, (1, 0), home))
        for robot, T in ((0, home), (1, far)):
            planner.on_submap(make_submap(robot, 0, 0, 1, T, wall, free))
            planner.on_pose(RobotPose(robot_id=robot, tick=1, stamp_ns=0,
                                      pose_world=Pose2D(x=1.0, y=2.0, yaw=0.0)))
        out = planner.plan(10)
        assert out.corrections and out.grid is not None
        grids.append(encode(out.grid))
    assert grids[0] == grids[1]


def test_the_node_starts_a_worker_only_when_merging_with_one() -> None:
    assert merges_for(EdgeConfig(merge=False)) is None
    assert merges_for(EdgeConfig(merge_worker=False)) is None
    runner = merges_for(EdgeConfig())
    assert isinstance(runner, WorkerMerges)
    runner.close()
    assert not runner._proc.is_alive()


def test_a_failing_or_dead_worker_raises_in_the_plan() -> None:
    config = EdgeConfig()
    runner = WorkerMerges(V, merger_params(config))
    try:
        runner.submap("not a submap")  # the worker's store cannot apply it
        with pytest.raises(RuntimeError, match="failed"):
            runner.finish(EdgePlanner(config, 0.1).store)
        runner._proc.kill()
        runner._proc.join(5)
        with pytest.raises(RuntimeError, match="died"):
            runner.finish(EdgePlanner(config, 0.1).store)
    finally:
        runner.close()


def test_the_worker_outlives_signals_to_its_group_and_ends_with_the_edge() -> None:
    """Ctrl-C reaches the whole process group: the edge shuts down and asks its worker for
    the closing summary, so the worker must not die of the signal; it ends when the edge
    closes it, or when the edge's end of the pipe closes."""
    runner = WorkerMerges(V, MergerParams())
    try:
        assert runner.summary()  # up and answering
        for sig in (signal.SIGINT, signal.SIGTERM):
            os.kill(runner._proc.pid, sig)
        assert runner.summary()
        runner._conn.close()  # as when the edge exits without closing it
        runner._proc.join(10)
        assert not runner._proc.is_alive()
    finally:
        runner._proc.kill()
