"""node.handle: publishes a tick's outputs on the robot's keys, CmdVel last (fake bus)."""

from __future__ import annotations

from schemas import Keys
from schemas.messages import Goal, Message, Odometry, Pose2D, RobotPose
from services.common.bus import Inbound
from services.robot_agent.agent import AgentCore
from services.robot_agent.config import AgentConfig
from services.robot_agent.node import finish, handle


class FakeBus:
    def __init__(self) -> None:
        self.keys = Keys("spacemap")
        self.sent: list[tuple[str, Message]] = []
        self.bytes_out: dict[str, int] = {}

    def publish(self, key: str, message: Message) -> int:
        self.sent.append((key, message))
        return 0

    def input_waiting(self) -> bool:
        return False


def test_handle_odometry_publishes_pose_then_cmd_vel_on_own_keys() -> None:
    bus, core, pending = FakeBus(), AgentCore(AgentConfig(), 3, 0.1), []
    other = RobotPose(robot_id=1, tick=0, stamp_ns=0, pose_world=Pose2D(x=1.0, y=0.0, yaw=0.0))
    handle(bus, core, Inbound("spacemap/robot/1/pose", other), 0.1, pending)  # type: ignore[arg-type]
    odom = Odometry(
        robot_id=3,
        tick=5,
        stamp_ns=5,
        pose_odom=Pose2D(x=0.0, y=0.0, yaw=0.0),
        v_mps=0.0,
        omega_radps=0.0,
    )
    handle(bus, core, Inbound("spacemap/robot/3/odom", odom), 0.1, pending)  # type: ignore[arg-type]
    keys = [k for k, _ in bus.sent]
    assert keys == ["spacemap/robot/3/pose", "spacemap/robot/3/cmd_vel"]
    assert bus.sent[-1][1].tick == 5 and 1 in core.teammates
    assert bus.sent[-1][1].omega_radps == 0.0  # still: no frame has anchored its map yet


def test_messages_of_the_same_tick_wait_for_the_next_tick() -> None:
    """A teammate's pose made at tick k races our Odometry(k): it is applied at k + 1 only,
    whichever arrives first, so lockstep runs repeat exactly."""
    bus, core, pending = FakeBus(), AgentCore(AgentConfig(), 3, 0.1), []

    def odom(tick: int) -> Inbound:
        msg = Odometry(
            robot_id=3,
            tick=tick,
            stamp_ns=tick,
            v_mps=0.0,
            omega_radps=0.0,
            pose_odom=Pose2D(x=0.0, y=0.0, yaw=0.0),
        )
        return Inbound("spacemap/robot/3/odom", msg)

    same_tick = RobotPose(robot_id=1, tick=5, stamp_ns=5, pose_world=Pose2D(x=1.0, y=0.0, yaw=0.0))
    handle(bus, core, Inbound("spacemap/robot/1/pose", same_tick), 0.1, pending)  # type: ignore[arg-type]
    handle(bus, core, odom(5), 0.1, pending)  # type: ignore[arg-type]
    assert 1 not in core.teammates and len(pending) == 1
    handle(bus, core, odom(6), 0.1, pending)  # type: ignore[arg-type]
    assert 1 in core.teammates and pending == []


def test_edge_outputs_of_tick_k_apply_at_k_plus_lag_plus_one() -> None:
    """With the edge pipelined by L ticks the sim waits for the edge's tick k only at k + L,
    so a goal stamped k may arrive as late as just before Odometry(k + L + 1)."""
    bus, core, pending = FakeBus(), AgentCore(AgentConfig(), 3, 0.1), []
    goal = Goal(robot_id=3, tick=10, goal_id=7, x=1.0, y=2.0, frontier_class="unexplored",
                revenue=1.0)
    handle(bus, core, Inbound("spacemap/robot/3/goal", goal), 0.1, pending, 3)  # type: ignore[arg-type]
    for tick in range(10, 14):
        handle(bus, core, _odom(tick), 0.1, pending, 3)  # type: ignore[arg-type]
        assert core.nav.goal is None and pending == [goal], tick
    handle(bus, core, _odom(14), 0.1, pending, 3)  # type: ignore[arg-type]
    assert pending == [] and core.nav.goal is not None and core.nav.goal.goal_id == 7


def _odom(tick: int) -> Inbound:
    return Inbound("spacemap/robot/3/odom", Odometry(
        robot_id=3, tick=tick, stamp_ns=tick, v_mps=0.0, omega_radps=0.0,
        pose_odom=Pose2D(x=0.0, y=0.0, yaw=0.0)))


def test_late_submap_follows_cmd_vel_except_just_before_an_edge_tick() -> None:
    """A frame's voxels and the periodic Submap delta may go out after CmdVel(k), but not at
    tick k = E − 1 of an edge tick E: the edge plans E on every message of ticks < E."""
    from tests.test_agent_core import _frame

    bus, core, pending = FakeBus(), AgentCore(AgentConfig(submap_every_ticks=1), 0, 0.1), []
    order = {}
    for tick in range(6):
        core.on_rgbd(_frame(tick, (0.0, 0.0, 0.0)))
        bus.sent.clear()
        handle(bus, core, Inbound("spacemap/robot/0/odom", Odometry(  # type: ignore[arg-type]
            robot_id=0, tick=tick, stamp_ns=tick, v_mps=0.0, omega_radps=0.0,
            pose_odom=Pose2D(x=0.0, y=0.0, yaw=0.0))), 0.1, pending, 0, 5)
        order[tick] = [k.rsplit("/", 1)[-1] for k, _ in bus.sent]
    assert order[3][-2:] == ["cmd_vel", "submap"]  # deferred: tick 4 is no edge tick
    assert order[4][-1] == "cmd_vel" and "submap" in order[4]  # tick 5 is
    assert all(o.count("cmd_vel") == 1 for o in order.values())


def test_an_odometry_tick_goes_ahead_of_mapping_its_input_cut_short() -> None:
    """When Odometry(k + 1) is waiting, the node leaves the camera tick's mapping queued
    (its command is out); the odometry-only tick answers before that mapping is done,
    which is finished once no input waits, before the next frame."""
    from tests.test_agent_core import _frame

    bus, core, pending = FakeBus(), AgentCore(AgentConfig(), 0, 0.1), []
    bus.input_waiting = lambda: True  # type: ignore[method-assign]

    def odom(tick: int) -> Inbound:
        return Inbound("spacemap/robot/0/odom", Odometry(
            robot_id=0, tick=tick, stamp_ns=tick, v_mps=0.0, omega_radps=0.0,
            pose_odom=Pose2D(x=0.0, y=0.0, yaw=0.0)))

    for tick in range(2):
        core.on_rgbd(_frame(tick, (0.0, 0.0, 0.0)))  # frames at ticks 0 and 1
        handle(bus, core, odom(tick), 0.1, pending, 0, 5)  # type: ignore[arg-type]
    assert core.unfinished and core.ran_ahead == 0  # tick 1's frame needed tick 0's map
    handle(bus, core, odom(2), 0.1, pending, 0, 5)  # type: ignore[arg-type]
    assert core.ran_ahead == 1 and core.unfinished  # no frame: tick 2 went ahead
    bus.input_waiting = lambda: False  # type: ignore[method-assign]
    finish(bus, core)
    assert not core.unfinished and core.mapper.current is not None
    assert len(core.mapper.current) > 0
