"""The `spacemap` command line: run a mission, or start one service alone."""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from services.common.config import SpacemapConfig, load_config

app = typer.Typer(add_completion=False, no_args_is_help=False, help=__doc__)

ConfigOpt = Annotated[Path | None, typer.Option("--config", help="mission config YAML")]
ConnectOpt = Annotated[
    str | None, typer.Option("--connect", help="router endpoint, e.g. tcp/HOST:7447")
]
SetOpt = Annotated[
    list[str] | None, typer.Option("--set", help="override a config field: section.field=value")
]
LogOpt = Annotated[str, typer.Option("--log-level", help="DEBUG, INFO, WARNING")]


def _setup_logging(level: str) -> None:
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s %(processName)s %(name)s %(levelname)s: %(message)s",
    )


def _parse_sets(sets: list[str] | None) -> dict[str, Any]:
    import yaml

    out: dict[str, Any] = {}
    for item in sets or []:
        if "=" not in item:
            raise typer.BadParameter(f"--set wants section.field=value, got {item!r}")
        key, raw = item.split("=", 1)
        out[key.strip()] = yaml.safe_load(raw)
    return out


def service_config(
    config: Path | None, connect: str | None, sets: list[str] | None
) -> SpacemapConfig:
    """YAML, then environment, then --set and --connect."""
    overrides = _parse_sets(sets)
    if connect:
        overrides["bus.connect"] = connect
    try:
        return load_config(config, overrides)
    except (ValueError, OSError) as exc:
        raise typer.BadParameter(str(exc)) from exc


def install_stop_handlers() -> threading.Event:
    """A stop event set by SIGTERM or SIGINT (services poll it)."""
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    return stop


@app.command()
def router(
    listen: Annotated[
        list[str] | None, typer.Option("--listen", help="endpoint(s) to listen on")
    ] = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Run the zenoh router (mode router)."""
    from services.common.router import run_router

    _setup_logging(log_level)
    run_router(listen or ["tcp/0.0.0.0:7447"], install_stop_handlers())


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

    _setup_logging(log_level)
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

    _setup_logging(log_level)
    main(service_config(config, connect, set_))


@app.command()
def agent(
    robot: Annotated[int, typer.Option("--robot", min=0, help="robot id")],
    config: ConfigOpt = None,
    connect: ConnectOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Run one robot agent alone."""
    from services.robot_agent.node import main

    _setup_logging(log_level)
    main(service_config(config, connect, set_), robot)


@app.command()
def worlds() -> None:
    """List the built-in worlds."""
    from services.simulator.worlds import WORLDS

    for name in sorted(WORLDS):
        typer.echo(f"{name}\t{WORLDS[name].description}")


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
        str | None, typer.Option("--planner", help="space|nearest|utility|rrt")
    ] = None,
    no_drf: Annotated[bool, typer.Option("--no-drf", help="standalone mapping baseline")] = False,
    resolution: Annotated[str | None, typer.Option("--resolution", help="camera WxH")] = None,
    realtime: Annotated[float | None, typer.Option("--realtime", help="real-time factor")] = None,
    connect: ConnectOpt = None,
    spawn: Annotated[str | None, typer.Option("--spawn", help='"X,Y,YAW;X,Y,YAW;..."')] = None,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "INFO",
) -> None:
    """Run a whole mission (router, simulator, edge, agents) to completion."""
    from services.launcher.run import MissionError, run_mission

    _setup_logging(log_level)
    overrides = _parse_sets(set_)
    for key, value in (
        ("sim.robots", robots),
        ("sim.world", world),
        ("sim.seed", seed),
        ("sim.max_sim_time_s", sim_time),
        ("edge.planner", planner),
        ("sim.realtime", realtime),
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
    out_dir = out or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    try:
        result = run_mission(cfg, out_dir, router_endpoint=connect)
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
        "total_distance_m",
    ):
        typer.echo(f"  {key}: {metrics.get(key)}")
