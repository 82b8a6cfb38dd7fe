"""The `spacemap` command line: run a mission, or start one service alone."""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Annotated

import typer

from services.cli_common import (
    VIEW_TO_HELP,
    ConfigOpt,
    ConnectOpt,
    LogOpt,
    SetOpt,
    parse_sets,
    service_config,
    setup_logging,
    tls_errors,
)
from services.cli_results import bench, eval_
from services.config import load_config

app = typer.Typer(add_completion=False, no_args_is_help=False, help=__doc__)

@app.command()
def router(
    listen: Annotated[
        list[str] | None, typer.Option("--listen", help="endpoint(s) to listen on (default "
                                       "tls/0.0.0.0:7447 with bus.credentials, else tcp/)")
    ] = None,
    lease: Annotated[
        float, typer.Option("--lease", help="seconds before a silent peer is gone")
    ] = 10.0,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Run the zenoh router (mode router); with bus.credentials, authenticated, with access
    control (bus.prefix names the keys) and mutual TLS (unless bus.tls=false)."""
    from services.common.router import default_listen, run_router
    from services.common.signals import stop_on_signals
    from services.common.tls import TlsError

    setup_logging(log_level)
    bus = service_config(config, None, set_).bus
    try:
        run_router(listen or default_listen(bus.credentials, bus.tls), stop_on_signals(), lease,
                   credentials=bus.credentials, prefix=bus.prefix, tls=bus.tls)
    except TlsError as exc:
        raise typer.BadParameter(str(exc)) from exc


@app.command()
def credentials(
    out: Annotated[Path, typer.Option("--out", help="folder to write (mode 0700)")],
    robots: Annotated[int, typer.Option("--robots", min=1, help="agents in the fleet")] = 3,
    router_host: Annotated[list[str] | None, typer.Option(
        "--router-host", help="host name or address clients use to reach the router, for "
        "its certificate (repeatable; localhost, 127.0.0.1, ::1 and router always)")] = None,
    days: Annotated[int, typer.Option("--days", min=1, help="certificate validity")] = 365,
) -> None:
    """Create a login per process (sim, edge, monitor, agent-0..N-1), the router's
    dictionary, a CA with the router's TLS certificate and a client certificate per
    process; point every service's bus.credentials at the folder."""
    from services.common.access import make_credentials
    from services.common.fleet import reset_claims
    from services.common.tls import router_names

    users = make_credentials(out, robots, router_host or (), days)
    reset_claims(out)  # a fresh fleet: agent replicas claim their ids anew
    typer.echo(f"credentials for {', '.join(users)} in {out}; router certificate for "
               f"{', '.join(router_names(out))}")


@app.command()
def sim(
    config: ConfigOpt = None,
    connect: ConnectOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Run the simulator alone."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from services.simulator.node import main

    setup_logging(log_level)
    with tls_errors():
        main(service_config(config, connect, set_))


@app.command()
def edge(
    config: ConfigOpt = None,
    connect: ConnectOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Run the edge server alone."""
    from services.edge_server.node import main

    setup_logging(log_level)
    with tls_errors():
        main(service_config(config, connect, set_))


@app.command()
def agent(
    robot: Annotated[str, typer.Option("--robot", help="robot id, or auto (replicas claim "
                                       "the lowest free id in bus.credentials/claims)")],
    config: ConfigOpt = None,
    connect: ConnectOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Run one robot agent alone."""
    from services.common.fleet import resolve_robot
    from services.robot_agent.node import main

    setup_logging(log_level)
    cfg = service_config(config, connect, set_)
    try:
        robot_id = resolve_robot(robot, cfg.bus.credentials, cfg.sim.robots, claim=True)
    except (ValueError, RuntimeError) as exc:
        raise typer.BadParameter(str(exc)) from exc
    logging.getLogger("spacemap.agent").info("robot id %s (--robot %s)", robot_id, robot)
    with tls_errors():
        main(cfg, robot_id)


@app.command()
def worlds() -> None:
    """List the built-in worlds."""
    from services.simulator.worlds import WORLDS

    for name in sorted(WORLDS):
        typer.echo(f"{name}\t{WORLDS[name].description}")


def _check_view(view: str) -> None:
    from services.launcher.config import parse_view

    try:
        parse_view(view)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from exc


def _parse_spawn(text: str) -> list[list[float]]:
    poses = []
    for item in filter(None, (s.strip() for s in text.split(";"))):
        parts = [float(v) for v in item.split(",")]
        if len(parts) != 3:
            raise typer.BadParameter(f"--spawn wants X,Y,YAW per robot, got {item!r}")
        poses.append(parts)
    return poses


def _parse_resolution(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise typer.BadParameter(f"--resolution wants WxH, got {text!r}") from exc
    return width, height


@app.command()
def run(
    robots: Annotated[int | None, typer.Option("--robots", min=1, help="number of robots")] = None,
    world: Annotated[str | None, typer.Option("--world", help="world name or MJCF path")] = None,
    sim_time: Annotated[float | None, typer.Option("--sim-time", help="sim-time cap, s")] = None,
    seed: Annotated[int | None, typer.Option("--seed")] = None,
    out: Annotated[Path | None, typer.Option("--out", help="run folder")] = None,
    planner: Annotated[
        str | None, typer.Option("--planner", help="space|space-paper|nearest|utility|rrt")
    ] = None,
    no_drf: Annotated[bool, typer.Option("--no-drf", help="standalone mapping baseline")] = False,
    resolution: Annotated[str | None, typer.Option("--resolution", help="camera WxH")] = None,
    realtime: Annotated[float | None, typer.Option("--realtime", help="real-time factor")] = None,
    sensors: Annotated[str | None, typer.Option(
        "--sensors", help="realistic (Kinect v2-like depth, odometry random walk; default) "
        "or ideal (every random term off)")] = None,
    connect: ConnectOpt = None,
    spawn: Annotated[str | None, typer.Option("--spawn", help='"X,Y,YAW;X,Y,YAW;..."')] = None,
    sample_every: Annotated[float, typer.Option(
        "--sample-every", help="coverage time-series period, sim s (0: final map only)")] = 5.0,
    view: Annotated[bool, typer.Option(
        "--view", help="watch live in rerun (see --view-to); the run folder's mission.rrd "
        "is written either way")] = False,
    view_to: Annotated[str, typer.Option("--view-to", help=VIEW_TO_HELP)] = "spawn",
    config: ConfigOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Run a whole mission (router, simulator, edge, agents) to completion."""
    from services.launcher.run import MissionError, run_mission

    setup_logging(log_level)
    overrides = parse_sets(set_)
    for key, value in (
        ("sim.robots", robots),
        ("sim.world", world),
        ("sim.seed", seed),
        ("sim.max_sim_time_s", sim_time),
        ("edge.planner", planner),
        ("sim.realtime", realtime),
        ("sim.sensors", sensors),
    ):
        if value is not None:
            overrides[key] = value
    if no_drf:
        overrides["agent.drf"] = False
    if resolution:
        overrides["sim.width"], overrides["sim.height"] = _parse_resolution(resolution)
    if spawn:
        overrides["sim.spawn"] = _parse_spawn(spawn)
    try:
        cfg = load_config(config, overrides)
    except (ValueError, OSError) as exc:
        raise typer.BadParameter(str(exc)) from exc
    if cfg.sim.spawn is not None and len(cfg.sim.spawn) != cfg.sim.robots:
        raise typer.BadParameter(
            f"--spawn gives {len(cfg.sim.spawn)} poses for {cfg.sim.robots} robots"
        )
    if view:
        _check_view(view_to)
    out_dir = out or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    try:
        with tls_errors():
            result = run_mission(cfg, out_dir, router_endpoint=connect,
                                 sample_every_s=sample_every, log_level=log_level,
                                 view=view_to if view else None)
    except MissionError as exc:
        typer.echo(f"mission failed: {exc}", err=True)
        raise typer.Exit(1) from exc
    metrics = result.metrics
    typer.echo(f"run folder: {result.out_dir}")
    for key in (
        "completed",
        "sim_time_s",
        "wall_time_s",
        "coverage_3d_pct",
        "coverage_2d_pct",
        "overlap_3d_pct",
        "overlap_2d_pct",
        "bounding_volume_pct",
        "t90_s",
        "total_distance_m",
        "ate_rmse_cm",
    ):
        typer.echo(f"  {key}: {metrics.get(key)}")


@app.command()
def record(
    out: Annotated[Path, typer.Option("--out", help="run folder to write")],
    sample_every: Annotated[float, typer.Option(
        "--sample-every", help="coverage time-series period, sim s (0: final map only)")] = 5.0,
    config: ConfigOpt = None,
    connect: ConnectOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Watch a mission started elsewhere (other hosts, docker compose); write its run folder."""
    from services.launcher.run import MissionError, record_mission

    setup_logging(log_level)
    try:
        with tls_errors():
            result = record_mission(service_config(config, connect, set_), out,
                                    sample_every_s=sample_every)
    except MissionError as exc:
        typer.echo(f"recording failed: {exc}", err=True)
        raise typer.Exit(1) from exc
    typer.echo(f"run folder: {result.out_dir}")


@app.command()
def view(
    to: Annotated[str, typer.Option("--to", help=VIEW_TO_HELP)] = "spawn",
    save: Annotated[Path | None, typer.Option("--save", help="also write this .rrd")] = None,
    sample_every: Annotated[float, typer.Option(
        "--sample-every", help="merged cloud and coverage period, sim s")] = 5.0,
    config: ConfigOpt = None,
    connect: ConnectOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Watch a mission started elsewhere (other hosts, docker compose) live in rerun."""
    from services.launcher.run import MissionError
    from services.launcher.view import watch_mission

    setup_logging(log_level)
    _check_view(to)
    try:
        with tls_errors():
            watch_mission(service_config(config, connect, set_), to, save, sample_every)
    except MissionError as exc:
        typer.echo(f"view stopped: {exc}", err=True)
        raise typer.Exit(1) from exc


@app.command()
def health(
    role: Annotated[str, typer.Option("--role", help="router|sim|edge|agent|monitor")],
    ident: Annotated[str, typer.Option("--id", help="process id (robot id for agents)")] = "0",
    timeout: Annotated[float, typer.Option("--timeout", help="seconds")] = 3.0,
    login_as: Annotated[str, typer.Option(
        "--as", help="user to log in as when bus.credentials is set; auto: the probed "
        "process's own")] = "monitor",
    config: ConfigOpt = None,
    connect: ConnectOpt = None,
    set_: SetOpt = None,
) -> None:
    """Exit 0 when the process is alive on the bus (for health checks), else 1."""
    from services.common.access import identity
    from services.common.fleet import resolve_robot
    from services.common.health import is_alive
    from services.common.tls import TlsError

    cfg = service_config(config, connect, set_)
    if ident == "auto":  # this agent replica's claimed id
        robot = resolve_robot(ident, cfg.bus.credentials, cfg.sim.robots, claim=False)
        if robot is None:
            typer.echo(f"{role}/auto: no robot id claimed yet", err=True)
            raise typer.Exit(1)
        ident = str(robot)
    if login_as == "auto":
        login_as = identity(role, ident)
    try:
        alive = is_alive(cfg.bus, role, ident, timeout, login_as)
    except TlsError as exc:
        typer.echo(f"{role}/{ident}: {exc}", err=True)
        raise typer.Exit(2) from exc
    if not alive:
        typer.echo(f"{role}/{ident}: not alive on {cfg.bus.connect}", err=True)
        raise typer.Exit(1)
    typer.echo(f"{role}/{ident}: alive")


@app.command()
def inventory(
    robots: Annotated[int, typer.Option("--robots", min=1, help="agents to ask")] = 3,
    timeout: Annotated[float, typer.Option("--timeout", help="seconds per query")] = 5.0,
    config: ConfigOpt = None,
    connect: ConnectOpt = None,
    set_: SetOpt = None,
) -> None:
    """Print, as JSON, the submaps each agent produced and those the edge merged."""
    import json

    from services.common.inventory import collect_inventories

    cfg = service_config(config, connect, set_)
    with tls_errors():
        typer.echo(json.dumps(collect_inventories(cfg.bus, robots, timeout), indent=1))


# results commands live in their own module (services/cli_results.py)
app.command("eval")(eval_)
app.command()(bench)
