"""Goal bookkeeping: each robot's active goal, hysteresis, blacklist and goal ids.

A robot keeps its goal while a frontier cell lies within `keep_radius_m` of the goal's frontier
anchor (frontier ids are renumbered every plan, so goals are matched by place), the robot can
still reach it and no other robot kept that frontier first; with `retarget_goals`, a robot whose
goal cell it can no longer reach but whose region's new f′ it can keeps the region and gets
that f′. Goals reported invalid or
unreachable set their place aside for `blacklist_ticks`; reached goals for
`reached_blacklist_ticks` (a frontier the robot stood at but could not clear is not worth an
immediate second trip); a reached F_w spot for `weak_visited_ticks` (it has been looked at
from close by; a weak region that stays weak is not improved by a second visit). The
`blacklist_strikes`-th report at one place sets it aside for good, so a frontier that no robot
can clear stops holding completion back. A robot whose
frontier vanished and that gets no other goal receives a cancel for its old goal. With
`space_successor_m`, a robot about to reach its goal also gets its next one ahead
(successors.py, `Goal.queued`); it becomes the robot's goal when the agent reports it active.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from schemas.messages import Goal, GoalStatus
from services.common.grid import GridSpec
from services.edge_server.assignment import Scorer
from services.edge_server.config import EdgeConfig
from services.edge_server.coordination import RobotStates, travel_time_s
from services.edge_server.frontiers import FrontierSet
from services.edge_server.robot_fields import RobotFields
from services.edge_server.successors import successor_frontiers
from services.edge_server.tours import coarse_paths_m, min_max_routes

log = logging.getLogger(__name__)

FOREVER_TICKS = 10**9


@dataclass(frozen=True)
class ActiveGoal:
    goal_id: int
    goal_xy: tuple[float, float]
    anchor_xy: tuple[float, float]
    revenue: float
    weak: bool = False


@dataclass(frozen=True)
class Assignment:
    """The outcome of one plan: robot → frontier index, and the goals to publish."""

    assigned: dict[int, int]
    new_goals: list[Goal]
    assignable: int  # frontiers neither blacklisted nor unreachable by every robot
    unexplored_voxels: int = 0  # the assignable F_u regions' voxels, together


class GoalBook:
    def __init__(self, config: EdgeConfig) -> None:
        self.config = config
        self.active: dict[int, ActiveGoal] = {}
        self.issued: dict[int, tuple[float, float, bool]] = {}  # goal id → goal x, y, F_w?
        self.blacklist: list[tuple[float, float, int]] = []  # (x, y, expiry tick)
        self.strikes: list[tuple[float, float]] = []  # every bad/reached report's place
        self.looked_from: list[tuple[float, float]] = []  # reached places (space_second_look_m)
        self.viewed_anchor: dict[int, tuple[float, float]] = {}  # far-view goal → anchor
        self.successors: dict[int, ActiveGoal] = {}  # robot → queued goal last sent
        self.provisional: set[int] = set()  # robots on an adopted successor, not yet re-scored
        self.retarget: set[int] = set()  # robots whose kept region's f′ moved (retarget_goals)
        self.drops: Counter[str] = Counter()  # why goals were not kept, over the mission
        self.next_goal_id = 0

    # -- agent reports ---------------------------------------------------------------------
    def on_status(self, status: GoalStatus) -> None:
        issued = self.issued.get(status.goal_id)
        if status.status == "active":
            queued = self.successors.get(status.robot_id)
            # adopted; unless a plan gave the robot a goal since (that one replaces it)
            if queued is not None and queued.goal_id == status.goal_id:
                del self.successors[status.robot_id]
                if status.robot_id not in self.active:
                    self.active[status.robot_id] = queued
                    self.provisional.add(status.robot_id)
            return
        if issued is None:
            return
        x, y, weak = issued
        ticks = self.config.blacklist_ticks
        if status.status == "reached":
            ticks = self.config.weak_visited_ticks if weak else self.config.reached_blacklist_ticks
            if self.config.planner == "space" and self.config.space_reached_final:
                ticks = FOREVER_TICKS  # what a visit did not clear, another from there won't
                if self.config.space_second_look_m > 0:  # ... but one from elsewhere might
                    self.looked_from.append((x, y))
                    ticks = 0
        r2 = self.config.blacklist_radius_m**2
        n = 1 + sum((x - sx) ** 2 + (y - sy) ** 2 <= r2 for sx, sy in self.strikes)
        self.strikes.append((x, y))
        if n >= self.config.blacklist_strikes:  # keeps coming back: never clearable
            ticks = FOREVER_TICKS
        if ticks > 0:
            self.blacklist.append((x, y, status.tick + ticks))
        anchor = self.viewed_anchor.get(status.goal_id)
        if status.status == "reached" and anchor is not None:
            # seen from as far back as the camera needed: the region is done from anywhere
            self.blacklist.append((anchor[0], anchor[1], FOREVER_TICKS))
        current = self.active.get(status.robot_id)
        if current is not None and current.goal_id == status.goal_id:
            log.info("robot %d goal %d %s %s", status.robot_id, status.goal_id, status.status,
                     status.reason)
            del self.active[status.robot_id]

    def goal_cells(self, reachable: np.ndarray, spec: GridSpec) -> np.ndarray:
        """Cells a goal may be placed on: reachable and away from every place looked from."""
        if not self.looked_from:
            return reachable
        rc = spec.cell_of(np.array(self.looked_from))
        rc = rc[spec.contains(rc)]
        if not len(rc):
            return reachable
        seen = np.zeros(reachable.shape, bool)
        seen[rc[:, 0], rc[:, 1]] = True
        r = self.config.space_second_look_m / spec.resolution_m
        return reachable & (ndimage.distance_transform_edt(~seen) > r)

    def release(self, robot_id: int) -> None:
        """Free a robot's goal (its agent is gone)."""
        self.active.pop(robot_id, None)

    # -- planning --------------------------------------------------------------------------
    def allowed(self, frontiers: FrontierSet, tick: int) -> np.ndarray:
        """(F,) bool: frontiers whose goal and anchor are clear of every live blacklist entry."""
        self.blacklist = [b for b in self.blacklist if b[2] > tick]
        ok = np.ones(len(frontiers), bool)
        if not self.blacklist or not len(frontiers):
            return ok
        bad = np.array([b[:2] for b in self.blacklist])
        r2 = self.config.blacklist_radius_m**2
        for xy in (frontiers.goal_xy, frontiers.anchor_xy):
            d2 = ((xy[:, None, :] - bad[None, :, :]) ** 2).sum(axis=2)
            ok &= ~(d2 <= r2).any(axis=1)
        return ok

    def _kept(
        self, robots: list[int], fields: RobotFields, frontiers: FrontierSet,
        spec: GridSpec, usable: np.ndarray,
    ) -> dict[int, int]:
        """Robot → frontier index for goals that survive (hysteresis)."""
        kept: dict[int, int] = {}
        if not len(frontiers):
            return kept
        k = int(np.ceil(self.config.keep_radius_m / spec.resolution_m)) + 1
        for robot in robots:
            goal = self.active.get(robot)
            if goal is None:
                continue
            rc = spec.cell_of(np.array([goal.anchor_xy]))
            grc = spec.cell_of(np.array([goal.goal_xy]))
            if not (spec.contains(rc)[0] and spec.contains(grc)[0]):
                self.drops["off the grid"] += 1
                continue
            r, c = rc[0]
            same = np.flatnonzero((frontiers.anchor_rc[:, 0] == r)
                                  & (frontiers.anchor_rc[:, 1] == c))
            if len(same) and self.config.keep_by_anchor:
                # the region is still there, anchor and all, though an F_w region drawn over
                # it may have taken every one of its cells on the label grid
                f = int(same[0])
                if usable[f] and f not in kept.values() and fields.reaches(robot, grc)[0]:
                    kept[robot] = f
                    continue
            # nearest frontier cell to the old anchor: EDT on a window of the keep radius
            r0, c0 = max(r - k, 0), max(c - k, 0)
            window = frontiers.labels[r0 : r + k + 1, c0 : c + k + 1]
            if not window.any():
                self.drops["region gone"] += 1
                continue
            dist, nearest = ndimage.distance_transform_edt(window == 0, return_indices=True)
            if dist[r - r0, c - c0] * spec.resolution_m > self.config.keep_radius_m:
                self.drops["region gone"] += 1
                continue
            f = int(window[nearest[0][r - r0, c - c0], nearest[1][r - r0, c - c0]]) - 1
            if not usable[f] or f in kept.values():
                self.drops["region not usable" if not usable[f] else "a teammate kept it"] += 1
                continue
            if fields.reaches(robot, grc)[0]:
                kept[robot] = f
            elif not fields.reaches(robot, frontiers.goal_rc[f])[0]:
                self.drops["region out of reach"] += 1
            elif self.config.retarget_goals:
                kept[robot] = f  # its cell was taken (an obstacle seen next to it): f′ moved
                self.retarget.add(robot)
                self.drops["goal cell taken, region kept at its new f′"] += 1
            else:
                self.drops["goal cell taken"] += 1
        return kept

    def plan(
        self, tick: int, robots: list[int], fields: RobotFields,
        frontiers: FrontierSet, spec: GridSpec, scorer: Scorer, poses: np.ndarray,
    ) -> Assignment:
        """Keep surviving goals, give every other robot its best free frontier.
        `poses`: (R, 3) x, y, yaw (world) of `robots`, in that order."""
        goal_rc = frontiers.goal_rc
        usable = self.allowed(frontiers, tick) & fields.reachable[goal_rc[:, 0], goal_rc[:, 1]]
        self.retarget.clear()
        kept = self._kept(robots, fields, frontiers, spec, usable)
        for robot in self.provisional:  # a successor was chosen ahead: score it with the rest
            kept.pop(robot, None)
        # path lengths only for robots that need a goal (Dijkstra is the costly part of a plan)
        need = [r for r in robots if r not in kept] if usable.any() else []
        fields.compute(need)
        reach = np.array([fields[r][goal_rc[:, 0], goal_rc[:, 1]] if r in need
                          else np.full(len(frontiers), np.inf)
                          for r in robots]).reshape(len(robots), len(frontiers))
        dropped = {r: self.active.pop(r) for r in sorted(self.active) if r not in kept}
        held = np.array([self.active[r].goal_xy for r in sorted(kept)]).reshape(-1, 2)
        poses = np.asarray(poses, np.float64).reshape(len(robots), 3)
        scores = scorer.score(reach * spec.resolution_m, frontiers,
                              RobotStates(poses[:, :2], poses[:, 2], held))
        scores[:, ~usable] = -np.inf
        scores[:, list(kept.values())] = -np.inf
        scores[[i for i, r in enumerate(robots) if r in kept], :] = -np.inf
        new_goals = []
        assigned = dict(kept)
        if self.config.planner == "space" and self.config.space_tour:
            matched = self._tour_match(robots, kept, reach * spec.resolution_m, frontiers,
                                       usable, spec, fields, poses, scores, scorer)
        else:
            matched = scorer.match(scores)
        for i, f in matched.items():
            assigned[robots[i]] = f
            old = dropped.get(robots[i])
            if robots[i] in self.provisional and old is not None and np.hypot(
                    *(frontiers.goal_xy[f] - old.goal_xy)) <= self.config.blacklist_radius_m:
                self.active[robots[i]] = dropped.pop(robots[i])  # confirmed: no new message
                continue
            goal, self.active[robots[i]] = self._goal(robots[i], f, tick, frontiers,
                                                      float(scores[i, f]))
            self.successors.pop(robots[i], None)  # a new goal clears the agent's queued one
            new_goals.append(goal)
        for robot in sorted(self.retarget & set(kept) - self.provisional):  # same region, new f′
            old = self.active[robot]
            goal, self.active[robot] = self._goal(robot, kept[robot], tick, frontiers, old.revenue)
            new_goals.append(goal)
        for robot, old in dropped.items():  # frontier gone and nothing else: withdraw the goal
            if robot not in assigned and robot in robots:
                new_goals.append(Goal(robot_id=robot, tick=tick, goal_id=old.goal_id,
                                      x=old.goal_xy[0], y=old.goal_xy[1], revenue=0.0,
                                      frontier_class="weak" if old.weak else "unexplored",
                                      cancel=True))
        self.provisional.clear()
        if self.config.planner == "space" and self.config.space_successor_m > 0:
            new_goals += self._successors(tick, robots, fields, frontiers, spec, scorer, poses,
                                          usable, assigned)
        unexplored = usable if frontiers.weak is None else usable & ~frontiers.weak
        return Assignment(dict(sorted(assigned.items())), new_goals, int(usable.sum()),
                          int(frontiers.sizes[unexplored].sum()))

    def _tour_match(
        self, robots: list[int], kept: dict[int, int], path_m: np.ndarray,
        frontiers: FrontierSet, usable: np.ndarray, spec: GridSpec, fields: RobotFields,
        poses: np.ndarray, scores: np.ndarray, scorer: Scorer,
    ) -> dict[int, int]:
        """Row → frontier for robots needing a goal: the first stop of their route in a
        min-max tour over the free usable regions (tours.py); the revenue's match for a robot
        whose route is empty."""
        cfg = self.config
        need = [i for i, r in enumerate(robots) if r not in kept and np.isfinite(scores[i]).any()]
        free = usable.copy()
        free[list(kept.values())] = False
        cols = np.flatnonzero(free)
        out: dict[int, int] = {}
        if need and len(cols):
            held = [i for i, r in enumerate(robots) if r in kept]
            goal_rc = frontiers.goal_rc[cols]
            kept_goal_rc = spec.cell_of(
                np.array([self.active[robots[i]].goal_xy for i in held]).reshape(-1, 2))
            kept_robot_rc = spec.cell_of(poses[held, :2].reshape(-1, 2))
            d = coarse_paths_m(fields.traversable, np.vstack([goal_rc, kept_goal_rc,
                                                              kept_robot_rc]),
                               np.vstack([goal_rc, kept_goal_rc]), cfg.space_tour_coarse,
                               spec.resolution_m)
            F, K = len(cols), len(held)
            start = np.vstack([
                travel_time_s(path_m[np.ix_(need, cols)], poses[need, :2], poses[need, 2],
                              frontiers.goal_xy[cols], cfg.nav_v_mps, cfg.nav_omega_radps),
                d[F:F + K, :F] / cfg.nav_v_mps])
            offset = np.concatenate([np.zeros(len(need)),
                                     d[F + K + np.arange(K), F + np.arange(K)] / cfg.nav_v_mps])
            start[len(need):][~np.isfinite(offset[len(need):])] = np.inf
            offset[~np.isfinite(offset)] = 0.0
            routes = min_max_routes(start, offset, d[:F, :F] / cfg.nav_v_mps,
                                    cfg.space_tour_stop_s, cfg.space_tour_sum_weight)
            out = {need[n]: int(cols[routes[n][0]]) for n in range(len(need)) if routes[n]}
        rest = scores.copy()
        rest[list(out), :] = -np.inf
        rest[:, list(out.values())] = -np.inf
        out.update(scorer.match(rest))
        return out

    def _successors(
        self, tick: int, robots: list[int], fields: RobotFields, frontiers: FrontierSet,
        spec: GridSpec, scorer: Scorer, poses: np.ndarray, usable: np.ndarray,
        assigned: dict[int, int],
    ) -> list[Goal]:
        """Queued goals for robots within `space_successor_m` of their goal (new or moved
        ones only), and withdrawals of those that no longer have one."""
        xy = {r: poses[i, :2] for i, r in enumerate(robots)}
        r2 = self.config.space_successor_m**2
        near = {r: f for r, f in assigned.items() if r in xy
                and ((xy[r] - np.array(self.active[r].goal_xy)) ** 2).sum() <= r2}
        free = usable.copy()
        free[list(assigned.values())] = False
        chosen = successor_frontiers(near, frontiers, fields.traversable, spec.resolution_m, xy,
                                     free, scorer, self.config.start_snap_m / spec.resolution_m)
        out = []
        for robot in sorted(near):
            old = self.successors.get(robot)
            f = chosen.get(robot)
            if f is None:
                if old is not None:
                    del self.successors[robot]
                    out.append(Goal(robot_id=robot, tick=tick, goal_id=old.goal_id,
                                    x=old.goal_xy[0], y=old.goal_xy[1], revenue=0.0,
                                    frontier_class="unexplored", cancel=True, queued=True))
                continue
            goal_xy = tuple(frontiers.goal_xy[f])
            if old is not None and np.allclose(old.goal_xy, goal_xy):
                continue  # the agent holds it already
            goal, self.successors[robot] = self._goal(robot, f, tick, frontiers, 0.0)
            out.append(goal.model_copy(update={"queued": True}))
        return out

    def _goal(self, robot: int, f: int, tick: int, frontiers: FrontierSet, score: float
              ) -> tuple[Goal, ActiveGoal]:
        """A new goal at frontier `f` (recorded as issued) and its bookkeeping entry."""
        goal_xy = (float(frontiers.goal_xy[f, 0]), float(frontiers.goal_xy[f, 1]))
        goal_id = self.next_goal_id
        self.next_goal_id += 1
        weak = bool(frontiers.weak[f]) if frontiers.weak is not None else False
        self.issued[goal_id] = (goal_xy[0], goal_xy[1], weak)
        anchor_xy = (float(frontiers.anchor_xy[f, 0]), float(frontiers.anchor_xy[f, 1]))
        look = None
        view = frontiers.view is not None and bool(frontiers.view[f])
        if view or (self.config.planner == "space" and self.config.space_look_at_region):
            look = (float(frontiers.centroid_xy[f, 0]), float(frontiers.centroid_xy[f, 1]))
        if view:
            self.viewed_anchor[goal_id] = anchor_xy
            log.info("robot %d goal %d: a far view at (%.2f, %.2f) of the region at (%.2f, "
                     "%.2f)", robot, goal_id, *goal_xy, *anchor_xy)
        goal = Goal(robot_id=robot, tick=tick, goal_id=goal_id, x=goal_xy[0], y=goal_xy[1],
                    frontier_class="weak" if weak else "unexplored", revenue=score,
                    look_xy=look)
        return goal, ActiveGoal(goal_id, goal_xy, anchor_xy, score, weak)
