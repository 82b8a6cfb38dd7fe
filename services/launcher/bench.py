"""`spacemap bench`: worlds × robot counts × methods × seeds, run in sequence, into the
paper's tables (markdown + CSV, mean ± std) and Fig. 5 style coverage-over-time plots."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from services.config import SpacemapConfig
from services.evaluator import run_files as rf
from services.evaluator import tables as tb
from services.evaluator.plots import plot_methods_coverage, world_label
from services.launcher.run import MissionError, run_mission

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BenchSpec:
    worlds: tuple[str, ...] = ("house",)
    robots: tuple[int, ...] = (3,)
    methods: tuple[str, ...] = tb.BENCH_METHODS
    seeds: tuple[int, ...] = (0, 1)
    sim_time_s: float = 150.0
    sample_every_s: float = 5.0


QUICK = BenchSpec()
AWS_HOUSE = Path(__file__).resolve().parents[2].parent / "shared" / "worlds" / \
    "aws_small_house" / "small_house.xml"


def full_spec() -> BenchSpec:
    """The issue's matrix: house and bookstore (and the AWS small house when ../shared has
    it) with 3 and 6 robots, every method, 3 seeds, 600 s cap."""
    worlds = ("house", "bookstore") + ((str(AWS_HOUSE),) if AWS_HOUSE.exists() else ())
    return BenchSpec(worlds=worlds, robots=(3, 6), seeds=(0, 1, 2), sim_time_s=600.0)


def mission_config(base: SpacemapConfig, world: str, robots: int, method: str, seed: int,
                   sim_time_s: float) -> SpacemapConfig:
    how = tb.METHODS[method]
    tree = base.model_dump(mode="json")
    tree["sim"].update(world=world, robots=robots, seed=seed, max_sim_time_s=sim_time_s,
                       spawn=None)
    tree["edge"]["planner"] = how.planner
    tree["agent"]["drf"] = how.drf
    if how.merge is not None:
        tree["edge"]["merge"] = how.merge
    return SpacemapConfig.model_validate(tree)


def matrix(spec: BenchSpec) -> list[tuple[str, int, str, int]]:
    return [(w, r, mt, s) for w in spec.worlds for r in spec.robots for mt in spec.methods
            for s in spec.seeds]


def run_bench(spec: BenchSpec, base: SpacemapConfig, out_dir: Path,
              console: Console | None = None) -> list[dict[str, Any]]:
    """Every mission of the matrix in sequence; tables and figures written at the end
    (bench.json is rewritten after each run, so an interrupted bench keeps its records)."""
    unknown = set(spec.methods) - set(tb.METHODS)
    if unknown:
        raise ValueError(f"unknown method(s) {sorted(unknown)}; known: {list(tb.METHODS)}")
    out_dir.mkdir(parents=True, exist_ok=True)
    console = console or Console(stderr=True)
    records: list[dict[str, Any]] = []
    cells = matrix(spec)
    columns = (TextColumn("[bold]bench"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn(), TextColumn("{task.fields[now]}"))
    with Progress(*columns, console=console) as bar:
        task = bar.add_task("bench", total=len(cells), now="")
        for world, robots, method, seed in cells:
            name = f"{world_label(world)}_{robots}r_{method}_s{seed}"
            bar.update(task, now=name)
            records.append(_one(spec, base, out_dir / "runs" / name, world, robots, method,
                                seed))
            rf.write_json(out_dir / "bench.json", {"records": records})
            bar.advance(task)
    write_outputs(records, out_dir)
    return records


def _one(spec: BenchSpec, base: SpacemapConfig, run_dir: Path, world: str, robots: int,
         method: str, seed: int) -> dict[str, Any]:
    cfg = mission_config(base, world, robots, method, seed, spec.sim_time_s)
    meta = {"method": method, "world_label": world_label(world), "run_dir": str(run_dir)}
    t0 = time.monotonic()
    try:
        result = run_mission(cfg, run_dir, console=Console(quiet=True),
                             sample_every_s=spec.sample_every_s)
    except (MissionError, OSError, RuntimeError) as exc:
        log.error("%s failed after %.0f s: %s", run_dir.name, time.monotonic() - t0, exc)
        return {**meta, "robots": robots, "world": world, "seed": seed, "failed": str(exc)}
    return {**result.metrics, **meta}


def write_outputs(records: list[dict[str, Any]], out_dir: Path) -> None:
    """table1.md/.csv, table2.md/.csv, tables.md and fig5_<world>_<robots>r.png."""
    ok = [r for r in records if "failed" not in r]
    t1 = tb.table_markdown(ok, tb.TABLE1_METHODS, tb.TABLE1_METRICS,
                           "Table I: mapping, standalone (no DRF) vs SPACE, map merger off and on")
    t2 = tb.table_markdown(ok, tb.TABLE2_METHODS, tb.TABLE2_METRICS,
                           "Table II: exploration, nearest / utility / rrt vs SPACE")
    (out_dir / "table1.md").write_text(t1)
    (out_dir / "table2.md").write_text(t2)
    tb.write_table_csv(out_dir / "table1.csv", ok, tb.TABLE1_METHODS, tb.TABLE1_METRICS)
    tb.write_table_csv(out_dir / "table2.csv", ok, tb.TABLE2_METHODS, tb.TABLE2_METRICS)
    failed = [f"- {r['run_dir']}: {r['failed']}" for r in records if "failed" in r]
    parts = [t1, t2, "### Bounding volume, standalone vs SPACE", "",
             *(tb.bv_ratio_lines(ok) or ["- n/a (needs both methods)"]), ""]
    if failed:
        parts += ["### Failed runs", "", *failed, ""]
    (out_dir / "tables.md").write_text("\n".join(parts))
    for (world, robots), curves in _curves(ok).items():
        plot_methods_coverage(curves, out_dir / f"fig5_{world}_{robots}r.png",
                              f"3D coverage over time, {world}, {robots} robots")


def _curves(records: list[dict[str, Any]]) -> dict[tuple[str, int], dict[str, list]]:
    """(world, robots) → method → [(sim times, 3D coverage)] from each run's timeseries.csv."""
    out: dict[tuple[str, int], dict[str, list]] = {}
    for rec in records:
        path = Path(rec["run_dir"]) / rf.TIMESERIES
        if not path.exists():
            continue
        rows = [r for r in rf.read_csv(path) if r.get("coverage_3d_pct") is not None]
        t = np.array([r["sim_time_s"] for r in rows])
        c = np.array([r["coverage_3d_pct"] for r in rows])
        scene = out.setdefault((rec["world_label"], int(rec["robots"])), {})
        scene.setdefault(rec["method"], []).append((t, c))
    return out
