"""Goal following: A* on the inflated local grid, pure pursuit, and goal status checks.

Pure functions (`plan_path`, `pure_pursuit`, `path_blocked`, `segment_times`) plus `Navigator`,
the per-goal state machine the node drives once per tick. Goal validity is the paper's
adaptive validator (`validator.py`): the robot's time over the last β path points against the
summed t_e of those points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from schemas.messages import Goal, GoalState
from services.common.geometry import wrap_angle
from services.common.grid import GridSpec
from services.common.planning import astar, disk, inflate, reachable
from services.robot_agent.config import AgentConfig
from services.robot_agent.contacts import ContactLayer, ContactParams
from services.robot_agent.local_grid import OCCUPIED, UNKNOWN, LocalGrid
from services.robot_agent.path_smoothing import smooth_path
from services.robot_agent.validator import PassLog, expected_times, window_exceeded


@dataclass(frozen=True)
class Command:
    v_mps: float
    omega_radps: float


@dataclass(frozen=True)
class PlanResult:
    path_xy: np.ndarray | None  # (K, 2) world xy of cell centres, start to goal
    reason: str = ""


@dataclass(frozen=True)
class StatusEvent:
    goal_id: int
    status: GoalState
    reason: str = ""


def inflation_cells(config: AgentConfig, cell_m: float) -> int:
    return int(math.ceil((config.robot_radius_m + config.inflation_margin_m) / cell_m))


def traversable_of(cells: np.ndarray, radius_cells: int, through_unknown: bool) -> np.ndarray:
    """Cells the robot centre may occupy: not within `radius_cells` of an obstacle."""
    trav = ~inflate(cells == OCCUPIED, radius_cells)
    return trav if through_unknown else trav & (cells != UNKNOWN)


def snap_cell(mask: np.ndarray, rc: tuple[int, int], radius_cells: float) -> tuple[int, int] | None:
    """The cell of `mask` nearest to `rc` within `radius_cells`, or None."""
    cand = np.argwhere(mask)
    if cand.size == 0:
        return None
    d2 = ((cand - np.asarray(rc)) ** 2).sum(axis=1)
    i = int(np.argmin(d2))
    return (int(cand[i, 0]), int(cand[i, 1])) if d2[i] <= radius_cells**2 else None


def plan_path(
    traversable: np.ndarray, spec: GridSpec, start_xy: np.ndarray, goal_xy: np.ndarray,
    snap_m: float, smooth: bool = False, island: tuple[int, float] = (0, 0.0),
) -> PlanResult:
    """A* from start to goal; a blocked start or goal moves to the nearest usable cell;
    `smooth`: the path shortened along lines of sight (path_smoothing.py); `island`: (cells,
    m) a start on a component of fewer cells moves to a larger one within that distance."""
    rc = spec.cell_of(np.array([start_xy, goal_xy]))
    if not spec.contains(rc).all():
        return PlanResult(None, "goal outside the local grid")
    start, goal = (int(rc[0, 0]), int(rc[0, 1])), (int(rc[1, 0]), int(rc[1, 1]))
    snap_cells = snap_m / spec.resolution_m
    if not traversable[start]:
        start = snap_cell(traversable, start, max(snap_cells, 10.0))
        if start is None:
            return PlanResult(None, "robot is boxed in by obstacles")
    reach = reachable(traversable, start)
    if island[0] and np.count_nonzero(reach) < island[0]:
        start, reach = _off_island(traversable, start, reach, island[0],
                                   island[1] / spec.resolution_m)
    if not reach[goal]:
        goal = snap_cell(reach, goal, snap_cells)
        if goal is None:
            return PlanResult(None, "no path to the goal on the local grid")
    path_rc = astar(traversable, start, goal)
    if path_rc is None:  # cannot happen after the reachability check; be safe
        return PlanResult(None, "A* found no path")
    return PlanResult(spec.centre_of(smooth_path(traversable, path_rc) if smooth else path_rc))


def _off_island(traversable: np.ndarray, start: tuple[int, int], reach: np.ndarray,
                min_cells: int, snap_cells: float) -> tuple[tuple[int, int], np.ndarray]:
    """The nearest cell of a component of at least `min_cells` within `snap_cells`, and its
    component; (start, reach) when there is none. The robot drove onto its island, so the
    inflated obstacles that close it in only pinch the way out."""
    labels, _ = ndimage.label(traversable)
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    near = snap_cell(sizes[labels] >= min_cells, start, snap_cells)
    if near is None:
        return start, reach
    return near, labels == labels[near]


def path_blocked(grid: LocalGrid, path_xy: np.ndarray, radius_cells: int) -> bool:
    """True when an occupied cell lies within `radius_cells` of a path point."""
    if path_xy.shape[0] == 0:
        return False
    offsets = np.argwhere(disk(radius_cells)) - radius_cells
    rc = grid.spec.cell_of(path_xy)
    around = (rc[:, None, :] + offsets[None, :, :]).reshape(-1, 2)
    around = around[grid.spec.contains(around)]
    return bool((grid.values_at(around) == OCCUPIED).any())


def segment_times(path_xy: np.ndarray, max_v: float, max_omega: float) -> np.ndarray:
    """(K-1,) expected seconds t_e per segment: driving at max_v plus turning at max_omega."""
    d = np.diff(path_xy, axis=0)
    if d.shape[0] == 0:
        return np.zeros(0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    turn = np.abs(wrap_angle(np.diff(heading, prepend=heading[0])))
    return np.hypot(d[:, 0], d[:, 1]) / max_v + turn / max_omega


def closest_index(path_xy: np.ndarray, xy: np.ndarray, from_index: int = 0) -> int:
    d = np.hypot(*(path_xy[from_index:] - xy).T)
    return from_index + int(np.argmin(d))


def pure_pursuit(
    pose: tuple[float, float, float], path_xy: np.ndarray, index: int, config: AgentConfig
) -> Command:
    """(v, ω) toward the path point one lookahead ahead; turn in place when far off heading."""
    x, y, yaw = pose
    xy = np.array([x, y])
    ahead = path_xy[index:]
    dist = np.hypot(*(ahead - xy).T)
    beyond = np.nonzero(dist >= config.lookahead_m)[0]
    target = ahead[beyond[0]] if beyond.size else ahead[-1]
    dx, dy = target - xy
    L = max(math.hypot(dx, dy), 1e-6)
    alpha = float(wrap_angle(math.atan2(dy, dx) - yaw))
    w_max = config.max_omega_radps
    if abs(alpha) > config.turn_in_place_rad:
        return Command(0.0, float(np.clip(config.k_omega * alpha, -w_max, w_max)))
    to_end = float(np.hypot(*(path_xy[-1] - xy)))
    v = min(config.max_v_mps, max(0.1, to_end))  # slow down over the last metre
    omega = 2.0 * v * math.sin(alpha) / L
    if abs(omega) > w_max:  # keep the curvature, lower the speed
        v *= w_max / abs(omega)
        omega = math.copysign(w_max, omega)
    return Command(v, omega)


class Navigator:
    """One goal at a time: plan, follow, replan, and report status changes."""

    def __init__(self, config: AgentConfig, tick_s: float) -> None:
        self.config = config
        self.tick_s = tick_s
        self.goal: Goal | None = None
        self.path_xy: np.ndarray | None = None
        self.index = 0
        self.plan_tick = -(10**9)
        self.t_e: np.ndarray = np.zeros(0)  # per segment of the current path
        self.log = PassLog(0)
        self.state = "idle"
        self.arrived_tick: int | None = None  # at f′, turning to the goal's look point
        self.avoid_xy: np.ndarray | None = None  # a teammate to plan around (`avoid`)
        self.avoid_until = -1
        self.had_goal = False
        self.contacts = (ContactLayer(ContactParams(), config.robot_radius_m)
                         if config.contact_layer else None)
        self.boxed_in = 0  # goals in a row that only the contact marks kept from a path

    def observe_motion(self, tick: int, pose: tuple[float, float, float], v_cmd_mps: float,
                       teammates_xy: np.ndarray) -> None:
        """The command sent from `pose` this tick: a stall marks a contact (contacts.py),
        and the path is planned around it at once."""
        if self.contacts is not None and self.contacts.observe(tick, pose, v_cmd_mps,
                                                                teammates_xy):
            self.plan_tick = -(10**9)

    def set_goal(self, goal: Goal, tick: int) -> StatusEvent | None:
        """Adopt a goal; the same goal id again changes nothing."""
        if self.goal is not None and goal.goal_id == self.goal.goal_id:
            return None
        self.goal, self.path_xy, self.index = goal, None, 0
        self.arrived_tick = None
        self.had_goal = True
        self.log = PassLog(tick)
        return StatusEvent(goal.goal_id, "active")

    def cancel(self, goal_id: int) -> bool:
        """Drop goal `goal_id` if it is the current one (the edge withdrew it); no status."""
        if self.goal is None or self.goal.goal_id != goal_id:
            return False
        self.goal, self.path_xy, self.state = None, None, "idle"
        self.arrived_tick = None
        return True

    def _finish(self, status: GoalState, reason: str = "") -> StatusEvent:
        assert self.goal is not None
        event = StatusEvent(self.goal.goal_id, status, reason)
        self.goal, self.path_xy, self.state = None, None, "idle"
        self.arrived_tick = None
        return event

    def _plan(self, grid: LocalGrid, pose: tuple[float, float, float], tick: int) -> PlanResult:
        assert self.goal is not None
        spec, cfg = grid.spec, self.config
        xy, goal_xy = np.array(pose[:2]), np.array([self.goal.x, self.goal.y])
        extra = spec.cell_of(np.array([xy, goal_xy]))
        rows, cols = grid.window(int(round(cfg.plan_beyond_known_m / spec.resolution_m)), extra)
        sub = GridSpec(
            spec.origin_x + cols.start * spec.resolution_m,
            spec.origin_y + rows.start * spec.resolution_m,
            spec.resolution_m, rows.stop - rows.start, cols.stop - cols.start,
        )
        cells = self._blocked_by_teammate(grid.cells(rows, cols), sub, tick)
        radius = inflation_cells(cfg, spec.resolution_m)
        trav = traversable_of(cells, radius, cfg.plan_through_unknown)
        island = (int(cfg.start_island_m2 / spec.resolution_m**2), cfg.start_island_snap_m)
        result = plan_path(trav, sub, xy, goal_xy, cfg.goal_snap_m, cfg.smooth_paths, island)
        if self.contacts is not None and result.path_xy is not None \
                and self.contacts.active(tick):
            # around what the robot ran into; a goal only reachable through it is not
            around = plan_path(traversable_of(self.contacts.mark(cells, sub, tick), radius,
                                              cfg.plan_through_unknown),
                               sub, xy, goal_xy, cfg.goal_snap_m, cfg.smooth_paths)
            result = around if around.path_xy is not None else self._boxed_in(result)
        if result.path_xy is not None:
            self.boxed_in = 0
        self.plan_tick = tick
        if result.path_xy is not None:
            # The path starts at the robot's cell: t_e from the robot's pose, then the path.
            path = np.vstack([xy[None, :], result.path_xy])
            self.path_xy, self.index = path, 0
            self.t_e = expected_times(path, pose[2], cfg.max_v_mps, cfg.max_omega_radps)
        return result

    def _boxed_in(self, without_marks: PlanResult) -> PlanResult:
        """A goal only the contact marks cut off: unreachable, unless as many goals in a row
        were (`contact_boxed_in_goals`): then the marks close every way out of where the
        robot stands, and it forgets them and takes the path (ROS's clear-costmap recovery;
        a robot stalled in a narrow gap otherwise stood there, every goal unreachable)."""
        assert self.contacts is not None
        self.boxed_in += 1
        limit = self.config.contact_boxed_in_goals
        if limit and self.boxed_in >= limit:
            self.contacts.clear()
            return without_marks
        return PlanResult(None, "only through what the robot ran into")

    def avoid(self, xy: np.ndarray, tick: int) -> None:
        """Plan around a teammate at `xy` from now until the next periodic replan."""
        self.avoid_xy = np.asarray(xy, np.float64).copy()
        self.avoid_until = tick + self.config.replan_every_ticks
        self.plan_tick = -(10**9)  # replan at the next step

    def _blocked_by_teammate(self, cells: np.ndarray, spec: GridSpec, tick: int) -> np.ndarray:
        """The planning cells with the avoided teammate's disc marked occupied."""
        if self.avoid_xy is None or tick > self.avoid_until:
            self.avoid_xy = None
            return cells
        r = int(math.ceil(self.config.detour_radius_m / spec.resolution_m))
        centre = spec.cell_of(self.avoid_xy[None, :])[0]
        rc = np.argwhere(disk(r)) - r + centre
        rc = rc[spec.contains(rc)]
        cells = cells.copy()
        cells[rc[:, 0], rc[:, 1]] = OCCUPIED
        return cells

    def _needs_plan(self, grid: LocalGrid, tick: int) -> bool:
        if self.path_xy is None or tick - self.plan_tick >= self.config.replan_every_ticks:
            return True
        ahead = self.path_xy[self.index :]
        radius = inflation_cells(self.config, grid.spec.resolution_m)
        return path_blocked(grid, ahead, radius - 1)

    def step(
        self, pose: tuple[float, float, float], grid: LocalGrid, tick: int
    ) -> tuple[Command, StatusEvent | None]:
        """The command for this tick and, when the goal's status changed, the new status."""
        cfg = self.config
        if self.goal is None:
            self.state = "idle"
            spin = self.had_goal or cfg.spin_before_first_goal
            return Command(0.0, cfg.spin_omega_radps if spin else 0.0), None
        if self.arrived_tick is not None:
            return self._look(pose, tick)
        xy = np.array(pose[:2])
        if self._needs_plan(grid, tick):
            result = self._plan(grid, pose, tick)
            if result.path_xy is None:
                return Command(0.0, 0.0), self._finish("unreachable", result.reason)
        assert self.path_xy is not None
        index = closest_index(self.path_xy, xy, self.index)
        self.log.passed(tick, self.t_e[self.index : index])
        self.index = index
        if np.hypot(*(self.path_xy[-1] - xy)) <= cfg.goal_tolerance_m:
            self.arrived_tick = tick
            return self._look(pose, tick)
        event = self._check_progress(tick)
        if event is not None:
            return Command(0.0, 0.0), event
        cmd = pure_pursuit(pose, self.path_xy, self.index, cfg)
        self.state = "turning" if cmd.v_mps == 0.0 else "following"
        return cmd, None

    def _look(self, pose: tuple[float, float, float], tick: int
              ) -> tuple[Command, StatusEvent | None]:
        """At f′: turn in place to face the goal's look point, then report reached. A turn
        that takes longer than a half turn at full rate (plus a second) ends anyway."""
        assert self.goal is not None and self.arrived_tick is not None
        cfg = self.config
        look = self.goal.look_xy
        if look is None:
            return Command(0.0, 0.0), self._finish("reached")
        err = wrap_angle(math.atan2(look[1] - pose[1], look[0] - pose[0]) - pose[2])
        limit_ticks = (math.pi / cfg.max_omega_radps + 1.0) / self.tick_s
        if abs(err) <= cfg.look_tolerance_rad or tick - self.arrived_tick > limit_ticks:
            return Command(0.0, 0.0), self._finish("reached")
        self.state = "turning"
        omega = float(np.clip(cfg.k_omega * err, -cfg.max_omega_radps, cfg.max_omega_radps))
        return Command(0.0, omega), None

    def _check_progress(self, tick: int) -> StatusEvent | None:
        """The adaptive validator: time over the last β points against their t_e."""
        cfg = self.config
        current = float(self.t_e[self.index]) if self.index < self.t_e.size else 0.0
        if window_exceeded(self.log, tick, self.tick_s, current, cfg.validator_beta,
                           cfg.validator_slack_s):
            return self._finish(
                "invalid", f"slower than t_e over the last {cfg.validator_beta} path points"
            )
        return None
