"""The launcher's view of a running mission: clock, map, frontiers, robots, traffic, truth.

The monitor is the evaluator's listener; it is the only process besides the simulator that
reads `eval/` keys, and no service reads what it collects.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter, OrderedDict
from dataclasses import dataclass, field
from typing import Protocol

from schemas import messages as m
from schemas.codec import decode, peek_tick
from schemas.errors import DecodeError
from services.common.bus import Bus, Inbound, Presence

log = logging.getLogger(__name__)

# robot topics whose bytes are the mission's traffic, and what each must decode as
COUNTED: dict[str, type[m.Message]] = {
    "pose": m.RobotPose, "submap": m.Submap, "cmd_vel": m.CmdVel, "goal_status": m.GoalStatus}


@dataclass
class RobotTrack:
    """What the monitor knows of one robot."""

    gt_stamps_ns: list[int] = field(default_factory=list)
    gt_xyyaw: list[tuple[float, float, float]] = field(default_factory=list)
    est_stamps_ns: list[int] = field(default_factory=list)
    est_xyyaw: list[tuple[float, float, float]] = field(default_factory=list)
    state: str = ""
    goals_assigned: int = 0
    goals_reached: int = 0
    goal_statuses: Counter[str] = field(default_factory=Counter)
    # goals, statuses and navigation state changes with their ticks (events.jsonl)
    events: list[dict] = field(default_factory=list)


@dataclass
class Snapshot:
    """One row of the run's time series."""

    sim_time_s: float
    known_cells: int
    frontiers: int


class MessageSink(Protocol):
    """A reader of every message the monitor handles (the recorders, the live view)."""

    def on_message(self, msg: m.Message) -> None: ...


RECENT = 64  # edge ticks kept (6.4 s of sim time at the defaults)


def _remember(store: OrderedDict, tick: int, value: object) -> None:
    store[tick] = value
    while len(store) > RECENT:
        store.popitem(last=False)


class Monitor:
    """Subscribes to everything a run report needs; call `pump()` from the main loop."""

    def __init__(self, bus: Bus, robots: int, camera_every_ticks: int = 0,
                 declare: bool = True) -> None:
        """`camera_every_ticks` > 0: also read the robots' RGB-D frames of every such tick
        (for the live view only: they are the bus's heaviest traffic, so the others are
        dropped before decoding); `declare`: hold the `alive/monitor/0` token (the recorder
        does; a second watcher such as `spacemap view` does not)."""
        self.bus = bus
        self.robots = robots
        self.tracks = {i: RobotTrack() for i in range(robots)}
        self.clock: m.Clock | None = None
        self.grid: m.OccupancyGrid | None = None
        self.frontiers: m.Frontiers | None = None
        self.complete_tick: int | None = None  # first edge tick that declared completion
        # recent edge outputs by tick, so a time-series sample can pair the cloud of edge
        # tick k with the grid and frontiers of the same tick
        self.recent_grids: OrderedDict[int, m.OccupancyGrid] = OrderedDict()
        self.recent_frontiers: OrderedDict[int, int] = OrderedDict()
        # edge ticks whose plan is fully out: the edge acknowledges a tick after its grid,
        # frontiers, goals and corrections
        self.recent_acks: OrderedDict[int, bool] = OrderedDict()
        self.alive: set[tuple[str, str]] = set()
        self.ever_alive: set[tuple[str, str]] = set()
        self.series: list[Snapshot] = []
        self._bytes: Counter[tuple[int, int]] = Counter()  # (robot, tick) → payload bytes
        self.bad_taps: Counter[tuple[str, str]] = Counter()  # (key, reason)
        self.sinks: list[MessageSink] = []
        self._bytes_lock = threading.Lock()
        keys = bus.keys
        bus.subscribe(keys.clock(), m.Clock)
        bus.subscribe(keys.map_grid(), m.OccupancyGrid)
        bus.subscribe(keys.map_frontiers(), m.Frontiers)
        bus.subscribe(keys.edge_ack(), m.EdgeAck)
        # every robot's two poses per tick wait for the next clock to be handled
        bus.subscribe(keys.any_robot("pose"), m.RobotPose, wake=False)
        bus.subscribe(keys.any_robot("goal"), m.Goal)
        bus.subscribe(keys.any_robot("goal_status"), m.GoalStatus)
        bus.subscribe(keys.gt_pose("*"), m.GtPose, wake=False)
        if camera_every_ticks > 0:
            def keep(payload: bytes) -> bool:  # an undecodable tick goes on, to be refused
                tick = peek_tick(payload)
                return tick is None or tick % camera_every_ticks == 0

            bus.subscribe(keys.any_robot("rgbd"), m.RgbdFrame, keep)
        for topic, kind in COUNTED.items():
            bus.tap(keys.any_robot(topic), lambda key, payload, kind=kind: self._count(
                key, payload, kind))
        bus.watch_liveliness()
        if declare:
            bus.declare_alive("monitor", 0)

    def _count(self, key: str, payload: bytes, kind: type[m.Message]) -> None:
        """Bytes per (robot, tick): the tick, not the arrival time, decides what counts, so a
        lockstep run's totals do not depend on which of the last tick's messages arrived before
        the run was read out. Only messages the robot's own processes would accept count
        (valid, of the key's kind, naming the key's robot): a bad message is no traffic."""
        try:
            robot = self.bus.keys.robot_id(key)
            msg = decode(payload, kind)
            if getattr(msg, "robot_id", robot) != robot:
                raise DecodeError("wrong robot", f"{msg.robot_id} on {key}")
        except (ValueError, DecodeError) as exc:
            reason = exc.reason if isinstance(exc, DecodeError) else "bad key"
            self.bad_taps[(key, reason)] += 1
            if self.bad_taps[(key, reason)] == 1:
                log.warning("dropped a message on %s (%s): not counted", key, reason)
            return
        tick = msg.tick
        with self._bytes_lock:
            self._bytes[(robot, tick)] += len(payload)

    def bytes_per_robot(self, before_tick: int | None = None) -> dict[int, int]:
        """Payload bytes each robot published for ticks < `before_tick` (all when None)."""
        with self._bytes_lock:
            total: Counter[int] = Counter()
            for (robot, tick), n in self._bytes.items():
                if before_tick is None or tick < before_tick:
                    total[robot] += n
        return {i: int(total.get(i, 0)) for i in range(self.robots)}

    def tracks_reach(self, stamp_ns: int) -> bool:
        """Every robot's ground truth and estimate have arrived up to `stamp_ns`."""
        return len(self.tracks) >= self.robots and all(
            s and s[-1] >= stamp_ns for t in self.tracks.values()
            for s in (t.gt_stamps_ns, t.est_stamps_ns))

    def trim_to_common_tick(self, end_stamp_ns: int | None = None) -> None:
        """Cut both tracks of every robot to the last stamp that every robot's ground truth and
        estimate reached (each stream arrives in order), so a run's files and its ATE do not
        depend on which of the final tick's messages arrived before shutdown."""
        ends = [s[-1] for t in self.tracks.values() for s in (t.gt_stamps_ns, t.est_stamps_ns)
                if s] + ([end_stamp_ns] if end_stamp_ns is not None else [])
        if not ends:
            return
        end = min(ends)
        for t in self.tracks.values():
            keep = sum(1 for s in t.gt_stamps_ns if s <= end)
            del t.gt_stamps_ns[keep:], t.gt_xyyaw[keep:]
            keep = sum(1 for s in t.est_stamps_ns if s <= end)
            del t.est_stamps_ns[keep:], t.est_xyyaw[keep:]

    def at_tick(self, tick: int) -> tuple[m.OccupancyGrid | None, int]:
        """(grid, frontier count) the edge published at `tick`, else the latest ones."""
        grid = self.recent_grids.get(tick, self.grid)
        fr = self.recent_frontiers.get(tick)
        if fr is None:
            fr = len(self.frontiers.frontiers) if self.frontiers else 0
        return grid, fr

    @property
    def sim_time_s(self) -> float:
        return self.clock.stamp_ns * 1e-9 if self.clock else 0.0

    def pump(self, timeout: float) -> None:
        """Handle whatever arrives within `timeout` seconds (at least one poll)."""
        item = self.bus.poll(timeout)
        while item is not None:
            self._handle(item)
            item = self.bus.poll(0) if not self.bus.inbox.empty() else None

    def _handle(self, item: Inbound | Presence) -> None:
        if isinstance(item, Presence):
            member = (item.role, item.ident)
            if item.alive:
                self.alive.add(member)
                self.ever_alive.add(member)
            else:
                self.alive.discard(member)
            return
        self._update(item.message)
        for sink in self.sinks:
            sink.on_message(item.message)

    def _update(self, msg: m.Message) -> None:
        if isinstance(msg, m.Clock):
            self.clock = msg
        elif isinstance(msg, m.OccupancyGrid):
            self.grid = msg
            _remember(self.recent_grids, msg.tick, msg)
            self._snapshot()
        elif isinstance(msg, m.Frontiers):
            self.frontiers = msg
            _remember(self.recent_frontiers, msg.tick, len(msg.frontiers))
            if msg.complete and self.complete_tick is None:
                self.complete_tick = msg.tick
        elif isinstance(msg, m.EdgeAck):
            _remember(self.recent_acks, msg.tick, True)
        elif isinstance(msg, m.GtPose) and msg.robot_id in self.tracks:
            t = self.tracks[msg.robot_id]
            t.gt_stamps_ns.append(msg.stamp_ns)
            t.gt_xyyaw.append((msg.pose_world.x, msg.pose_world.y, msg.pose_world.yaw))
        elif isinstance(msg, m.RobotPose) and msg.robot_id in self.tracks:
            t = self.tracks[msg.robot_id]
            t.est_stamps_ns.append(msg.stamp_ns)
            t.est_xyyaw.append((msg.pose_world.x, msg.pose_world.y, msg.pose_world.yaw))
            if msg.state != t.state:
                t.events.append({"tick": msg.tick, "kind": "state", "state": msg.state})
            t.state = msg.state
        elif isinstance(msg, m.Goal) and msg.robot_id in self.tracks:
            t = self.tracks[msg.robot_id]
            t.goals_assigned += not (msg.cancel or msg.queued)
            t.events.append({"tick": msg.tick, "kind": "goal", "goal_id": msg.goal_id,
                             "x": msg.x, "y": msg.y, "frontier_class": msg.frontier_class,
                             "revenue": msg.revenue, "cancel": msg.cancel,
                             "queued": msg.queued, "look_xy": msg.look_xy})
        elif isinstance(msg, m.GoalStatus) and msg.robot_id in self.tracks:
            t = self.tracks[msg.robot_id]
            t.goal_statuses[msg.status] += 1
            t.goals_reached += msg.status == "reached"
            t.events.append({"tick": msg.tick, "kind": "status", "goal_id": msg.goal_id,
                             "status": msg.status, "reason": msg.reason})

    def _snapshot(self) -> None:
        assert self.grid is not None
        known = int((self.grid.cells >= 0).sum())
        n_frontiers = len(self.frontiers.frontiers) if self.frontiers else 0
        self.series.append(Snapshot(self.sim_time_s, known, n_frontiers))
