"""`spacemap eval` and `spacemap bench`: results from finished runs and the paper's matrix."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Any

import typer

from services.cli_common import ConfigOpt, LogOpt, SetOpt, service_config, setup_logging


def eval_(
    run_dir: Annotated[Path, typer.Argument(help="a finished run folder")],
    out: Annotated[
        Path | None, typer.Option("--out", help="write the metrics here (default RUN_DIR/"
                                  "metrics_eval.json)")
    ] = None,
    plots: Annotated[bool, typer.Option("--plots", help="also redraw the PNG figures")] = False,
    explain: Annotated[bool, typer.Option(
        "--explain", help="only print where each robot's time and distance went")] = False,
    from_coverage: Annotated[float | None, typer.Option(
        "--from-coverage", min=0.0, max=100.0, help="with --explain: only the mission after "
        "the 3D coverage first reached this many % (where the tail's time goes)")] = None,
    log_level: LogOpt = "WARNING",
) -> None:
    """Recompute metrics.json from a finished run folder's files and compare."""
    from services.evaluator.evaluate import (
        evaluate_run_folder,
        explain_run_folder,
        redraw_plots,
    )
    from services.evaluator.run_files import METRICS, read_json, write_json

    setup_logging(log_level)
    if not (run_dir / "config.yaml").exists():
        raise typer.BadParameter(f"{run_dir} has no config.yaml: not a run folder")
    if from_coverage is not None and not explain:
        raise typer.BadParameter("--from-coverage goes with --explain")
    if explain:
        try:
            typer.echo(explain_run_folder(run_dir, from_coverage), nl=False)
        except (FileNotFoundError, ValueError) as exc:
            raise typer.BadParameter(str(exc)) from exc
        return
    metrics = evaluate_run_folder(run_dir)
    write_json(out or run_dir / "metrics_eval.json", metrics)
    if plots:
        redraw_plots(run_dir, metrics)
    recorded = read_json(run_dir / METRICS) if (run_dir / METRICS).exists() else {}
    for key, value in metrics.items():
        mark = "" if key not in recorded or recorded[key] == value else (
            f"   (metrics.json: {recorded[key]})")
        typer.echo(f"{key}: {value}{mark}")


def _csv_list(text: str, cast: type = str) -> tuple:
    return tuple(cast(v.strip()) for v in text.split(",") if v.strip())


def bench(
    quick: Annotated[bool, typer.Option("--quick", help="house, 3 robots, all methods, "
                                        "seeds 0,1, 150 s cap (14 runs, 20-35 min here); "
                                        "default: house, bookstore, AWS house × 3, 6 "
                                        "robots × all methods × seeds 0-2, 600 s")] = False,
    worlds: Annotated[str | None, typer.Option("--worlds", help="names or MJCF paths, "
                                               "comma-separated")] = None,
    robots: Annotated[str | None, typer.Option("--robots", help="e.g. 3,6")] = None,
    methods: Annotated[str | None, typer.Option(
        "--methods", help="standalone,space,space-paper,nearest,utility,rrt")] = None,
    seeds: Annotated[str | None, typer.Option("--seeds", help="e.g. 0,1,2")] = None,
    sim_time: Annotated[float | None, typer.Option("--sim-time", help="cap per run, s")] = None,
    sample_every: Annotated[float | None, typer.Option(
        "--sample-every", help="coverage sample period, sim s")] = None,
    out: Annotated[Path | None, typer.Option("--out", help="bench folder")] = None,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    log_level: LogOpt = "WARNING",
) -> None:
    """Run the worlds × robots × methods × seeds matrix; write Tables I and II and Fig. 5."""
    from dataclasses import replace

    from services.launcher.bench import QUICK, full_spec, run_bench

    setup_logging(log_level)
    spec = QUICK if quick else full_spec()
    changes: dict[str, Any] = {}
    for name, text, cast in (("worlds", worlds, str), ("robots", robots, int),
                             ("methods", methods, str), ("seeds", seeds, int)):
        if text:
            changes[name] = _csv_list(text, cast)
    if sim_time is not None:
        changes["sim_time_s"] = sim_time
    if sample_every is not None:
        changes["sample_every_s"] = sample_every
    spec = replace(spec, **changes)
    base = service_config(config, None, set_)
    out_dir = out or Path("bench_runs") / time.strftime("%Y%m%d-%H%M%S")
    try:
        records = run_bench(spec, base, out_dir)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from exc
    failed = sum("failed" in r for r in records)
    typer.echo(f"bench folder: {out_dir} ({len(records)} runs, {failed} failed)")
    typer.echo((out_dir / "tables.md").read_text())
