"""One robot's agent as a pure state machine: messages in, messages out, no bus or clock.

`AgentCore.on_odometry(k)` is the lockstep tick handler: it integrates the RGB-D frame of tick
k (received just before), then returns, in order, RobotPose, Submap deltas, GoalStatus changes
and last CmdVel(k). With `defer=True` the work CmdVel(k) does not need (the frame's voxels into
the submap, the frame into the registration map, and the tick's periodic submap delta) waits
for `finish_tick()`, which the node calls once CmdVel(k) is out, so the simulator's next tick
overlaps it; the state after `finish_tick` and every message are the same as without.

Pose chain: T_world_base = T_world_loc · T_loc_odom · T_odom_base. `odom` is the drifting wheel
odometry, `loc` the frame registration keeps consistent (localization.py; submaps live in it),
T_world_loc comes from the edge's corrections (identity until one arrives).

Per frame: mutual awareness picks the teammates that may be in view, the DRF zeroes their
pixels, and only the filtered depth reaches registration, the submap and the grid.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from schemas.messages import (
    Correction,
    Goal,
    Inventory,
    OccupancyGrid,
    Odometry,
    RgbdFrame,
    RobotPose,
)
from services.common.geometry import (
    T_from_xyyaw,
    invert,
    transform_points,
    transform_xy,
    xyyaw_from_T,
)
from services.common.inventory import inventory_of
from services.robot_agent.config import AgentConfig
from services.robot_agent.drf import filter_mask
from services.robot_agent.exploration import LocalExplorer
from services.robot_agent.local_grid import LocalGrid, floor_rays
from services.robot_agent.local_map import KeyframeMapper, SubmapDelta
from services.robot_agent.localization import Localizer
from services.robot_agent.navigation import Command, Navigator, StatusEvent
from services.robot_agent.outbox import Outbox, Outgoing, TickResult
from services.robot_agent.params import drf_params, loop_params, registration_params
from services.robot_agent.projection import cam_to_base, depth_to_points, pixel_colors
from services.robot_agent.teammates import teammates_in_view, teammates_xy
from services.robot_agent.view_voxels import CameraView, whole_voxel_mask
from services.robot_agent.yielding import YieldRule

if TYPE_CHECKING:
    from services.robot_agent.back_end import BackEnd

log = logging.getLogger(__name__)

SUBMAP_IDS_PER_EPOCH = 10_000


@dataclass(frozen=True)
class DrfRecord:
    """The last frame's DRF inputs and output (for benchmarks and tests)."""

    tick: int
    pose_world: tuple[float, float, float]
    targets_xy: np.ndarray  # (N, 2) teammates passed to the DRF
    mask: np.ndarray  # (H, W) bool pixels removed


def _back_end(config: AgentConfig, robot_id: int) -> BackEnd | None:
    """The keyframe pose graph when loop closure is on; imported only then, since it alone
    needs gtsam (0.3 s of CPU at every agent start otherwise)."""
    if not (config.loop_closure and config.registration):
        return None
    from services.robot_agent.back_end import BackEnd

    return BackEnd(loop_params(config), robot_id)


class AgentCore:
    """Local mapping, pose estimate and navigation of robot `robot_id`."""

    def __init__(
        self, config: AgentConfig, robot_id: int, tick_s: float, team_size: int = 0
    ) -> None:
        self.config = config
        self.robot_id = robot_id
        self.team_size = team_size  # teammates (robots − 1) whose poses mapping waits for
        self.frame: RgbdFrame | None = None
        self.goal: Goal | None = None
        self.queued: Goal | None = None  # the edge's successor, adopted when a goal ends
        self.cancels: list[int] = []
        self.epoch: int | None = None  # first tick this process handled
        self.T_world_loc = np.eye(4)
        self.grid: LocalGrid | None = None
        self.edge_grid: OccupancyGrid | None = None
        self.mapper = KeyframeMapper(config)
        self.localizer = Localizer(registration_params(config))
        self.back_end = _back_end(config, robot_id)
        self.n_frames = 0
        self.view_hidden = False  # the last frame was too hidden by teammates to register
        self.hidden_hold_ticks = 0  # ticks the current turn in place was held for it
        self.tick_s = tick_s
        self.nav = Navigator(config, tick_s)
        self.teammates: dict[int, RobotPose] = {}
        self.teammates_prev: dict[int, RobotPose] = {}  # the one before, for the velocity
        self.yields = YieldRule(config, robot_id)
        self.frames_skipped = 0  # frames dropped while waiting for the team's poses
        self.drf = drf_params(config)
        self.last_drf: DrfRecord | None = None
        self.edge_alive = True  # assumed until its liveliness token is seen to go
        self.resend_pending = False
        self.explorer = LocalExplorer(config, robot_id)
        self.outbox = Outbox(robot_id, config.cell_m)
        self.defer = False  # this tick's submap integration waits for `finish_tick`
        self.deferred: list[Callable[[], None]] = []  # ... these
        # (tick, stamp_ns, T_world_loc, epoch) of the periodic delta that waits for them
        self.late: tuple[int, int, np.ndarray, int] | None = None
        self.ran_ahead = 0  # ticks that went ahead of unfinished deferred work

    # -- inputs that only update state -------------------------------------------------------
    def on_rgbd(self, frame: RgbdFrame) -> None:
        self.frame = frame

    def on_goal(self, goal: Goal) -> None:
        if goal.queued:
            withdrawn = goal.cancel and self.queued is not None \
                and self.queued.goal_id == goal.goal_id
            self.queued = None if withdrawn else (self.queued if goal.cancel else goal)
            return
        if goal.cancel:
            self.cancels.append(goal.goal_id)
            if self.goal is not None and self.goal.goal_id == goal.goal_id:
                self.goal = None
            return
        self.goal = goal  # adopted on the next tick, so its status goes out in tick order
        self.queued = None  # a successor of the goal it replaces; the edge sends anew

    def on_grid(self, grid: OccupancyGrid) -> None:
        self.edge_grid = grid
        if self.grid is not None:
            self.grid.merge_edge(grid)

    def on_pose(self, pose: RobotPose) -> None:
        if pose.robot_id == self.robot_id:
            return
        if self.localizer.walls is not None:
            self.localizer.walls.receive(pose.robot_id, pose.wall_direction_rad,
                                         xyyaw_from_T(self.T_world_loc)[2])
        if self.localizer.odometry is not None:
            self.localizer.odometry.calibration.receive(pose.robot_id, pose.odometry_stats)
        last = self.teammates.get(pose.robot_id)
        if last is not None and last.tick < pose.tick:
            self.teammates_prev[pose.robot_id] = last
        self.teammates[pose.robot_id] = pose

    def team_ready(self, tick: int) -> bool:
        """Every teammate's pose is known (so the DRF can remove it), or the bounded wait
        is over (a teammate that never came up must not block mapping forever)."""
        if not self.config.drf:
            return True  # standalone maps teammates anyway: nothing to wait for
        waited = tick - (self.epoch if self.epoch is not None else tick)
        return len(self.teammates) >= self.team_size or waited >= self.config.map_wait_ticks

    def inventory(self, tick: int) -> Inventory:
        """The submaps this agent process produced and published (issue 7's nothing-lost
        check compares it with the edge's)."""
        epoch = self.epoch or 0
        items = [(epoch, sid, n) for sid, n in self.mapper.published() if n > 0]
        return inventory_of({self.robot_id: items}, tick)

    def on_edge_presence(self, alive: bool) -> None:
        """The edge's liveliness token appeared (True) or went (False)."""
        if alive and not self.edge_alive:
            self.resend_pending = True  # it may have missed (or lost) any of our submaps
        if alive != self.edge_alive:
            log.info("robot %d: edge %s", self.robot_id, "back" if alive else "away")
        self.edge_alive = alive

    def on_correction(self, corr: Correction) -> None:
        """Move the loc frame so the newest corrected submap we know lands on its pose."""
        known = [(int(i), T) for i, T in zip(corr.submap_ids, corr.T_world_submap, strict=True)
                 if self.mapper.pose_of(int(i)) is not None]
        if known:
            sid, T_world_submap = max(known, key=lambda item: item[0])
            self.T_world_loc = T_world_submap @ invert(self.mapper.pose_of(sid))

    # -- the tick ----------------------------------------------------------------------------
    def finish_tick(self, until: Callable[[], bool] | None = None) -> list[Outgoing]:
        """The deferred work of earlier `on_odometry(defer=True)` calls, in order, and its
        late messages (the periodic Submap delta, if a tick took one). With `until`, it
        stops between steps once `until()` is true (the node's next input is waiting): the
        rest stays queued for a later call, or for the next `on_odometry`."""
        registrar = self.localizer.registrar
        while self.deferred:
            if until is not None and until():
                return []
            self.deferred.pop(0)()
        if registrar.pending:
            if until is not None and until():
                return []
            registrar.flush()
        late, self.late = self.late, None
        delta = self.mapper.take_delta() if late is not None else None
        if late is None or delta is None:
            return []
        return [Outgoing("submap", self.outbox.submap(delta, *late))]

    @property
    def unfinished(self) -> bool:
        """Deferred work (or its late delta) is still queued: `finish_tick` has something."""
        return bool(self.deferred or self.late is not None or self.localizer.registrar.pending)

    def on_odometry(self, odom: Odometry, defer: bool = False) -> list[Outgoing]:
        """Tick k's messages, CmdVel(k) last; with `defer`, call `finish_tick` next.

        Deferred work still queued is done first (its late messages go out now), unless
        this tick may run ahead of it (`_runs_ahead`): then it waits behind this tick's."""
        ahead = defer and self.unfinished and self._runs_ahead(odom)
        self.ran_ahead += ahead
        early = [] if ahead else self.finish_tick()
        self.defer = self.localizer.registrar.defer_inserts = defer
        return early + self._tick(odom)

    def _runs_ahead(self, odom: Odometry) -> bool:
        """Whether tick k may come before the deferred work of earlier ticks: it has no
        frame to register or integrate, resends nothing and no late delta waits, so it
        neither reads the submap nor the registration map that work writes (a periodic
        delta of its own becomes late, taken after that work). The command of an
        odometry-only tick then goes out without waiting for the last frame's mapping."""
        frame_due = self.frame is not None and self.frame.tick <= odom.tick
        return not (frame_due or self.resend_pending or self.late is not None)

    def _tick(self, odom: Odometry) -> list[Outgoing]:
        if self.epoch is None:
            self.epoch = odom.tick
            self.mapper.next_id = odom.tick * SUBMAP_IDS_PER_EPOCH
        p = odom.pose_odom
        T_odom_base = T_from_xyyaw(p.x, p.y, p.yaw)
        self.localizer.observe_odometry(T_odom_base)
        deltas: list[SubmapDelta] = []
        if self.resend_pending:
            deltas += self.mapper.resend_all()
            self.resend_pending = False
        frame = self.frame if self.frame is not None and self.frame.tick <= odom.tick else None
        self.frame = None if frame is not None else self.frame
        if frame is not None and not self.team_ready(odom.tick):
            frame = None  # a teammate of unknown pose would be mapped as a ghost
            self.frames_skipped += 1
        T_loc_base = self.localizer.guess(T_odom_base)
        points_base = cam = None
        if frame is not None:
            if self.n_frames == 0:
                log.info("robot %d: first frame at tick %d (%d skipped waiting for teammates)",
                         self.robot_id, odom.tick, self.frames_skipped)
            cam, points_base = self._filtered_points(frame, T_loc_base, odom.tick)
            removed = self._drf_removed_frac(frame)
            self.view_hidden = removed > self.config.reg_max_removed_frac
            T_loc_base = self._register(self._whole_voxels(points_base, frame, T_loc_base),
                                        T_odom_base, removed)
        T_world_base = self._T_world_front() @ T_loc_base
        pose_world = xyyaw_from_T(T_world_base)
        self._ensure_grid(pose_world)
        if frame is not None:
            deltas += self._integrate(frame, cam, points_base, T_loc_base, T_world_base, odom.tick)
        periodic = odom.tick % self.config.submap_every_ticks == 0
        if periodic and not self.deferred:
            delta = self.mapper.take_delta()
            deltas += [delta] if delta is not None else []
        events = self._navigate_goal_inputs(pose_world, odom.tick)
        cmd, event = self.nav.step(pose_world, self.grid, odom.tick)
        cmd = self.yields.command(cmd, pose_world, self.teammates, self.teammates_prev, self.nav,
                                  odom.tick)
        if self.nav.state == "idle" and self.view_hidden and \
                not self.config.idle_spin_when_hidden:
            cmd = Command(0.0, 0.0)  # a turn no frame can register: hold still
        cmd = self._hold_hidden_turn(cmd)
        if self.n_frames == 0:
            # Still until the first frame anchors the map: odometry drifts only with motion, and
            # the yaw it lost in a first spin (0.1-0.5 deg) would rotate the whole map.
            cmd = Command(0.0, 0.0)
        self.nav.observe_motion(odom.tick, pose_world, cmd.v_mps,
                                teammates_xy(self.teammates))
        events += [event] if event is not None else []
        self._adopt_queued(events)
        walls, odometry = self.localizer.walls, self.localizer.odometry
        result = TickResult(
            tick=odom.tick, stamp_ns=odom.stamp_ns, pose_world=pose_world, state=self.nav.state,
            wall_direction_rad=walls.shared(xyyaw_from_T(self.T_world_loc)[2])
            if walls is not None else None,
            odometry_stats=odometry.calibration.shared() if odometry is not None else None,
            deltas=deltas, events=events, cmd=cmd)
        self.late = ((odom.tick, odom.stamp_ns, self.T_world_loc.copy(), self.epoch or 0)
                     if periodic and self.deferred else None)
        return self.outbox.messages(result, self.T_world_loc, self.epoch or 0)

    def _hold_hidden_turn(self, cmd: Command) -> Command:
        """No command while a turn in place (and, with `hidden_hold_driving`, any motion)
        would go unregistered behind teammates, for at most `hidden_turn_hold_s` at a time
        (two robots hiding each other's view both move on after it)."""
        moving = (cmd.v_mps != 0.0 and self.config.hidden_hold_driving) or (
            cmd.v_mps == 0.0 and cmd.omega_radps != 0.0)
        if not (self.view_hidden and moving):
            self.hidden_hold_ticks = 0
            return cmd
        if self.hidden_hold_ticks * self.tick_s >= self.config.hidden_turn_hold_s:
            return cmd
        self.hidden_hold_ticks += 1
        return Command(0.0, 0.0)

    def _adopt_queued(self, events: list[StatusEvent]) -> None:
        """The edge's successor becomes the goal (next tick) when this tick ended the last."""
        ended = any(ev.status in ("reached", "invalid", "unreachable") for ev in events)
        if ended and self.queued is not None and self.goal is None and self.nav.goal is None:
            self.goal, self.queued = self.queued.model_copy(update={"queued": False}), None

    def _T_world_front(self) -> np.ndarray:
        """World pose of the front end's frame: the edge's correction and the back end's."""
        if self.back_end is None:
            return self.T_world_loc
        return self.T_world_loc @ self.back_end.T_map_front()

    def _ensure_grid(self, pose_world: tuple[float, float, float]) -> None:
        if self.grid is None:
            self.grid = LocalGrid.centred(
                pose_world[0], pose_world[1], self.config.grid_half_size_m, self.config.cell_m
            )
            if self.edge_grid is not None:
                self.grid.merge_edge(self.edge_grid)

    def _navigate_goal_inputs(self, pose_world: tuple[float, float, float], tick: int
                              ) -> list[StatusEvent]:
        """Apply cancels and the pending goal; pick an own goal while the edge is away."""
        for goal_id in self.cancels:
            if self.nav.cancel(goal_id):
                log.info("robot %d goal %d cancelled by the edge", self.robot_id, goal_id)
        self.cancels = []
        if self.goal is None and self.explorer.wants_goal(tick, self.edge_alive,
                                                          self.nav.goal is not None):
            assert self.grid is not None
            self.goal = self.explorer.goal(self.grid, pose_world, tick)
        events: list[StatusEvent] = []
        if self.goal is not None:
            assert self.grid is not None
            if self.grid.cover(np.array([[self.goal.x, self.goal.y], pose_world[:2]]),
                               self.config.grid_half_size_m / 2) and self.edge_grid is not None:
                self.grid.merge_edge(self.edge_grid)  # the edge's cells beyond the old bounds
            event = self.nav.set_goal(self.goal, tick)
            events += [event] if event is not None else []
            self.goal = None
        return events

    # -- perception --------------------------------------------------------------------------
    def _filtered_points(self, frame: RgbdFrame, T_loc_base: np.ndarray, tick: int):
        """Camera points of the frame after the DRF, and the same points in the base frame."""
        depth = frame.depth_m
        if self.config.drf:
            pose_world = xyyaw_from_T(self._T_world_front() @ T_loc_base)  # pre-registration
            targets = teammates_in_view(self.teammates, self.teammates_prev, pose_world,
                                        frame, tick, self.config)
            mask = np.zeros(depth.shape, bool)
            if targets.shape[0]:
                mask = filter_mask(depth, frame.K, frame.T_base_cam, pose_world, targets,
                                   self.drf)
                depth = np.where(mask, np.float32(0.0), depth)
            self.last_drf = DrfRecord(tick, pose_world, targets, mask)
        cam = depth_to_points(depth, frame.K, self.config.pixel_stride, frame.range_max_m)
        return cam, cam_to_base(cam.points_cam, frame.T_base_cam)

    def _whole_voxels(self, points_base: np.ndarray, frame: RgbdFrame,
                      T_loc_base: np.ndarray) -> np.ndarray:
        """The points to register: with `reg_whole_voxels`, those whose registration-map voxel
        the frame saw whole at the odometry guess (the mapping keeps them all)."""
        mode, below = self.config.reg_whole_voxels, self.config.reg_whole_voxels_below_ratio
        if mode == "off" or (below < 1 and self.localizer.info_ratio >= below):
            return points_base
        depth = frame.depth_m
        valid = None
        if mode in ("pixels", "sphere"):
            valid = np.isfinite(depth) & (depth > 0) & (depth <= frame.range_max_m)
            if self.last_drf is not None and self.last_drf.tick == frame.tick:
                valid &= ~self.last_drf.mask
        view = CameraView(frame.K, depth.shape[1], depth.shape[0], frame.range_max_m,
                          frame.T_base_cam, valid, sphere=mode == "sphere")
        return points_base[whole_voxel_mask(points_base, T_loc_base,
                                            self.config.reg_map_voxel_m, view.holds_whole)]

    def _drf_removed_frac(self, frame: RgbdFrame) -> float:
        """Share of the frame's valid pixels the DRF removed (a teammate close to the lens)."""
        if self.last_drf is None or self.last_drf.tick != frame.tick:
            return 0.0
        valid = int(np.count_nonzero(frame.depth_m > 0))
        return float(np.count_nonzero(self.last_drf.mask)) / max(valid, 1)

    def _register(self, points_base: np.ndarray, T_odom_base: np.ndarray,
                  removed_frac: float = 0.0) -> np.ndarray:
        """Registered T_loc_base (or the odometry guess); T_loc_odom takes up the drift found."""
        guess = self.localizer.guess(T_odom_base)
        self.n_frames += 1
        if not self.config.registration or (self.n_frames - 1) % self.config.register_every_frames:
            return guess
        out = self.localizer.update(points_base, T_odom_base, removed_frac)
        if log.isEnabledFor(logging.DEBUG):  # the per-frame trace missions are diagnosed from
            dx, dy, dyaw = xyyaw_from_T(invert(guess) @ out.T_loc_base)
            mx, my, myaw = (xyyaw_from_T(invert(guess) @ out.T_measured)
                            if out.T_measured is not None else (np.nan,) * 3)
            log.debug("robot %d frame %d: %s, %d points, removed %.2f, measured (%.1f, %.1f) cm "
                      "%.2f deg, d2 %.1f, correction (%.1f, %.1f) cm %.2f deg, sd %s",
                      self.robot_id, self.n_frames, "accepted" if out.accepted else out.reason,
                      len(points_base), removed_frac, 100 * mx, 100 * my, math.degrees(myaw),
                      out.mahalanobis2, 100 * dx, 100 * dy, math.degrees(dyaw),
                      np.round(np.sqrt(np.diag(self.localizer.P)), 4))
        return out.T_loc_base

    def _surely_placed(self, points_base: np.ndarray) -> np.ndarray | slice:
        """The points the heading's σ places within `map_heading_tolerance_m` (all: a slice)."""
        tolerance = self.config.map_heading_tolerance_m
        sigma = math.sqrt(max(float(self.localizer.P[2, 2]), 0.0))
        if tolerance <= 0 or sigma <= 0:
            return slice(None)
        return np.hypot(points_base[:, 0], points_base[:, 1]) * sigma <= tolerance

    def _integrate(
        self, frame: RgbdFrame, cam, points_base: np.ndarray, T_loc_base: np.ndarray,
        T_world_base: np.ndarray, tick: int,
    ) -> list[SubmapDelta]:
        """Add one frame to the current submap (switching keyframes first) and the grid."""
        cfg = self.config
        out: list[SubmapDelta] = []
        if self.mapper.needs_keyframe(T_loc_base, tick):
            delta = self.mapper.take_delta()
            out += [delta] if delta is not None else []
            closed = self.mapper.current
            sub = self.mapper.start_keyframe(T_loc_base, tick)
            if self.back_end is not None:
                self.back_end.on_keyframe(closed, sub, self.mapper)
                out += self.mapper.take_pose_updates()
        free_base = floor_rays(
            points_base, frame.T_base_cam[:2, 3], cfg.obstacle_z_min_m, cfg.obstacle_z_max_m,
            cfg.cell_m, cfg.ray_bin_rad,
        )
        floor = points_base[:, 2] <= cfg.obstacle_z_min_m  # the scan's rays cover floor hits
        assert self.mapper.current is not None
        T_submap_base = invert(self.mapper.current.T_odom_submap) @ T_loc_base
        sure = self._surely_placed(points_base)
        mapper = self.mapper

        def add_voxels() -> None:
            mapper.integrate(transform_points(T_submap_base, points_base[sure]),
                             pixel_colors(frame.rgb, cam)[sure],
                             transform_xy(T_submap_base, free_base))

        if self.defer:
            self.deferred.append(add_voxels)
        else:
            add_voxels()
        band = ~floor & (points_base[:, 2] <= cfg.obstacle_z_max_m)
        assert self.grid is not None
        occupied_world = transform_xy(T_world_base, points_base[band, :2])
        self.grid.update(transform_xy(T_world_base, free_base), occupied_world)
        return out
