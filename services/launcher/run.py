"""`spacemap run`: a whole mission as separate OS processes, to completion, into a run folder."""

from __future__ import annotations

import json
import logging
import resource
import shutil
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console
from rich.live import Live

from services.common.access import identity, make_credentials
from services.common.bus import connect
from services.config import SpacemapConfig, write_config
from services.evaluator.evaluate import probe_for
from services.launcher.monitor import Monitor
from services.launcher.panel import mission_panel, status_line
from services.launcher.recorders import camera_ticks, open_recorders
from services.launcher.report import mission_end_stamp_ns, write_run_folder
from services.launcher.sampler import CoverageSampler, fetch_cloud
from services.processes import ProcessGroup, free_tcp_port, spacemap_command

log = logging.getLogger(__name__)


class MissionError(RuntimeError):
    """A mission that could not run to its end (a service died or stalled)."""


@dataclass(frozen=True)
class RunResult:
    out_dir: Path
    metrics: dict[str, object]
    exit_codes: dict[str, int]


def _with_bus(config: SpacemapConfig, **fields: object) -> SpacemapConfig:
    tree = config.model_dump(mode="json")
    tree["bus"].update(fields)
    return SpacemapConfig.model_validate(tree)


def start_services(group: ProcessGroup, config_path: Path, robots: int,
                   log_level: str = "INFO") -> None:
    """Edge, agents, then the simulator (which waits for the others' liveliness)."""
    cfg = ["--config", str(config_path), "--log-level", log_level]
    group.start("edge", spacemap_command("edge", *cfg))
    for robot in range(robots):
        group.start(f"agent{robot}", spacemap_command("agent", "--robot", str(robot), *cfg))
    group.start("sim", spacemap_command("sim", *cfg))


def run_mission(
    config: SpacemapConfig,
    out_dir: Path,
    router_endpoint: str | None = None,
    stall_timeout_s: float = 120.0,
    console: Console | None = None,
    sample_every_s: float = 5.0,
    log_level: str = "INFO",
    view: str | None = None,
) -> RunResult:
    """Start router (unless given), edge, agents and simulator; run; write the run folder.

    `sample_every_s`: sim-time period of the live coverage samples (0 = final map only);
    `log_level`: the services' too (DEBUG gives each agent's per-frame registration trace);
    `view`: a live rerun view (`rerun_recorder.view_sinks`), None for none."""
    out_dir.mkdir(parents=True, exist_ok=True)
    group = ProcessGroup(out_dir / "logs")
    secrets_dir: str | None = None
    try:
        if router_endpoint is None:
            # our own router: fresh logins and certificates for this run only, kept out of
            # the run folder; mutual TLS on loopback unless bus.tls=false
            secrets_dir = tempfile.mkdtemp(prefix="spacemap-credentials-")
            make_credentials(Path(secrets_dir), config.sim.robots, days=7)
            config = _with_bus(config, credentials=secrets_dir)
            scheme = "tls" if config.bus.tls else "tcp"
            router_endpoint = f"{scheme}/127.0.0.1:{free_tcp_port()}"
            group.start("router", spacemap_command(
                "router", "--listen", router_endpoint, "--set", f"bus.credentials={secrets_dir}",
                "--set", f"bus.prefix={config.bus.prefix}",
                "--set", f"bus.tls={str(config.bus.tls).lower()}"))
        config = _with_bus(config, connect=router_endpoint)
        metrics = _record(config, out_dir, group, stall_timeout_s, console, sample_every_s,
                          log_level, view)
    finally:
        codes = group.stop(order=["sim", "edge"])
        if secrets_dir is not None:
            shutil.rmtree(secrets_dir, ignore_errors=True)
    return RunResult(out_dir, metrics, codes)


def record_mission(
    config: SpacemapConfig,
    out_dir: Path,
    stall_timeout_s: float = 600.0,
    console: Console | None = None,
    sample_every_s: float = 5.0,
    view: str | None = None,
) -> RunResult:
    """Watch a mission whose services run elsewhere (other hosts, docker compose) and write
    its run folder when it completes or reaches the sim-time cap; starts nothing."""
    out_dir.mkdir(parents=True, exist_ok=True)
    metrics = _record(config, out_dir, None, stall_timeout_s, console, sample_every_s,
                      view=view)
    return RunResult(out_dir, metrics, {})


def _record(
    config: SpacemapConfig,
    out_dir: Path,
    group: ProcessGroup | None,
    stall_timeout_s: float,
    console: Console | None,
    sample_every_s: float,
    log_level: str = "INFO",
    view: str | None = None,
) -> dict[str, object]:
    wall_start = time.monotonic()
    probe = probe_for(config.sim)  # before the services start: a cold ground truth takes seconds
    write_config(config, out_dir / "config.yaml")
    with connect(config.bus, identity("monitor")) as bus:
        monitor = Monitor(bus, config.sim.robots, declare=True,
                          camera_every_ticks=camera_ticks(config) if view else 0)
        if group is not None:
            # the services take a second or more to import: the recorders open meanwhile;
            # what arrives before then waits in the monitor's inbox until the first pump
            start_services(group, out_dir / "config.yaml", config.sim.robots, log_level)
        sampler = CoverageSampler(monitor, probe, sample_every_s, config.sim.tick_s)
        recorders = open_recorders(out_dir, config.sim.robots, config.record, config.sim.tick_s,
                                   monitor.tracks, view)
        monitor.sinks.append(recorders)
        sampler.sinks.append(recorders)
        try:
            sampler.start()
            try:
                completed = _watch(monitor, sampler, group, config, stall_timeout_s, console)
            finally:
                sampler.stop()
            cpu_s = _cpu_seconds(group)  # before the halt: a stopped sim has no /proc entry
            if completed and group is not None:
                _halt(group, "sim")
            if not completed:
                _await_last_plan(monitor, config.sim.edge_every_ticks)
            wall_s = time.monotonic() - wall_start
            cloud = fetch_cloud(bus)
            if cloud is None:
                raise MissionError("the edge did not answer the final map/cloud query")
            _catch_up(monitor, cloud.tick)
            live = _live_fields(config, monitor, completed, wall_s, sample_every_s)
            _wait_for_tracks(monitor, mission_end_stamp_ns(config, live))
            metrics = write_run_folder(out_dir, config, monitor, sampler, cloud, live, probe,
                                       recorders)
        finally:
            recorders.close()
    write_profile(out_dir / PROFILE, cpu_s, wall_s, float(metrics["sim_time_s"]), sampler.cpu_s,
                  sampler.stage_cpu_s)
    return metrics


PROFILE = "profile.json"
REAP_EVERY_S = 0.5  # how often the launcher looks for services that exited


def _cpu_seconds(group: ProcessGroup | None) -> dict[str, float]:
    """CPU seconds per process of the mission so far: each child, and this launcher (its
    monitor and live coverage sampler)."""
    cpu = group.cpu_seconds() if group is not None else {}
    own = resource.getrusage(resource.RUSAGE_SELF)
    cpu["launcher"] = own.ru_utime + own.ru_stime
    return cpu


def write_profile(path: Path, cpu_s: dict[str, float], wall_s: float, sim_s: float,
                  sampler_cpu_s: float = 0.0,
                  sampler_stages: dict[str, float] | None = None) -> None:
    """profile.json: where a mission's CPU went (bench/bench_mission.py reads it); the
    launcher's figure includes its live coverage sampler's thread, `sampler_cpu_s` (by stage
    in `sampler_stage_cpu_s`), and `sampler_core_pct` is that thread's share of one core
    over the mission."""
    profile = {
        "wall_time_s": round(wall_s, 3),
        "sim_time_s": sim_s,
        "real_time_factor": round(sim_s / wall_s, 3) if wall_s > 0 else None,
        "cpu_s": {name: round(sec, 2) for name, sec in sorted(cpu_s.items())},
        "cpu_s_total": round(sum(cpu_s.values()), 2),
        "sampler_cpu_s": round(sampler_cpu_s, 2),
        "sampler_stage_cpu_s": {k: round(v, 2) for k, v in (sampler_stages or {}).items()},
        "sampler_core_pct": round(100.0 * sampler_cpu_s / wall_s, 2) if wall_s > 0 else None,
    }
    path.write_text(json.dumps(profile, indent=2) + "\n")


def _watch(
    monitor: Monitor, sampler: CoverageSampler, group: ProcessGroup | None,
    config: SpacemapConfig, stall_timeout_s: float, console: Console | None,
    stop: threading.Event | None = None,
) -> bool:
    """Until exploration completes (True) or the sim-time cap is reached or `stop` is set
    (False); a live panel on a terminal, a log line every 5 s otherwise."""
    cap_s = config.sim.max_sim_time_s
    start = last_change = time.monotonic()
    last_tick = -1
    console = console or Console(stderr=True)
    next_log = next_reap = start

    def panel() -> object:
        row = sampler.rows[-1] if sampler.rows else None
        return mission_panel(monitor, config.sim.world, cap_s, time.monotonic() - start, row)

    with Live(panel(), console=console, refresh_per_second=4,
              auto_refresh=False) if console.is_terminal else _NoLive() as live:
        while True:
            monitor.pump(timeout=0.2)
            now = time.monotonic()
            if group is not None and now >= next_reap:  # pump returns per burst: not each
                next_reap = now + REAP_EVERY_S
                dead = {n: c for n, c in group.dead().items() if n != "router" or c != 0}
                if dead:
                    raise MissionError(f"service(s) exited: {dead}; see {group.log_dir}")
            tick = monitor.clock.tick if monitor.clock else -1
            if tick != last_tick:
                last_tick, last_change = tick, now
            elif now - last_change > stall_timeout_s:
                raise MissionError(f"no clock tick for {stall_timeout_s:.0f} s (at tick {tick})")
            if now >= next_log:
                if live is not None:
                    live.update(panel(), refresh=True)
                    next_log = now + 0.25
                else:
                    row = sampler.rows[-1] if sampler.rows else None
                    log.info("sim %.1f/%.0f s  %s", monitor.sim_time_s, cap_s,
                             status_line(monitor, row))
                    next_log = now + 5.0
            if monitor.complete_tick is not None:
                return True
            if monitor.sim_time_s >= cap_s - 0.5 * config.sim.tick_s or (
                    stop is not None and stop.is_set()):
                return False


class _NoLive:
    """Stands in for rich's Live when the output is no terminal."""

    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


def _halt(group: ProcessGroup, name: str, grace_s: float = 10.0) -> None:
    """Stop one child (SIGTERM, then SIGKILL): the simulator once the edge declared the
    exploration complete, so the map stops growing before the final query."""
    proc = group.children.get(name)
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=grace_s)


def _wait_for_tracks(monitor: Monitor, end_stamp_ns: int, timeout_s: float = 3.0) -> None:
    """Read the inbox until every robot's truth and estimate reached the mission's end (or
    the deadline: a stream that stopped earlier is then cut where every stream has data)."""
    deadline = time.monotonic() + timeout_s
    while not monitor.tracks_reach(end_stamp_ns) and time.monotonic() < deadline:
        monitor.pump(timeout=0.05)


def _await_last_plan(monitor: Monitor, edge_every_ticks: int, timeout_s: float = 10.0) -> None:
    """At the sim-time cap the simulator publishes its last Clock and stops without waiting,
    but the edge still plans that tick when it is an edge tick. Read on until that plan's
    acknowledgement arrives, which the edge sends after the plan's frontiers, goals and
    corrections (the plan is then over and the planner lock free), so the final map query
    cannot race the plan (measured: a 120 s house run got tick 1190's map once in three) and
    the last plan's goals are in events.jsonl whatever the load (waiting for its frontiers
    alone, a 20 s run's tick-200 goal was there in one run and not in its repeat)."""
    if monitor.clock is None:
        return
    last = monitor.clock.tick - monitor.clock.tick % edge_every_ticks
    deadline = time.monotonic() + timeout_s
    while last not in monitor.recent_acks and time.monotonic() < deadline:
        monitor.pump(timeout=0.05)


def _catch_up(monitor: Monitor, edge_tick: int, timeout_s: float = 3.0) -> None:
    """Read the monitor's inbox until it holds the edge's grid of the final map's tick, so
    the grid written and scored belongs to the same edge tick as the final cloud."""
    deadline = time.monotonic() + timeout_s
    while edge_tick not in monitor.recent_grids and time.monotonic() < deadline:
        monitor.pump(timeout=0.05)
    if monitor.recent_grids.get(edge_tick) is not None:
        monitor.grid = monitor.recent_grids[edge_tick]


def _live_fields(
    config: SpacemapConfig, monitor: Monitor, completed: bool, wall_s: float,
    sample_every_s: float,
    log_level: str = "INFO",
) -> dict[str, object]:
    """What only the live run knows (live.json): completion, sim and wall time, traffic."""
    tick_s = config.sim.tick_s
    if completed and monitor.complete_tick is not None:
        sim_s = round(monitor.complete_tick * tick_s, 6)
    else:
        sim_s = round(min(monitor.sim_time_s, config.sim.max_sim_time_s), 6)
    per_s = max(sim_s, 1e-9)
    return {
        "completed": completed,
        "mapping_time_s": sim_s if completed else None,
        "sim_time_s": sim_s,
        "wall_time_s": wall_s,
        "bytes_per_robot": {
            str(r): {"total": b, "per_sim_s": b / per_s}
            for r, b in monitor.bytes_per_robot(before_tick=round(sim_s / tick_s)).items()
        },
        "sample_every_s": sample_every_s,
    }
