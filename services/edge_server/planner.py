"""The edge's functional core: messages in, one planning update out (no bus, no clock).

A plan updates the pose graph (corrected submap poses go back to the agents), merges the
submaps (P*), builds the merged grid, computes each robot's distance field on the inflated
grid, finds frontiers with goals f′ that some robot can reach (detector per planner), assigns
them and judges completion. Everything is driven by message order and tick numbers only.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from schemas.messages import (
    Correction,
    Frontiers,
    Goal,
    GoalStatus,
    OccupancyGrid,
    Pose2D,
    RobotPose,
    Submap,
)
from services.edge_server.assignment import Scorer, make_scorer
from services.edge_server.completion import CompletionJudge, VisitLog
from services.edge_server.config import EdgeConfig
from services.edge_server.frontier_cache import IncrementalFrontiers
from services.edge_server.frontiers import (
    FrontierSet,
    GoalTransform,
    detect_frontiers,
    empty_frontiers,
    frontier_length_near,
    frontiers_message,
    goal_transform,
)
from services.edge_server.frontiers3d import PointFrontiers
from services.edge_server.goals import GoalBook
from services.edge_server.importance import importance
from services.edge_server.merged_grid import GridSnapshot, MergedGrid
from services.edge_server.merged_map import MergedMap
from services.edge_server.robot_fields import InflationCache, RobotFields
from services.edge_server.robot_views import robot_grid
from services.edge_server.rrt import RrtMemory, rrt_frontiers
from services.edge_server.spatial_frontiers import (
    concat,
    detect_spatial_frontiers,
    grid_as_unexplored,
    subset,
)
from services.edge_server.submap_store import SubmapStore
from services.edge_server.unseen_floor import FULL_ENTROPY, unseen_floor_regions
from services.edge_server.visible_unknown import live_unknown, visible_unknown_m2

if TYPE_CHECKING:
    from services.edge_server.merge_runner import Merges
    from services.edge_server.merger import MapMerger


log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlanOutput:
    """What the node publishes for one edge tick, in this order, before its EdgeAck."""

    grid: OccupancyGrid | None
    frontiers: Frontiers
    goals: list[Goal]
    corrections: list[Correction] = field(default_factory=list)


@dataclass(frozen=True)
class Survey:
    """What a plan reads of the merged data (`snap` None: no data yet, nothing else)."""

    snap: GridSnapshot | None
    fields: RobotFields | None = None  # each robot's reachable cells and distance fields
    fs: FrontierSet | None = None  # the planner's frontier regions, with their goals
    fell_back: bool = False  # no 3D region was usable: `fs` are the grid's frontiers
    rrt: RrtMemory | None = None  # `rrt`: what its detector keeps, once the plan is made


SPACE_PLANNERS = ("space", "space-paper")

class EdgePlanner:
    """State of the edge server and its planning update."""

    def __init__(self, config: EdgeConfig, tick_s: float, merges: Merges | None = None
                 ) -> None:
        """`merges`: where the merger's update runs (merge_runner.py; None: in this thread,
        made on first use)."""
        self.config = config
        self.tick_s = tick_s
        self.store = SubmapStore(config.voxel_m)
        self._merges = merges
        self.merged = MergedMap(config.voxel_m)
        self.grid = MergedGrid(config)
        self.book = GoalBook(config)
        self.judge = CompletionJudge(config, tick_s)
        self.skipped_edge_ticks = 0  # since the last plan (plan_every_edge_ticks)
        self.scorer = make_scorer(config.planner, config)
        # before space_size_from_fraction is reached, the same scorer without the size factor
        self.early_scorer = (make_scorer(config.planner,
                                         config.model_copy(update={"space_size_exponent": 0.0}))
                             if config.planner == "space" and config.space_size_exponent > 0
                             and config.space_size_from_fraction < 1 else self.scorer)
        self.poses: dict[int, Pose2D] = {}
        self.dead: set[int] = set()
        self.last_grid: GridSnapshot | None = None
        # Alg. 1 kept up to date between plans (only voxels near new ones are recomputed)
        self.alg1 = IncrementalFrontiers(config.frontier_voxel_m, config.search_radius_m,
                                         config.density_threshold, config.variance_threshold_m2,
                                         config.frontier_z_max_m)
        self._alg1_version = -1
        self.rrt = RrtMemory()  # the RRT's tree and frontier points, between plans
        self._floor_regions = 0  # unseen floor patches in the last plan (logged on change)
        self.inflation = InflationCache()
        self.visits = VisitLog(config.weak_visit_range_m, math.radians(config.weak_visit_fov_deg))

    # -- inputs ----------------------------------------------------------------------------
    def on_submap(self, msg: Submap) -> None:
        self.store.apply(msg)
        if self._merges is not None:
            self._merges.submap(msg)

    def on_pose(self, msg: RobotPose) -> None:
        self.poses[msg.robot_id] = msg.pose_world

    def on_goal_status(self, msg: GoalStatus) -> None:
        self.book.on_status(msg)

    def on_agent(self, robot_id: int, alive: bool) -> None:
        """Liveliness: a dead agent's goal is freed and it gets no more goals."""
        if alive:
            self.dead.discard(robot_id)
        else:
            self.dead.add(robot_id)
            self.book.release(robot_id)

    # -- planning --------------------------------------------------------------------------
    def plan_due(self, edge_tick: int) -> bool:
        """Whether edge tick `edge_tick` needs a full plan (`plan_every_edge_ticks`): a robot
        that reached, lost or never had a goal gets one at the next edge tick regardless."""
        every = self.config.plan_every_edge_ticks
        if every == 1 or edge_tick % every == 0 or self.judge.complete:
            return True
        return any(r not in self.book.active for r in self.active_robots())

    def skip(self) -> None:
        """An edge tick acknowledged without a plan: viewpoints are still logged."""
        self.skipped_edge_ticks += 1
        self._record_views(self.active_robots())

    def _record_views(self, robots: list[int]) -> None:
        for r in robots:
            self.visits.record(r, self.poses[r].x, self.poses[r].y, self.poses[r].yaw)

    def active_robots(self) -> list[int]:
        return sorted(r for r in self.poses if r not in self.dead)

    @property
    def merges(self) -> Merges:
        """Where the merger's update runs, made on first use: the merger alone needs gtsam,
        whose import costs the edge 0.3 s of CPU at every start when `merge` is off."""
        if self._merges is None:
            from services.edge_server.merge_runner import LocalMerges
            from services.edge_server.merger import merger_params

            self._merges = LocalMerges(self.config.voxel_m, merger_params(self.config))
        return self._merges

    @property
    def merger(self) -> MapMerger:
        """The pose-graph merger of an in-thread runner (the benches time and read it)."""
        return self.merges.merger  # type: ignore[attr-defined]

    def close(self) -> None:
        """Release the merger's runner (its worker process, if any)."""
        if self._merges is not None:
            self._merges.close()

    def robot_grid(self, robot_id: int, tick: int) -> OccupancyGrid | None:
        """One robot's own grid on the merged grid's current bounds (map/robot_grid)."""
        return robot_grid(self.store, self.merged, self.grid, robot_id, tick)

    def _merge_and_survey(self, tick: int, robots: list[int], robot_xy: np.ndarray,
                          ) -> tuple[list[Correction], Survey]:
        """Pose-graph update (corrected poses move the submaps and go back to the agents),
        then the survey of the merged data. A runner in another process updates while this
        one surveys the data at the poses as they are; most updates correct nothing, and that
        survey stands. After a correction the grid's bounds go back to where they were and
        the survey is made again: P*, the grid and Alg. 1's sums end as if made once."""
        if not self.config.merge:
            self.merged.update(self.store)
            return [], self._survey(tick, robots, robot_xy)
        self.merges.start(self.store)
        survey, bounds = None, self.grid.bounds
        if self.merges.concurrent:
            self.merged.update(self.store)
            survey = self._survey(tick, robots, robot_xy)
        changed, estimates = self.merges.finish(self.store)
        for key in sorted(changed):
            self.store.set_pose(key, changed[key])
        if changed or survey is None:
            self.grid.bounds = bounds  # the bounds only grow: not from the poses before
            self.merged.update(self.store)
            survey = self._survey(tick, robots, robot_xy)
        return [Correction(robot_id=robot, tick=tick, submap_ids=np.array(ids, np.int32),
                           T_world_submap=poses) for robot, (ids, poses) in estimates.items()
                ], survey

    def _survey(self, tick: int, robots: list[int], robot_xy: np.ndarray) -> Survey:
        """The merged grid, each robot's reachable cells and the planner's frontier regions:
        what the plan reads of the merged data, changing nothing but caches and the grid's
        bounds (so it may be made again after a correction)."""
        # Robots widen the grid only once there is data (no grid at all before that).
        snap = self.grid.update(self.store, self.merged, robot_xy if self.store.submaps else None)
        if snap is None:
            return Survey(None)
        spec = snap.spec
        radius_cells = math.ceil(self.config.robot_radius_m / spec.resolution_m - 1e-9)
        traversable = snap.free & ~self.inflation(snap.occupied, radius_cells)
        starts = dict(zip(robots, spec.cell_of(robot_xy), strict=True))
        fields = RobotFields(traversable, starts, self.config.start_snap_m / spec.resolution_m,
                             int(self.config.start_island_m2 / spec.resolution_m**2))
        reachable = fields.reachable
        goal_edt = goal_transform(self.book.goal_cells(reachable, spec))
        fs, rrt = self._frontiers(tick, snap, traversable, reachable, fields, robot_xy, goal_edt)
        fell_back = self._fall_back_to_grid(fs, fields, tick)
        if fell_back:
            fallback = self.config.model_copy(
                update={"frontier_min_cells": self.config.space_grid_fallback_min_cells})
            fs = grid_as_unexplored(detect_frontiers(snap.free, snap.known, reachable, spec,
                                                     fallback, goal_edt))
        return Survey(snap, fields, fs, fell_back, rrt)

    def _point_frontiers(self) -> PointFrontiers | None:
        """Alg. 1 on P*, incrementally when P* is on the ϱ lattice (None: from scratch)."""
        if not np.isclose(self.merged.voxel_m, self.config.frontier_voxel_m):
            return None
        step = self.merged.version == self._alg1_version + 1
        added = self.merged.added_keys if step else None  # else: set difference
        if self.merged.version != self._alg1_version or self._alg1_version < 0:
            self._pf = self.alg1.update(self.merged.keys, added, self.merged.removed_keys)
            self._alg1_version = self.merged.version
        return self._pf

    def _frontiers(
        self, tick: int, snap: GridSnapshot, traversable: np.ndarray, reachable: np.ndarray,
        fields: RobotFields, robot_xy: np.ndarray, goal_edt: GoalTransform,
    ) -> tuple[FrontierSet, RrtMemory | None]:
        """Frontier regions of the configured planner, with goals among `reachable` cells
        (and, for `rrt`, what its detector keeps for the next plan)."""
        cfg, spec = self.config, snap.spec
        if cfg.planner in SPACE_PLANNERS:
            fs, _ = detect_spatial_frontiers(self.merged, snap.known, reachable, spec, cfg,
                                             self._point_frontiers(), goal_edt, snap.free)
            # F_w regions already seen from close by are not worth a trip (completion.py)
            fs = subset(fs, ~(fs.weak & self.visits.seen(fs.centroid_xy)))
            fs = self._without_tail_specks(fs, reachable, tick)
            fs = self._with_unseen_floor(fs, snap, reachable, goal_edt, tick)
            fs = self._with_grid_goals(fs, snap, reachable, goal_edt)
            imp = importance(tick * self.tick_s, robot_xy, fs.centroid_xy, fs.weak,
                             cfg.importance_lambda, cfg.importance_xi_s)
            border = (frontier_length_near(snap.free, snap.known, fs.goal_rc, spec,
                                           cfg.space_grid_view_m, cfg.frontier_min_cells)
                      if cfg.space_grid_gain_per_m > 0 else None)
            seen = (visible_unknown_m2(snap.occupied,
                                       live_unknown(snap.free, snap.known,
                                                    cfg.space_view_min_frontier_cells),
                                       fs.goal_rc, spec, cfg.space_view_range_m)
                    if cfg.space_view_gain_per_m2 > 0 and cfg.planner == "space" else None)
            return replace(fs, importance=imp, grid_frontier_m=border, unknown_view_m2=seen), None
        if cfg.planner == "rrt":
            starts = [fields.starts[r] for r in sorted(fields.starts)]
            return rrt_frontiers(traversable, snap.known, starts, reachable, spec, cfg,
                                 np.random.default_rng([cfg.seed, tick]), self.rrt, goal_edt)
        return detect_frontiers(snap.free, snap.known, reachable, spec, cfg, goal_edt), None

    def _unexplored_voxels(self, fs: FrontierSet, reachable: np.ndarray, tick: int) -> int:
        """The assignable F_u regions' voxels, together."""
        if not len(fs):
            return 0
        assert fs.weak is not None
        goal_rc = fs.goal_rc
        usable = (self.book.allowed(fs, tick) & reachable[goal_rc[:, 0], goal_rc[:, 1]]
                  & ~fs.weak)
        return int(fs.sizes[usable].sum())

    def _without_tail_specks(self, fs: FrontierSet, reachable: np.ndarray,
                             tick: int) -> FrontierSet:
        """`space` with `space_tail_min_voxels`: once the assignable F_u regions hold at most
        `space_tail_fraction` of the merged map, those under that many voxels are no goal:
        late in a mission a robot crossed the house for a speck worth a tenth of a percent."""
        cfg = self.config
        if (cfg.planner != "space" or cfg.space_tail_min_voxels <= 0 or not len(fs)
                or self._unexplored_voxels(fs, reachable, tick)
                > cfg.space_tail_fraction * len(self.merged)):
            return fs
        weak = fs.weak if cfg.space_tail_weak else np.zeros(len(fs), bool)
        return subset(fs, weak | (~fs.weak & (fs.sizes >= cfg.space_tail_min_voxels)))

    def _scorer_for(self, fs: FrontierSet, reachable: np.ndarray, tick: int) -> Scorer:
        """The scorer with its size factor once the assignable F_u voxels are down to
        `space_size_from_fraction` of the merged map, without it before: late in a mission a
        large region left across the house waited for specks and made the last trip."""
        if (self.early_scorer is not self.scorer and self._unexplored_voxels(fs, reachable, tick)
                > self.config.space_size_from_fraction * len(self.merged)):
            return self.early_scorer
        return self.scorer

    def _with_unseen_floor(self, fs: FrontierSet, snap: GridSnapshot, reachable: np.ndarray,
                           goal_edt: GoalTransform, tick: int) -> FrontierSet:
        """`space` with `floor_unseen_min_m2`: the unseen floor patches join the regions
        (unseen_floor.py), always or once the assignable F_u voxels are down to the tail's
        fraction of the map; in that endgame the grid's long frontiers join them too
        (`floor_endgame_grid_frontiers`), so the tail rule does not end a mission beside a
        hole in the grid that the fallback would have sent a robot to."""
        cfg = self.config
        if cfg.planner != "space" or cfg.floor_unseen_min_m2 <= 0:
            return fs
        endgame = (self._unexplored_voxels(fs, reachable, tick)
                   <= cfg.complete_unexplored_fraction * len(self.merged))
        if cfg.floor_unseen_when == "endgame" and not endgame:
            return fs
        extra = unseen_floor_regions(self.merged.keys, self.merged.voxel_m, snap.free,
                                     reachable, snap.spec, cfg, goal_edt)
        floor_m2 = extra.sizes.sum() * snap.spec.resolution_m**2
        if endgame and cfg.floor_endgame_grid_frontiers:
            long_only = cfg.model_copy(
                update={"frontier_min_cells": cfg.space_grid_fallback_min_cells})
            grid = detect_frontiers(snap.free, snap.known, reachable, snap.spec, long_only,
                                    goal_edt)
            extra = concat(extra, replace(grid_as_unexplored(grid),
                                          gain=np.full(len(grid), FULL_ENTROPY)))
        if len(extra) != self._floor_regions:
            log.info("t=%.1f s: %d endgame regions (unseen floor %.1f m²)",
                     tick * self.tick_s, len(extra), floor_m2)
            self._floor_regions = len(extra)
        return concat(fs, extra) if len(extra) else fs

    def _with_grid_goals(self, fs: FrontierSet, snap: GridSnapshot, reachable: np.ndarray,
                         goal_edt: GoalTransform) -> FrontierSet:
        """`space` with `space_grid_goals_min_cells`: the grid's frontier clusters of that many
        cells join the 3D regions as goals worth no information of their own: what they are
        worth is the unknown floor in sight of them (`space_view_gain_per_m2`) and the regions
        near them. Their cells count toward the tail's share, as the endgame's do."""
        cfg = self.config
        if cfg.planner != "space" or cfg.space_grid_goals_min_cells <= 0:
            return fs
        grid = detect_frontiers(snap.free, snap.known, reachable, snap.spec,
                                cfg.model_copy(update={
                                    "frontier_min_cells": cfg.space_grid_goals_min_cells}),
                                goal_edt)
        if not len(grid):
            return fs
        return concat(fs, replace(grid_as_unexplored(grid), gain=np.zeros(len(grid))))

    def _fall_back_to_grid(self, fs: FrontierSet, fields: RobotFields, tick: int) -> bool:
        """SPACE planners with `space_grid_fallback`: no 3D region is usable this plan."""
        if not self.config.space_grid_fallback or self.config.planner not in SPACE_PLANNERS:
            return False
        goal_rc = fs.goal_rc
        usable = self.book.allowed(fs, tick) & fields.reachable[goal_rc[:, 0], goal_rc[:, 1]]
        return not usable.any()

    def plan(self, tick: int) -> PlanOutput:
        robots = self.active_robots()
        robot_xy = np.array([[self.poses[r].x, self.poses[r].y] for r in robots]).reshape(-1, 2)
        self._record_views(robots)
        edge_ticks, self.skipped_edge_ticks = 1 + self.skipped_edge_ticks, 0
        corrections, survey = self._merge_and_survey(tick, robots, robot_xy)
        snap = self.last_grid = survey.snap
        if survey.rrt is not None:
            self.rrt = survey.rrt
        if snap is None:
            complete = self.judge.update(tick, 0, 0, edge_ticks=edge_ticks)
            return PlanOutput(None, frontiers_message(tick, empty_frontiers((0, 0)), complete, {},
                                                      self.config.grid_resolution_m), [],
                              corrections)
        assert survey.fields is not None and survey.fs is not None
        spec, fs, reachable = snap.spec, survey.fs, survey.fields.reachable
        poses = np.array([[self.poses[r].x, self.poses[r].y, self.poses[r].yaw] for r in robots])
        result = self.book.plan(tick, robots, survey.fields, fs, spec,
                                self._scorer_for(fs, reachable, tick), poses)
        fraction = (None if survey.fell_back or self.config.planner != "space"  # as written
                    else result.unexplored_voxels / max(len(self.merged), 1))
        log.debug("plan tick %d: unexplored fraction %s", tick, fraction)
        complete = self.judge.update(tick, result.assignable, int(snap.known.sum()), fraction,
                                     edge_ticks)
        grid_msg = OccupancyGrid(tick=tick, resolution_m=spec.resolution_m, origin_x=spec.origin_x,
                                 origin_y=spec.origin_y, cells=snap.cells)
        return PlanOutput(grid_msg, frontiers_message(tick, fs, complete, result.assigned,
                                                      spec.resolution_m), result.new_goals,
                          corrections)
