"""The robot agent process: bus wiring around `AgentCore` (lockstep handshake: ARCHITECTURE.md)."""

from __future__ import annotations

import logging
import threading

import numpy as np

from schemas.messages import (
    Correction,
    Goal,
    Inventory,
    Message,
    OccupancyGrid,
    Odometry,
    RgbdFrame,
    RobotPose,
)
from services.common.access import identity
from services.common.bus import Bus, Inbound, Presence, connect
from services.common.signals import stop_on_signals
from services.config import SpacemapConfig
from services.robot_agent.agent import AgentCore

log = logging.getLogger(__name__)

POLL_S = 0.1
REPORT_EVERY_TICKS = 500


def _subscribe(bus: Bus, robot_id: int) -> None:
    k = bus.keys
    bus.subscribe(k.rgbd(robot_id), RgbdFrame)
    bus.subscribe(k.odom(robot_id), Odometry)
    bus.subscribe(k.goal(robot_id), Goal)
    bus.subscribe(k.correction(robot_id), Correction)
    bus.subscribe(k.map_grid(), OccupancyGrid)
    bus.subscribe(k.any_robot("pose"), RobotPose, channel=True)  # applied at the next odometry


def _out_key(bus: Bus, robot_id: int, topic: str) -> str:
    k = bus.keys
    by_topic = {"pose": k.pose, "submap": k.submap, "goal_status": k.goal_status,
                "cmd_vel": k.cmd_vel}
    return by_topic[topic](robot_id)


# Messages stamped with the tick they were made at. One made at tick k by a teammate races
# this agent's Odometry(k), but always arrives before Odometry(k + 1) (the sim waits for every
# answer to k first), so applying them only at a later tick is deterministic. The edge's
# outputs of tick k are waited for only at tick k + L (L = the edge lag, sim.edge_lag_ticks),
# so they are applied from tick k + L + 1 on, whenever they arrive before that.
TICKED = (Goal, Correction, OccupancyGrid, RobotPose)
FROM_EDGE = (Goal, Correction, OccupancyGrid)


def due_at(msg: Message, edge_lag: int) -> int:
    """The first tick whose Odometry applies `msg`."""
    lag = edge_lag if isinstance(msg, FROM_EDGE) else 0
    return msg.tick + lag + 1  # type: ignore[attr-defined]


def defers(tick: int, edge_every_ticks: int | None) -> bool:
    """Whether tick k's late work (AgentCore.finish_tick) may follow CmdVel(k) out: not
    when k + 1 is an edge tick, whose Clock the simulator sends as soon as it has every
    CmdVel(k), so a Submap delta stamped k would race it to the edge (None: never)."""
    return edge_every_ticks is not None and (tick + 1) % edge_every_ticks != 0


def handle(
    bus: Bus, core: AgentCore, item: Inbound | Presence, tick_s: float, pending: list[Message],
    edge_lag: int = 0, edge_every_ticks: int | None = None,
) -> None:
    """Feed one inbound item to the core; on Odometry(k), publish the tick's outputs
    (with `edge_every_ticks`, the work CmdVel(k) does not need after it: `defers`)."""
    if isinstance(item, Presence):
        if item.role == "edge":
            core.on_edge_presence(item.alive)
        return
    msg = item.message
    if isinstance(msg, TICKED):
        pending.append(msg)
    elif isinstance(msg, RgbdFrame):
        core.on_rgbd(msg)
    elif isinstance(msg, Odometry):
        due = [m for m in pending if due_at(m, edge_lag) <= msg.tick]
        pending[:] = [m for m in pending if due_at(m, edge_lag) > msg.tick]
        for earlier in due:
            _apply(core, earlier)
        outs = core.on_odometry(msg, defer=defers(msg.tick, edge_every_ticks))
        for out in outs:  # CmdVel(k) is last
            bus.publish(_out_key(bus, core.robot_id, out.topic), out.message)
        finish(bus, core)
        if msg.tick and msg.tick % REPORT_EVERY_TICKS == 0:
            sim_s = msg.tick * tick_s
            key = bus.keys.submap(core.robot_id)
            log.info("robot %d tick %d: submap traffic %.1f kB per sim second; "
                     "registrations %s; %d ticks ran ahead of the last frame's mapping",
                     core.robot_id, msg.tick, bus.bytes_out[key] / 1000.0 / sim_s,
                     dict(core.localizer.outcomes), core.ran_ahead)
            if core.localizer.odometry is not None:
                cal = core.localizer.odometry.calibration
                log.info("robot %d tick %d: odometry errors %s from %d segments (%d left out, "
                         "%.1f pooled over the fleet); fleet prior %s segments", core.robot_id,
                         msg.tick, cal.errors, cal.n_used, cal.n_rejected,
                         cal.pooled_segments(), cal.fleet_prior_weight)
            walls = core.localizer.walls
            if walls is not None:
                log.info("robot %d tick %d: wall heading: world direction %s (own %s, %d "
                         "teammates'), %d fused, %d rejected, %d re-acquired", core.robot_id,
                         msg.tick, _degrees(walls.world_rad), _degrees(walls.own_rad),
                         len(walls.team), walls.n_fused, walls.n_rejected, walls.n_reacquired)


def finish(bus: Bus, core: AgentCore) -> None:
    """What the commands did not need, while the simulator steps on, step by step until an
    input waits (Odometry(k + 1) first: an odometry-only tick runs ahead of the work,
    AgentCore._runs_ahead); the rest waits for the next call."""
    if core.unfinished:
        for out in core.finish_tick(until=bus.input_waiting):
            bus.publish(_out_key(bus, core.robot_id, out.topic), out.message)


def _degrees(angle_rad: float | None) -> str:
    return "unknown" if angle_rad is None else f"{np.degrees(angle_rad):+.2f}°"


def _apply(core: AgentCore, msg: Message) -> None:
    if isinstance(msg, Goal):
        core.on_goal(msg)
    elif isinstance(msg, Correction):
        core.on_correction(msg)
    elif isinstance(msg, OccupancyGrid):
        core.on_grid(msg)
    elif isinstance(msg, RobotPose):
        core.on_pose(msg)


def main(config: SpacemapConfig, robot_id: int) -> None:
    """Run robot `robot_id`'s agent until SIGTERM or SIGINT."""
    stop = stop_on_signals()
    core = AgentCore(config.agent, robot_id, config.sim.tick_s, team_size=config.sim.robots - 1)
    with connect(config.bus, identity("agent", robot_id)) as bus:
        lock = threading.Lock()  # the inventory queryable runs on a zenoh thread
        pending: list[Message] = []
        last_tick = [0]

        def answer_inventory(_body: bytes) -> Inventory:
            with lock:
                return core.inventory(last_tick[0])

        _subscribe(bus, robot_id)
        bus.serve(bus.keys.inventory(robot_id), answer_inventory)
        bus.watch_liveliness()  # the edge going and coming back (issue 7)
        bus.declare_alive("agent", robot_id)
        log.info("agent %d up on %s", robot_id, config.bus.connect)
        while not stop.is_set():
            item = bus.poll(timeout=POLL_S)
            with lock:
                if item is not None:
                    handle(bus, core, item, config.sim.tick_s, pending,
                           config.sim.edge_lag_ticks, config.sim.edge_every_ticks)
                finish(bus, core)  # work an input cut short, now that none waits
                if isinstance(item, Inbound) and isinstance(item.message, Odometry):
                    last_tick[0] = item.message.tick
    log.info("agent %d stopped", robot_id)
