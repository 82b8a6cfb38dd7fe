"""The edge server process: bus wiring around `EdgePlanner` (lockstep: ARCHITECTURE.md).

On Clock(k) with k % sim.edge_every_ticks == 0 the edge plans with everything read so far and
publishes map/grid, map/frontiers, goals and corrections, then EdgeAck(k) last (the simulator
waits for it at tick k + sim.edge_pipeline_ticks). The inbox is handled strictly in order, so a
plan sees exactly the messages of ticks < k, however long it takes; wall time is only logged.
The `map/cloud` queryable runs on a zenoh thread, so it and the main loop share one lock around
the planner.
"""

from __future__ import annotations

import logging
import statistics
import threading
import time
from typing import TYPE_CHECKING

import numpy as np

from schemas import decode
from schemas.messages import (
    Clock,
    Cloud,
    CloudRequest,
    EdgeAck,
    GoalStatus,
    GridRequest,
    Inventory,
    OccupancyGrid,
    RobotPose,
    Submap,
)
from services.common.access import identity
from services.common.bus import Bus, Inbound, Presence, connect
from services.common.heap import keep_freed_memory
from services.common.inventory import inventory_of
from services.common.signals import stop_on_signals
from services.config import SpacemapConfig
from services.edge_server.config import EdgeConfig
from services.edge_server.planner import EdgePlanner, PlanOutput

if TYPE_CHECKING:
    from services.edge_server.merge_runner import Merges

log = logging.getLogger(__name__)

POLL_S = 0.1
REPORT_EVERY_PLANS = 50


def _subscribe(bus: Bus) -> None:
    k = bus.keys
    bus.subscribe(k.clock(), Clock)
    bus.subscribe(k.any_robot("submap"), Submap)
    bus.subscribe(k.any_robot("pose"), RobotPose, wake=False)  # read at plan time only
    bus.subscribe(k.any_robot("goal_status"), GoalStatus)
    bus.watch_liveliness()


def cloud_reply(planner: EdgePlanner, tick: int, body: bytes, max_bytes: int) -> Cloud:
    """P* (robot_id −1 or an empty body) or one robot's own map for a `map/cloud` query;
    with `since_version`, keyed and versioned, and only what changed when it can be."""
    request = decode(body, CloudRequest, max_bytes) if body else CloudRequest()
    merged = planner.merged
    if request.since_version is not None:
        view = merged.cloud_view(request.robot_id, request.since_version)
        return Cloud(tick=tick, robot_id=request.robot_id, points_world=view.points_world,
                     colors=view.colors, robot_ids=view.robot_ids, voxel_keys=view.keys,
                     version=view.version, delta=view.delta)
    if request.robot_id < 0:
        return Cloud(tick=tick, points_world=merged.points_world.astype(np.float32),
                     colors=merged.colors, robot_ids=merged.robot_ids)
    points, colors = merged.robot_cloud(request.robot_id)
    return Cloud(tick=tick, robot_id=request.robot_id, points_world=points.astype(np.float32),
                 colors=colors, robot_ids=np.full(len(points), request.robot_id, np.uint8))


def robot_grid_reply(planner: EdgePlanner, tick: int, body: bytes, max_bytes: int
                     ) -> OccupancyGrid:
    """One robot's own grid for a `map/robot_grid` query (empty grid before any data)."""
    request = decode(body, GridRequest, max_bytes)
    grid = planner.robot_grid(request.robot_id, tick)
    if grid is None:
        return OccupancyGrid(tick=tick, resolution_m=planner.config.grid_resolution_m,
                             origin_x=0.0, origin_y=0.0, cells=np.full((1, 1), -1, np.int8))
    return grid


class EdgeNode:
    """The edge's loop state: planner, lock, last planned tick."""

    def __init__(self, bus: Bus, config: SpacemapConfig) -> None:
        self.bus = bus
        self.config = config
        edge = config.edge
        if "seed" not in edge.model_fields_set:
            edge = edge.model_copy(update={"seed": config.sim.seed})  # the mission seed
        self.planner = EdgePlanner(edge, config.sim.tick_s, merges_for(edge))
        self.lock = threading.Lock()
        self.last_tick = 0
        self.plans = 0
        self.plan_ms: list[float] = []  # wall time, for the log only
        self.tick_ms: list[float] = []
        self.all_plan_ms: list[float] = []
        self.cloud_queries = 0
        self.unplanned = 0  # edge ticks acknowledged without a plan (edge.plan_every_edge_ticks)
        self.cloud_lock_s = 0.0  # wall time map/cloud answers held the lock (stalls the clock)

    def serve_cloud(self, body: bytes) -> Cloud:
        with self.lock:
            t0 = time.perf_counter()  # for the log only
            reply = cloud_reply(self.planner, self.last_tick, body,
                                self.config.bus.max_array_bytes)
            self.cloud_queries += 1
            self.cloud_lock_s += time.perf_counter() - t0
            return reply

    def serve_inventory(self, _body: bytes) -> Inventory:
        """Every submap merged so far, per robot (issue 7's nothing-lost check)."""
        with self.lock:
            items: dict[int, list[tuple[int, int, int]]] = {}
            for sub in self.planner.store.ordered():
                items.setdefault(sub.robot_id, []).append(
                    (sub.epoch, sub.submap_id, len(sub.keys)))
            return inventory_of(items, self.last_tick)

    def serve_robot_grid(self, body: bytes) -> OccupancyGrid:
        with self.lock:
            return robot_grid_reply(self.planner, self.last_tick, body,
                                    self.config.bus.max_array_bytes)

    def handle(self, item: Inbound | Presence) -> None:
        if isinstance(item, Presence):
            if item.role == "agent" and item.ident.isdigit():
                with self.lock:
                    self.planner.on_agent(int(item.ident), item.alive)
                log.info("agent %s %s", item.ident, "alive" if item.alive else "gone")
            return
        msg = item.message
        with self.lock:
            if isinstance(msg, Submap):
                self.planner.on_submap(msg)
            elif isinstance(msg, RobotPose):
                self.planner.on_pose(msg)
            elif isinstance(msg, GoalStatus):
                self.planner.on_goal_status(msg)
        every = self.config.sim.edge_every_ticks
        if isinstance(msg, Clock) and msg.tick % every == 0:
            with self.lock:
                due = self.planner.plan_due(msg.tick // every)
                if not due:
                    self.planner.skip()
            if due:
                self.plan_and_publish(msg.tick)
            else:
                self.unplanned += 1
                self.bus.publish(self.bus.keys.edge_ack(), EdgeAck(tick=msg.tick))

    def plan_and_publish(self, tick: int) -> None:
        t0 = time.perf_counter()  # for the log only
        with self.lock:
            out = self.planner.plan(tick)
            self.last_tick = tick
        t_plan = time.perf_counter() - t0
        self.publish(out)
        self.bus.publish(self.bus.keys.edge_ack(), EdgeAck(tick=tick))  # last
        self.plans += 1
        self.plan_ms.append(1000 * t_plan)
        self.all_plan_ms.append(1000 * t_plan)
        self.tick_ms.append(1000 * (time.perf_counter() - t0))
        if self.plans % REPORT_EVERY_PLANS == 0:
            log.info("tick %d: %d voxels, %d frontiers, assigned %s, complete %s, plan median %.1f"
                     " ms (max %.1f), plan + publish median %.1f ms over the last %d plans",
                     tick, len(self.planner.merged), len(out.frontiers.frontiers),
                     out.frontiers.assigned, out.frontiers.complete,
                     statistics.median(self.plan_ms), max(self.plan_ms),
                     statistics.median(self.tick_ms), len(self.plan_ms))
            self.plan_ms.clear()
            self.tick_ms.clear()

    def publish(self, out: PlanOutput) -> None:
        k = self.bus.keys
        if out.grid is not None:
            self.bus.publish(k.map_grid(), out.grid)
        self.bus.publish(k.map_frontiers(), out.frontiers)
        for goal in out.goals:
            self.bus.publish(k.goal(goal.robot_id), goal)
        for corr in out.corrections:
            self.bus.publish(k.correction(corr.robot_id), corr)


def merges_for(edge: EdgeConfig) -> Merges | None:
    """A worker process for the merger's updates when the config asks for one."""
    if not (edge.merge and edge.merge_worker):
        return None
    from services.edge_server.merge_runner import WorkerMerges
    from services.edge_server.merger import merger_params

    return WorkerMerges(edge.voxel_m, merger_params(edge))


def main(config: SpacemapConfig) -> None:
    """Run the edge server until SIGTERM or SIGINT."""
    keep_freed_memory()  # a plan frees and allocates arrays of hundreds of MB
    stop = stop_on_signals()
    with connect(config.bus, identity("edge")) as bus:
        node = EdgeNode(bus, config)
        _subscribe(bus)
        bus.serve(bus.keys.map_cloud(), node.serve_cloud)
        bus.serve(bus.keys.map_robot_grid(), node.serve_robot_grid)
        bus.serve(bus.keys.map_inventory(), node.serve_inventory)
        bus.declare_alive("edge", 0)
        log.info("edge up on %s, planner %s", config.bus.connect, config.edge.planner)
        complete_logged = False
        while not stop.is_set():
            item = bus.poll(timeout=POLL_S)
            if item is not None:
                node.handle(item)
            if node.planner.judge.complete and not complete_logged:
                complete_logged = True
                log.info("exploration complete at tick %s (%d plans: median %.1f ms; %d edge "
                         "ticks unplanned; goals not kept: %s)", node.planner.judge.complete_tick,
                         node.plans, statistics.median(node.all_plan_ms), node.unplanned,
                         dict(node.planner.book.drops))
    log.info("edge stopped (submap seq gaps: %s; %d map/cloud queries held the lock %.2f s)",
             dict(node.planner.store.seq_gaps), node.cloud_queries, node.cloud_lock_s)
    if config.edge.merge:
        log.info("merger: %s", node.planner.merges.summary())
    node.planner.close()

