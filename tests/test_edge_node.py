"""Edge node wiring without zenoh: publish order on an edge tick and the cloud reply."""

from __future__ import annotations

import numpy as np
import pytest

from schemas import DecodeError, Keys, encode
from schemas.messages import (
    Clock,
    CloudRequest,
    EdgeAck,
    Frontiers,
    Goal,
    GoalStatus,
    GridRequest,
    OccupancyGrid,
)
from services.common.bus import Inbound, Presence
from services.config import SpacemapConfig
from services.edge_server.config import EdgeConfig
from services.edge_server.node import EdgeNode
from tests.test_edge_planning import corridor_planner, pose


class FakeBus:
    def __init__(self) -> None:
        self.keys = Keys()
        self.sent: list[tuple[str, object]] = []

    def publish(self, key: str, message: object) -> int:
        self.sent.append((key, message))
        return 0


def clock(tick: int) -> Inbound:
    msg = Clock(tick=tick, stamp_ns=tick * 10**8, dt_ns=10**8, lockstep=True, camera_tick=False)
    return Inbound("spacemap/sim/clock", msg)


def test_edge_tick_publishes_then_acks_last() -> None:
    bus = FakeBus()
    node = EdgeNode(bus, SpacemapConfig())  # type: ignore[arg-type]
    node.planner = corridor_planner()
    node.handle(Inbound("spacemap/robot/0/pose", pose(0, 0.5)))
    node.handle(clock(5))  # not an edge tick
    assert bus.sent == []
    node.handle(clock(10))
    kinds = [type(m) for _, m in bus.sent]
    assert kinds == [OccupancyGrid, Frontiers, Goal, EdgeAck]
    assert bus.sent[-1][1].tick == 10
    assert bus.sent[2][0] == "spacemap/robot/0/goal"
    node.handle(Presence("agent", "0", alive=False))
    assert 0 in node.planner.dead


def test_cloud_reply() -> None:
    node = EdgeNode(FakeBus(), SpacemapConfig())  # type: ignore[arg-type]
    node.planner = corridor_planner()
    node.handle(clock(10))
    cloud = node.serve_cloud(b"")
    assert cloud.points_world.dtype == np.float32 and len(cloud.points_world) > 0
    assert len(cloud.robot_ids) == len(cloud.points_world) and cloud.tick == 10
    assert len(node.serve_cloud(encode(CloudRequest())).points_world) == len(cloud.points_world)
    with pytest.raises(DecodeError):
        node.serve_cloud(b"garbage")


def test_robot_cloud_and_robot_grid_queries() -> None:
    node = EdgeNode(FakeBus(), SpacemapConfig())  # type: ignore[arg-type]
    node.planner = corridor_planner()
    node.handle(Inbound("spacemap/robot/0/pose", pose(0, 0.5)))
    node.handle(clock(10))
    own = node.serve_cloud(encode(CloudRequest(robot_id=0)))
    assert own.robot_id == 0 and len(own.points_world) == len(node.serve_cloud(b"").points_world)
    assert len(node.serve_cloud(encode(CloudRequest(robot_id=3))).points_world) == 0
    grid = node.serve_robot_grid(encode(GridRequest(robot_id=0)))
    merged = node.planner.last_grid
    assert merged is not None and grid.cells.shape == merged.cells.shape
    assert np.array_equal(grid.cells, merged.cells)  # one robot: its grid is the merged grid
    other = node.serve_robot_grid(encode(GridRequest(robot_id=1)))
    assert (other.cells == -1).all()


def test_unplanned_edge_ticks_are_acknowledged_and_a_free_robot_brings_the_plan_back() -> None:
    bus = FakeBus()
    config = SpacemapConfig(edge=EdgeConfig(plan_every_edge_ticks=2))
    node = EdgeNode(bus, config)  # type: ignore[arg-type]
    node.planner = corridor_planner(EdgeConfig(planner="nearest", plan_every_edge_ticks=2))
    node.handle(Inbound("spacemap/robot/0/pose", pose(0, 0.5)))

    def kinds_at(tick: int) -> list[type]:
        bus.sent.clear()
        node.handle(clock(tick))
        assert bus.sent[-1][1] == EdgeAck(tick=tick)
        return [type(m) for _, m in bus.sent]

    # edge tick 1 is not due, but robot 0 holds no goal yet
    assert kinds_at(10) == [OccupancyGrid, Frontiers, Goal, EdgeAck]
    goal = bus.sent[2][1]
    assert kinds_at(20) == [OccupancyGrid, Frontiers, EdgeAck]  # due: planned, goal kept
    assert kinds_at(30) == [EdgeAck]  # not due and every robot holds a goal
    node.handle(Inbound("spacemap/robot/0/goal_status",
                        GoalStatus(robot_id=0, tick=31, goal_id=goal.goal_id, status="reached")))
    assert kinds_at(50) == [OccupancyGrid, Frontiers, Goal, EdgeAck]
    assert node.unplanned == 1
