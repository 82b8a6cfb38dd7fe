"""The simulator process over a real zenoh router: real-time pacing and lockstep liveliness.

A router runs in a thread on a free port; `node.main` runs in another thread; the test plays
the agents through its own bus session.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import pytest

from schemas.messages import Clock, CmdVel, EdgeAck, GtPose, Odometry
from services.common.bus import Bus, BusConfig, Inbound, connect
from services.common.router import run_router
from services.config import SpacemapConfig
from services.simulator import node


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def sim_over_router(sim_overrides: dict, prefix: str) -> Iterator[Bus]:
    """Router + simulator threads; yields the test's own bus session on the same router."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    stop_router, stop_sim = threading.Event(), threading.Event()
    router = threading.Thread(target=run_router, args=([endpoint], stop_router), daemon=True)
    router.start()
    bus_cfg = BusConfig(connect=endpoint, prefix=prefix, connect_timeout_s=5.0)
    config = SpacemapConfig.model_validate(
        {"bus": bus_cfg.model_dump(), "sim": {"world": "bookstore", "width": 32, "height": 24,
                                              "wait_for_peers_s": 0.5, **sim_overrides}}
    )
    sim = threading.Thread(target=node.main, args=(config, stop_sim), daemon=True)
    try:
        with connect(bus_cfg) as bus:
            sim.start()
            yield bus
    finally:
        stop_sim.set()
        sim.join(timeout=10)
        stop_router.set()
        router.join(timeout=10)
    assert not sim.is_alive(), "simulator thread did not stop"


@dataclass
class Seen:
    """What the test's session received, by kind."""

    clocks: list[tuple[float, int]] = field(default_factory=list)  # (wall s, tick)
    gt: dict[int, list[tuple[int, tuple[float, float, float]]]] = field(default_factory=dict)
    odom_ticks: dict[int, list[int]] = field(default_factory=dict)

    def record(self, item: object) -> object | None:
        if not isinstance(item, Inbound):
            return None
        msg = item.message
        if isinstance(msg, Clock):
            self.clocks.append((time.monotonic(), msg.tick))
        elif isinstance(msg, GtPose):
            pose = (msg.pose_world.x, msg.pose_world.y, msg.pose_world.yaw)
            self.gt.setdefault(msg.robot_id, []).append((msg.tick, pose))
        elif isinstance(msg, Odometry):
            self.odom_ticks.setdefault(msg.robot_id, []).append(msg.tick)
        return msg

    @property
    def last_tick(self) -> int:
        return self.clocks[-1][1] if self.clocks else -1


def subscribe_all(bus: Bus) -> None:
    bus.subscribe(bus.keys.clock(), Clock)
    bus.subscribe(bus.keys.any_robot("odom"), Odometry)
    bus.subscribe("/".join([bus.keys.gt_pose(0).rsplit("/", 2)[0], "*", "gt_pose"]), GtPose)


def test_realtime_paces_ticks_and_applies_commands() -> None:
    factor, robots = 4.0, 1
    with sim_over_router({"realtime": factor, "robots": robots}, "rt_test") as bus:
        subscribe_all(bus)
        bus.declare_alive("agent", 0)
        seen = Seen()
        deadline = time.monotonic() + 15.0
        while time.monotonic() < deadline and (
            not seen.clocks or seen.clocks[-1][0] - seen.clocks[0][0] < 2.0
        ):
            msg = seen.record(bus.poll(timeout=0.1))
            if isinstance(msg, Odometry):
                bus.publish(bus.keys.cmd_vel(0), CmdVel(
                    robot_id=0, tick=msg.tick, v_mps=0.5, omega_radps=0.0))
    (w0, k0), (w1, k1) = seen.clocks[5], seen.clocks[-1]  # skip the start-up ticks
    rate = (k1 - k0) * 0.1 / (w1 - w0)
    assert rate == pytest.approx(factor, rel=0.25)
    ticks = [t for t, _ in seen.gt[0]]
    assert ticks == sorted(ticks)
    (ta, pa), (tb, pb) = seen.gt[0][5], seen.gt[0][-1]
    speed = (pb[0] - pa[0]) / ((tb - ta) * 0.1)
    assert 0.4 < speed <= 0.51  # the commands moved the robot along +x at ≈ 0.5 m/s


def test_lockstep_waits_for_live_agents_and_stops_waiting_for_a_dead_one() -> None:
    with sim_over_router({"robots": 2}, "ls_test") as bus:
        subscribe_all(bus)
        tokens = {i: bus.session.liveliness().declare_token(bus.keys.alive("agent", i))
                  for i in (0, 1)}
        answering = {0, 1}
        commands = {0: (0.0, 0.5), 1: (0.3, 0.0)}  # 0 turns on the spot, 1 drives away from it
        seen = Seen()

        def serve_until(done: object, limit_s: float) -> None:
            deadline = time.monotonic() + limit_s
            while time.monotonic() < deadline and not done():
                msg = seen.record(bus.poll(timeout=0.05))
                if isinstance(msg, Odometry) and msg.robot_id in answering:
                    v, omega = commands[msg.robot_id]
                    bus.publish(bus.keys.cmd_vel(msg.robot_id), CmdVel(
                        robot_id=msg.robot_id, tick=msg.tick, v_mps=v, omega_radps=omega))

        serve_until(lambda: seen.last_tick >= 10, 15.0)
        assert seen.last_tick >= 10
        answering.discard(1)  # agent 1 hangs: the clock must stop
        stalled_at = seen.last_tick
        serve_until(lambda: False, 1.0)
        assert seen.last_tick <= stalled_at + 1
        tokens[1].undeclare()  # agent 1 dies: the clock goes on without it
        serve_until(lambda: seen.last_tick >= stalled_at + 20, 15.0)
        assert seen.last_tick >= stalled_at + 20
    gt1 = dict(seen.gt[1])
    assert gt1[stalled_at][0] - gt1[0][0] > 0.3 * 0.1 * 8  # it drove while alive
    x_dead = [gt1[t][0] for t in range(stalled_at + 3, max(gt1) + 1)]
    assert max(x_dead) - min(x_dead) < 1e-3  # the dead agent's robot stopped
    gt0 = dict(seen.gt[0])
    turned = gt0[max(gt0)][2] - gt0[stalled_at][2]
    assert turned > 0.5 * 0.1 * 15  # robot 0 kept going (yaw stays below π: no wrap)


def test_pipelined_lockstep_waits_for_edge_tick_k_at_tick_k_plus_lag() -> None:
    """sim.edge_pipeline_ticks = 3: the clock runs on past edge tick k without the edge and
    stops at k + 3 until EdgeAck(k) arrives."""
    lag = 3
    with sim_over_router({"robots": 1, "edge_pipeline_ticks": lag}, "pl_test") as bus:
        subscribe_all(bus)
        agent = bus.session.liveliness().declare_token(bus.keys.alive("agent", 0))
        edge = bus.session.liveliness().declare_token(bus.keys.alive("edge", 0))
        seen = Seen()
        acking = [True]

        def serve_until(done: object, limit_s: float) -> None:
            deadline = time.monotonic() + limit_s
            while time.monotonic() < deadline and not done():
                msg = seen.record(bus.poll(timeout=0.05))
                if isinstance(msg, Odometry):
                    bus.publish(bus.keys.cmd_vel(0), CmdVel(
                        robot_id=0, tick=msg.tick, v_mps=0.0, omega_radps=0.0))
                # The edge answers tick k only once it saw Clock(k + lag): a clock that
                # waited for EdgeAck(k) at tick k would never get there.
                if isinstance(msg, Clock) and acking[0] and msg.tick >= lag \
                        and (msg.tick - lag) % 10 == 0:
                    bus.publish(bus.keys.edge_ack(), EdgeAck(tick=msg.tick - lag))

        serve_until(lambda: seen.last_tick >= 25, 20.0)
        assert seen.last_tick >= 25, "the clock waited for an edge answer before it was due"
        acking[0] = False
        serve_until(lambda: seen.last_tick >= 30 + lag, 15.0)
        serve_until(lambda: False, 1.0)
        assert seen.last_tick == 30 + lag, "the clock did not wait for EdgeAck(30) at tick 33"
        edge.undeclare()  # a dead edge is not waited for
        serve_until(lambda: seen.last_tick >= 45, 15.0)
        assert seen.last_tick >= 45
        agent.undeclare()
