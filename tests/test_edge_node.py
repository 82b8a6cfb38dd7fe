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
    GridRequest,
    OccupancyGrid,
)
from services.common.bus import Inbound, Presence
from services.config import SpacemapConfig
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
