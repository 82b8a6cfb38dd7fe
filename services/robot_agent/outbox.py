"""What an agent publishes at the end of a tick, in the lockstep handshake's order: RobotPose,
Submap deltas, GoalStatus changes, and CmdVel last (the simulator waits for it, so everything
a teammate or the edge needs of tick k is out before tick k + 1 starts).

Pure: messages built from the tick's results; it keeps the submap sequence counter and what it
last sent of the odometry statistics.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from schemas.messages import CmdVel, GoalStatus, Message, Pose2D, RobotPose, Submap
from services.robot_agent.exploration import LOCAL_GOAL_BASE
from services.robot_agent.local_map import SubmapDelta
from services.robot_agent.navigation import Command, StatusEvent

log = logging.getLogger(__name__)

# teammates keep the last odometry statistics they got: a pose carries them when they changed
# and at least this often (for a teammate that starts late), not at every tick (7 floats of
# a 220-byte pose, 10 times a second)
STATS_REFRESH_TICKS = 50


@dataclass(frozen=True)
class Outgoing:
    """A message to publish on the robot's `topic` key (pose, submap, goal_status, cmd_vel)."""

    topic: str
    message: Message


@dataclass(frozen=True)
class TickResult:
    """What one tick of the agent produced, for its messages."""

    tick: int
    stamp_ns: int
    pose_world: tuple[float, float, float]  # x, y, yaw in the world frame
    state: str  # navigation state
    wall_direction_rad: float | None  # the walls' direction to share (world frame)
    odometry_stats: list[float] | None  # the calibration's own sums, when pooled
    deltas: list[SubmapDelta]
    events: list[StatusEvent]
    cmd: Command


class Outbox:
    """Builds robot `robot_id`'s messages; `seq` counts its Submap messages, without gaps."""

    def __init__(self, robot_id: int, cell_m: float) -> None:
        self.robot_id = robot_id
        self.cell_m = cell_m
        self.seq = 0
        self.stats_sent: tuple[int, list[float]] | None = None  # (tick, odometry stats)

    def stats_to_send(self, stats: list[float] | None, tick: int) -> list[float] | None:
        """`stats` when they changed since they were last sent or STATS_REFRESH_TICKS have
        passed, else None (teammates keep what they have: `OdometryCalibration.receive`)."""
        last = self.stats_sent
        if stats is None or (last is not None and last[1] == stats
                             and tick - last[0] < STATS_REFRESH_TICKS):
            return None
        self.stats_sent = (tick, stats)
        return stats

    def messages(self, result: TickResult, T_world_loc: np.ndarray,
                 epoch: int) -> list[Outgoing]:
        """The tick's messages in handshake order."""
        rid, tick = self.robot_id, result.tick
        x, y, yaw = result.pose_world
        out = [Outgoing("pose", RobotPose(
            robot_id=rid, tick=tick, stamp_ns=result.stamp_ns,
            pose_world=Pose2D(x=x, y=y, yaw=yaw), state=result.state,
            wall_direction_rad=result.wall_direction_rad,
            odometry_stats=self.stats_to_send(result.odometry_stats, tick),
        ))]
        for delta in result.deltas:
            out.append(Outgoing("submap", self.submap(delta, tick, result.stamp_ns, T_world_loc,
                                                      epoch)))
        for ev in result.events:
            if ev.goal_id >= LOCAL_GOAL_BASE:  # the agent's own goal: the edge never knew it
                continue
            log.info("robot %d goal %d: %s %s", rid, ev.goal_id, ev.status, ev.reason)
            out.append(Outgoing("goal_status", GoalStatus(
                robot_id=rid, tick=tick, goal_id=ev.goal_id, status=ev.status, reason=ev.reason,
            )))
        out.append(Outgoing("cmd_vel", CmdVel(
            robot_id=rid, tick=tick, v_mps=result.cmd.v_mps, omega_radps=result.cmd.omega_radps,
        )))
        return out

    def submap(self, delta: SubmapDelta, tick: int, stamp_ns: int, T_world_loc: np.ndarray,
               epoch: int) -> Submap:
        """One Submap message of `delta`, numbered next."""
        msg = Submap(
            robot_id=self.robot_id, epoch=epoch, submap_id=delta.submap_id, seq=self.seq,
            tick=tick, stamp_ns=stamp_ns, T_world_submap=T_world_loc @ delta.T_odom_submap,
            T_odom_submap=delta.T_odom_submap,
            points_mm=delta.points_mm, colors=delta.colors, counts=delta.counts,
            free_cells=delta.free_cells, cell_m=self.cell_m,
            offsets=delta.offsets, offset_levels=delta.offset_levels,
        )
        self.seq += 1
        return msg
