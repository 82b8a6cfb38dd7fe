"""The simulator process: owns the clock and runs the lockstep protocol of ARCHITECTURE.md.

Per tick k: publish Clock(k), then per robot GtPose(k) (eval key), RgbdFrame(k) on camera ticks
and Odometry(k); wait for CmdVel(tick=k) from every live agent and for EdgeAck(k − L) when
k − L was an edge tick with the edge alive (L = `sim.edge_pipeline_ticks`, edge_barrier.py);
then apply the commands and integrate one tick. Real-time mode paces the ticks at F × wall
clock, uses the latest commands and never waits.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # numpy post-processing is 3× faster

import logging  # noqa: E402
import signal  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from contextlib import contextmanager  # noqa: E402

from schemas.messages import (  # noqa: E402
    Clock,
    CmdVel,
    EdgeAck,
    Frontiers,
    GtPose,
    Odometry,
    Pose2D,
    RgbdFrame,
)
from services.common.access import identity  # noqa: E402
from services.common.bus import Bus, Inbound, Presence, connect  # noqa: E402
from services.config import SpacemapConfig  # noqa: E402
from services.simulator.config import SimConfig  # noqa: E402
from services.simulator.core import Simulation  # noqa: E402
from services.simulator.edge_barrier import EdgeBarrier  # noqa: E402

log = logging.getLogger(__name__)

POLL_S = 0.1  # longest wait between checks of the stop event
STALL_WARN_S = 10.0


class SimNode:
    """The imperative shell around `Simulation`: bus traffic, liveliness, pacing."""

    def __init__(self, bus: Bus, cfg: SimConfig, stop: threading.Event) -> None:
        self.bus, self.cfg, self.stop = bus, cfg, stop
        self.keys = bus.keys
        self.sim = Simulation(cfg)
        _ = self.sim.camera  # GL set-up now, in the thread that renders, not in the first tick
        n = self.sim.n_robots
        self.live_agents: set[int] = set()
        self.joining: set[int] = set()  # waited for from the next tick on
        self.edge_alive = False
        self.commands: dict[int, tuple[float, float]] = {}
        self.answered: set[int] = set()
        self.barrier = EdgeBarrier(cfg.edge_every_ticks, cfg.edge_lag_ticks)
        self.ignored = 0
        self.timing: dict[str, float] = defaultdict(float)
        self.K = self.sim.K
        self.T_base_cam = [self.sim.T_base_cam(i) for i in range(n)]
        self.dt_ns = round(cfg.tick_s * 1e9)
        bus.subscribe(self.keys.any_robot("cmd_vel"), CmdVel)
        bus.subscribe(self.keys.edge_ack(), EdgeAck)
        bus.subscribe(self.keys.map_frontiers(), Frontiers)
        self.complete_tick: int | None = None  # the edge declared exploration complete
        bus.watch_liveliness()
        bus.declare_alive("sim", 0)

    # -- inbox -------------------------------------------------------------------------------
    def handle(self, item: Inbound | Presence | None) -> None:
        if isinstance(item, Presence):
            self._presence(item)
        elif isinstance(item, Inbound):
            msg = item.message
            if isinstance(msg, CmdVel):
                self._cmd_vel(item.key, msg)
            elif isinstance(msg, EdgeAck):
                self.barrier.acked(msg.tick)
            elif isinstance(msg, Frontiers) and msg.complete and self.complete_tick is None:
                # Read before the EdgeAck of the same tick, and acted on only at the tick
                # that ack is due (barrier.stop_tick): the stop tick is deterministic.
                self.complete_tick = msg.tick

    def _presence(self, p: Presence) -> None:
        if p.role == "edge":
            self.edge_alive = p.alive
            if not p.alive:
                self.barrier.edge_gone()
            log.info("edge %s %s", p.ident, "alive" if p.alive else "gone")
        elif p.role == "agent" and p.ident.isdigit() and int(p.ident) < self.sim.n_robots:
            i = int(p.ident)
            if p.alive:
                if i not in self.live_agents:
                    log.info("agent %d alive: waited for from the next tick", i)
                self.joining.add(i)
            else:
                self.joining.discard(i)
                self.live_agents.discard(i)
                self.commands.pop(i, None)  # a dead agent's robot stops
                log.warning("agent %d gone: its robot stops", i)

    def _cmd_vel(self, key: str, msg: CmdVel) -> None:
        try:
            robot = self.keys.robot_id(key)
        except ValueError:
            robot = -1
        lockstep = self.cfg.realtime is None
        stale = msg.tick != self.sim.tick if lockstep else msg.tick > self.sim.tick
        if robot != msg.robot_id or robot not in self.live_agents or stale:
            self.ignored += 1
            log.debug("ignored CmdVel robot %d tick %d on %s", msg.robot_id, msg.tick, key)
            return
        self.commands[robot] = (msg.v_mps, msg.omega_radps)
        self.answered.add(robot)

    def drain(self) -> None:
        for item in self.bus.drain():
            self.handle(item)

    # -- protocol ----------------------------------------------------------------------------
    def wait_for_peers(self) -> None:
        wanted = set(range(self.sim.n_robots))
        deadline = time.monotonic() + self.cfg.wait_for_peers_s
        while not self.stop.is_set() and time.monotonic() < deadline:
            if wanted <= self.joining and self.edge_alive:
                log.info("all peers present")
                return
            self.handle(self.bus.poll(timeout=POLL_S))
        if not self.stop.is_set():
            log.warning(
                "starting without all peers: agents %s, edge %s",
                sorted(self.joining), self.edge_alive,
            )

    def publish_tick(self) -> None:
        sim, keys, k = self.sim, self.keys, self.sim.tick
        stamp = sim.stamp_ns
        camera_tick = k % self.cfg.camera_every_ticks == 0
        self.bus.publish(keys.clock(), Clock(
            tick=k, stamp_ns=stamp, dt_ns=self.dt_ns, lockstep=self.cfg.realtime is None,
            camera_tick=camera_tick,
        ))
        for i in range(sim.n_robots):
            x, y, yaw = sim.true_pose(i)
            self.bus.publish(keys.gt_pose(i), GtPose(
                robot_id=i, tick=k, stamp_ns=stamp, pose_world=Pose2D(x=x, y=y, yaw=yaw)
            ))
            if camera_tick:
                t0 = time.perf_counter()
                img = sim.render(i)
                self.timing["render"] += time.perf_counter() - t0
                self.bus.publish(keys.rgbd(i), RgbdFrame(
                    robot_id=i, tick=k, stamp_ns=stamp, depth_m=img.depth_m, rgb=img.rgb,
                    K=self.K, T_base_cam=self.T_base_cam[i], range_max_m=self.cfg.range_m,
                ))
            odom = sim.odometry(i)
            ox, oy, oyaw = odom.pose
            self.bus.publish(keys.odom(i), Odometry(
                robot_id=i, tick=k, stamp_ns=stamp, pose_odom=Pose2D(x=ox, y=oy, yaw=oyaw),
                v_mps=odom.v_mps, omega_radps=odom.omega_radps,
            ))

    def wait_for_answers(self) -> bool:
        """Block until every live agent answered tick k and the edge every edge tick due."""
        k = self.sim.tick
        started = time.monotonic()
        warned = False
        while not self.stop.is_set():
            edge_due = self.barrier.blocking(k)
            if self.live_agents <= self.answered and not edge_due:
                return True
            self.handle(self.bus.poll(timeout=POLL_S))
            if not warned and time.monotonic() - started > STALL_WARN_S:
                warned = True
                log.warning(
                    "tick %d: still waiting for agents %s and the edge's ticks %s (their "
                    "liveliness tokens are still held; a process cut off over TLS with data "
                    "queued toward it keeps its token until the router host's TCP gives up: "
                    "ARCHITECTURE.md, \"A cut link\")", k,
                    sorted(self.live_agents - self.answered), edge_due,
                )
        return False

    def run(self) -> None:
        self.wait_for_peers()
        max_ns = round(self.cfg.max_sim_time_s * 1e9)
        realtime = self.cfg.realtime
        period_s = self.cfg.tick_s / realtime if realtime is not None else 0.0
        wall0 = time.monotonic()
        next_wall = wall0 + period_s
        while not self.stop.is_set():
            # Agents that appeared during the last tick are waited for from this tick on.
            self.live_agents |= self.joining
            self.answered.clear()
            if realtime is None:
                self.commands.clear()
                self.barrier.published(self.sim.tick, self.edge_alive)
            t0 = time.perf_counter()
            self.publish_tick()
            self.timing["publish"] += time.perf_counter() - t0
            if self.sim.stamp_ns >= max_ns:
                log.info("reached max_sim_time_s at tick %d", self.sim.tick)
                break
            t0 = time.perf_counter()
            if realtime is None:
                if not self.wait_for_answers():
                    break
            else:
                self._pace(next_wall)
                next_wall = self._next_deadline(next_wall, period_s)
            self.timing["wait"] += time.perf_counter() - t0
            if self.complete_tick is not None and (
                realtime is not None or self.sim.tick >= self.barrier.stop_tick(self.complete_tick)
            ):
                log.info("exploration complete at tick %d: the clock stops at tick %d",
                         self.complete_tick, self.sim.tick)
                break
            t0 = time.perf_counter()
            self.sim.step({i: c for i, c in self.commands.items() if i in self.live_agents})
            self.timing["step"] += time.perf_counter() - t0
            if self.sim.tick % 1000 == 0:
                self.log_timing(time.monotonic() - wall0)
        self.log_timing(time.monotonic() - wall0)
        self.stop.wait()  # idle until SIGTERM / SIGINT

    def _next_deadline(self, deadline: float, period_s: float) -> float:
        """The next tick's wall deadline; a backlog over one tick is dropped, not caught up in
        a burst (a robot's clock runs slow when the machine is overloaded, never fast)."""
        deadline += period_s
        now = time.monotonic()
        if deadline < now - period_s:
            self.timing["late_ticks"] += 1
            return now
        return deadline

    def _pace(self, deadline: float) -> None:
        while not self.stop.is_set():
            left = deadline - time.monotonic()
            if left <= 0:
                self.drain()
                return
            self.handle(self.bus.poll(timeout=min(left, POLL_S)))

    def log_timing(self, wall_s: float) -> None:
        ticks = max(self.sim.tick, 1)
        sim_s = self.sim.tick * self.cfg.tick_s
        log.info(
            "tick %d: sim %.1f s in %.1f s wall (%.1fx); per tick ms: publish %.2f "
            "(render %.2f) wait %.2f step %.2f; %d commands ignored, %d real-time backlogs dropped",
            self.sim.tick, sim_s, wall_s, sim_s / max(wall_s, 1e-9),
            1e3 * self.timing["publish"] / ticks, 1e3 * self.timing["render"] / ticks,
            1e3 * self.timing["wait"] / ticks, 1e3 * self.timing["step"] / ticks, self.ignored,
            self.timing["late_ticks"],
        )

    def close(self) -> None:
        self.sim.close()


@contextmanager
def _signals_set(stop: threading.Event) -> Iterator[None]:
    """SIGTERM / SIGINT set `stop` (only possible from the main thread)."""
    previous = {}
    try:
        for sig in (signal.SIGTERM, signal.SIGINT):
            previous[sig] = signal.signal(sig, lambda *_: stop.set())
    except ValueError:  # not the main thread: the caller stops us through the event
        pass
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def main(config: SpacemapConfig, stop: threading.Event | None = None) -> None:
    """Run the simulator until SIGTERM / SIGINT (or until `stop` is set)."""
    stop = stop or threading.Event()
    with _signals_set(stop):
        try:
            with connect(config.bus, identity("sim")) as bus:
                node = SimNode(bus, config.sim, stop)
                mode = config.sim.realtime
                log.info(
                    "simulator: world %s, %d robots, %s", config.sim.world, node.sim.n_robots,
                    "lockstep" if mode is None else f"real time ×{mode}",
                )
                try:
                    node.run()
                finally:
                    node.close()
        except KeyboardInterrupt:
            log.info("interrupted")
    log.info("simulator stopped")
