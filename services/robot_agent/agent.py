"""One robot's agent as a pure state machine: messages in, messages out, no bus or clock.

`AgentCore.on_odometry(k)` is the lockstep tick handler: it integrates the RGB-D frame of tick
k (received just before), then returns, in order, RobotPose, Submap deltas, GoalStatus changes
and last CmdVel(k). The pose estimate is odometry composed with the edge's correction offset
T_world_odom (identity until a Correction arrives; registration comes later).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from schemas.messages import (
    CmdVel,
    Correction,
    Goal,
    GoalStatus,
    Message,
    OccupancyGrid,
    Odometry,
    Pose2D,
    RgbdFrame,
    RobotPose,
    Submap,
)
from services.common.geometry import T_from_xyyaw, invert, transform_points, xyyaw_from_T
from services.robot_agent.config import AgentConfig
from services.robot_agent.local_grid import LocalGrid, floor_rays
from services.robot_agent.local_map import KeyframeMapper, SubmapDelta
from services.robot_agent.navigation import Command, Navigator, StatusEvent
from services.robot_agent.projection import cam_to_base, depth_to_points, pixel_colors

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Outgoing:
    """A message to publish on the robot's `topic` key (pose, submap, goal_status, cmd_vel)."""

    topic: str
    message: Message


def _xy_in(T_to_from: np.ndarray, xy_from: np.ndarray) -> np.ndarray:
    """Planar transform of (N, 2) points."""
    return xy_from @ T_to_from[:2, :2].T + T_to_from[:2, 3]


class AgentCore:
    """Local mapping, pose estimate and navigation of robot `robot_id`."""

    def __init__(self, config: AgentConfig, robot_id: int, tick_s: float) -> None:
        self.config = config
        self.robot_id = robot_id
        self.frame: RgbdFrame | None = None
        self.goal: Goal | None = None
        self.T_world_odom = np.eye(4)
        self.T_odom_submaps: dict[int, np.ndarray] = {}
        self.grid: LocalGrid | None = None
        self.edge_grid: OccupancyGrid | None = None
        self.mapper = KeyframeMapper(config)
        self.nav = Navigator(config, tick_s)
        self.teammates: dict[int, RobotPose] = {}
        self.seq = 0

    # -- inputs that only update state -------------------------------------------------------
    def on_rgbd(self, frame: RgbdFrame) -> None:
        self.frame = frame

    def on_goal(self, goal: Goal) -> None:
        self.goal = goal  # adopted on the next tick, so its status goes out in tick order

    def on_grid(self, grid: OccupancyGrid) -> None:
        self.edge_grid = grid
        if self.grid is not None:
            self.grid.merge_edge(grid)

    def on_pose(self, pose: RobotPose) -> None:
        if pose.robot_id != self.robot_id:
            self.teammates[pose.robot_id] = pose

    def on_correction(self, corr: Correction) -> None:
        """Move the odometry frame so the newest corrected submap we know lands on its pose."""
        known = [(int(i), T) for i, T in zip(corr.submap_ids, corr.T_world_submap, strict=True)
                 if int(i) in self.T_odom_submaps]
        if known:
            sid, T_world_submap = max(known, key=lambda item: item[0])
            self.T_world_odom = T_world_submap @ invert(self.T_odom_submaps[sid])

    # -- the tick ----------------------------------------------------------------------------
    def on_odometry(self, odom: Odometry) -> list[Outgoing]:
        p = odom.pose_odom
        T_odom_base = T_from_xyyaw(p.x, p.y, p.yaw)
        T_world_base = self.T_world_odom @ T_odom_base
        pose_world = xyyaw_from_T(T_world_base)
        if self.grid is None:
            self.grid = LocalGrid.centred(
                pose_world[0], pose_world[1], self.config.grid_half_size_m, self.config.cell_m
            )
            if self.edge_grid is not None:
                self.grid.merge_edge(self.edge_grid)
        deltas: list[SubmapDelta] = []
        if self.frame is not None and self.frame.tick <= odom.tick:
            deltas += self._integrate(self.frame, T_odom_base, T_world_base, odom.tick)
            self.frame = None
        if odom.tick % self.config.submap_every_ticks == 0:
            delta = self.mapper.take_delta()
            deltas += [delta] if delta is not None else []
        events: list[StatusEvent] = []
        if self.goal is not None:
            event = self.nav.set_goal(self.goal, odom.tick)
            events += [event] if event is not None else []
            self.goal = None
        cmd, event = self.nav.step(pose_world, self.grid, odom.tick)
        events += [event] if event is not None else []
        return self._outputs(odom, pose_world, deltas, events, cmd)

    def _integrate(
        self, frame: RgbdFrame, T_odom_base: np.ndarray, T_world_base: np.ndarray, tick: int
    ) -> list[SubmapDelta]:
        """Add one frame to the current submap (switching keyframes first) and the grid."""
        cfg = self.config
        out: list[SubmapDelta] = []
        if self.mapper.needs_keyframe(T_odom_base, tick):
            delta = self.mapper.take_delta()
            out += [delta] if delta is not None else []
            sub = self.mapper.start_keyframe(T_odom_base, tick)
            self.T_odom_submaps[sub.submap_id] = sub.T_odom_submap
        cam = depth_to_points(frame.depth_m, frame.K, cfg.pixel_stride, frame.range_max_m)
        points_base = cam_to_base(cam.points_cam, frame.T_base_cam)
        free_base = floor_rays(
            points_base, frame.T_base_cam[:2, 3], cfg.obstacle_z_min_m, cfg.obstacle_z_max_m,
            cfg.cell_m, cfg.ray_bin_rad,
        )
        floor = points_base[:, 2] <= cfg.obstacle_z_min_m  # the scan's rays cover floor hits
        assert self.mapper.current is not None
        T_submap_base = invert(self.mapper.current.T_odom_submap) @ T_odom_base
        self.mapper.integrate(
            transform_points(T_submap_base, points_base),
            pixel_colors(frame.rgb, cam),
            _xy_in(T_submap_base, free_base),
        )
        band = ~floor & (points_base[:, 2] <= cfg.obstacle_z_max_m)
        assert self.grid is not None
        occupied_world = _xy_in(T_world_base, points_base[band, :2])
        self.grid.update(_xy_in(T_world_base, free_base), occupied_world)
        return out

    def _outputs(
        self, odom: Odometry, pose_world: tuple[float, float, float], deltas: list[SubmapDelta],
        events: list[StatusEvent], cmd: Command,
    ) -> list[Outgoing]:
        rid, tick = self.robot_id, odom.tick
        out = [Outgoing("pose", RobotPose(
            robot_id=rid, tick=tick, stamp_ns=odom.stamp_ns, pose_world=Pose2D(
                x=pose_world[0], y=pose_world[1], yaw=pose_world[2]), state=self.nav.state,
        ))]
        for delta in deltas:
            out.append(Outgoing("submap", self._submap_message(delta, tick, odom.stamp_ns)))
        for ev in events:
            log.info("robot %d goal %d: %s %s", rid, ev.goal_id, ev.status, ev.reason)
            out.append(Outgoing("goal_status", GoalStatus(
                robot_id=rid, tick=tick, goal_id=ev.goal_id, status=ev.status, reason=ev.reason,
            )))
        out.append(Outgoing("cmd_vel", CmdVel(
            robot_id=rid, tick=tick, v_mps=cmd.v_mps, omega_radps=cmd.omega_radps,
        )))
        return out

    def _submap_message(self, delta: SubmapDelta, tick: int, stamp_ns: int) -> Submap:
        msg = Submap(
            robot_id=self.robot_id, submap_id=delta.submap_id, seq=self.seq, tick=tick,
            stamp_ns=stamp_ns, T_world_submap=self.T_world_odom @ delta.T_odom_submap,
            points_mm=delta.points_mm, colors=delta.colors, counts=delta.counts,
            free_cells=delta.free_cells, cell_m=self.config.cell_m,
        )
        self.seq += 1
        return msg
