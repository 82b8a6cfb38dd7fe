"""Planners compared at equal 3D coverage: how long, and how far, each takes to map as much as
the reference planner had mapped when it stopped.

Issue 12 compares mean mapping times, but a planner that stops early (rrt ends when its 2D grid
has no frontier, often under 98 % 3D coverage) then looks fast for mapping less. Here, for
every (world, robots, seed) run of the reference planner, the level is its final 3D coverage
(metrics.json), and each planner's time to that level is the first time-series row at or
above it (rows every `--sample-every` sim seconds: the figure is an upper bound, at most one
period late), with the distance driven and the 3D overlap of that row.

    .venv/bin/spacemap bench --robots 3 \
        --worlds house,bookstore,../shared/worlds/aws_small_house/small_house.xml \
        --methods rrt,space --seeds 0,1,2,3,4 --sim-time 500 --sample-every 5 --out DIR
    .venv/bin/python bench/bench_equal_coverage.py DIR/runs --reference rrt --against space
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
from pathlib import Path

import numpy as np
from compare_settings import relative_change


def read_run(run: Path) -> tuple[dict, list[dict[str, float]]]:
    metrics = json.loads((run / "metrics.json").read_text())
    with (run / "timeseries.csv").open() as f:
        rows = [{k: float(v) for k, v in row.items() if v not in ("", None)}
                for row in csv.DictReader(f)]
    return metrics, rows


CSV_ROUNDING = 1e-4  # timeseries.csv keeps 4 decimals: the final row of 93.33653 % reads 93.3365


def first_at(rows: list[dict[str, float]], level: float) -> dict[str, float] | None:
    """The first time-series row whose 3D coverage reaches `level` (to the CSV's rounding),
    or None."""
    return next((r for r in rows if r.get("coverage_3d_pct", -1.0) >= level - CSV_ROUNDING),
                None)


def runs_by_key(folder: Path) -> dict[tuple[str, int, str, int], Path]:
    out = {}
    for run in sorted(p for p in folder.iterdir() if (p / "metrics.json").is_file()):
        m = json.loads((run / "metrics.json").read_text())
        out[(Path(str(m["world"])).stem, int(m["robots"]), str(m["planner"]), int(m["seed"]))] = run
    return out


def compare(folder: Path, reference: str, against: list[str]) -> list[dict]:
    runs = runs_by_key(folder)
    table = []
    for (world, robots, planner, seed), run in sorted(runs.items()):
        if planner != reference:
            continue
        ref_metrics, ref_rows = read_run(run)
        level = float(ref_metrics["coverage_3d_pct"])
        ref_first = first_at(ref_rows, level)
        entry = {"world": world, "robots": robots, "seed": seed, "level": level,
                 reference: (ref_first["sim_time_s"] if ref_first else None,
                             ref_first.get("distance_m") if ref_first else None,
                             ref_first.get("overlap_3d_pct") if ref_first else None),
                 f"{reference} stop": float(ref_metrics["mapping_time_s"])}
        for other in against:
            key = (world, robots, other, seed)
            if key not in runs:
                entry[other] = None
                continue
            row = first_at(read_run(runs[key])[1], level)
            entry[other] = ((row["sim_time_s"], row.get("distance_m"), row.get("overlap_3d_pct"))
                            if row else (None, None, None))
        table.append(entry)
    return table


def _mean(values: list[float | None]) -> str:
    got = [v for v in values if v is not None]
    return f"{statistics.mean(got):.1f}" if got else "–"


def report(table: list[dict], reference: str, against: list[str]) -> None:
    names = [reference, *against]
    head = " | ".join(f"{n} time s / distance m / 3D overlap %" for n in names)
    print(f"| world | robots | seed | level 3D % | {reference} stops s | {head} |")
    print("|---|---:|---:|---:|---:|" + "---|" * len(names))
    for e in table:
        cells = []
        for n in names:
            t, d, o = e[n] if e.get(n) else (None, None, None)
            cells.append("never" if t is None else f"{t:.0f} / {d:.1f} / {o:.1f}")
        print(f"| {e['world']} | {e['robots']} | {e['seed']} | {e['level']:.2f} | "
              f"{e[f'{reference} stop']:.0f} | " + " | ".join(cells) + " |")
    print("\nMeans over the seeds where every planner reached the level (paired):\n")
    print("| world | robots | seeds | "
          + " | ".join(f"{n} time s | {n} distance m" for n in names) + " |")
    print("|---|---:|---:|" + "---:|---:|" * len(names))
    for world, robots in sorted({(e["world"], e["robots"]) for e in table}):
        group = [e for e in table if (e["world"], e["robots"]) == (world, robots)
                 and all(e.get(n) and e[n][0] is not None for n in names)]
        cells = []
        for n in names:
            cells += [_mean([e[n][0] for e in group]), _mean([e[n][1] for e in group])]
        print(f"| {world} | {robots} | {len(group)} | " + " | ".join(cells) + " |")
    _report_changes(table, reference, against)


def _report_changes(table: list[dict], reference: str, against: list[str]) -> None:
    """Each planner's time and distance at the level against the reference's, with the 95 %
    bootstrap interval over the seeds (compare_settings.py's)."""
    print(f"\nChange against {reference} at its level, 95 % bootstrap interval over the "
          "paired seeds:\n")
    print("| world | robots | " + " | ".join(f"{n} seeds | {n} time | {n} distance"
                                          for n in against) + " |")
    print("|---|---:|" + "---:|---|---|" * len(against))
    rng = np.random.default_rng(0)
    for world, robots in sorted({(e["world"], e["robots"]) for e in table}):
        cells = []
        for n in against:
            group = [e for e in table if (e["world"], e["robots"]) == (world, robots)
                     and e.get(n) and e[n][0] is not None and e[reference][0] is not None]
            cells.append(str(len(group)))
            for i in (0, 1):  # time, distance (a series without distances: left out)
                pairs = [(e[reference][i], e[n][i]) for e in group
                         if e[reference][i] is not None and e[n][i] is not None]
                if not pairs:
                    cells.append("–")
                    continue
                c, lo, hi = relative_change(*np.array(pairs, float).T, rng)
                cells.append(f"{100 * c:+.1f} % ({100 * lo:+.1f} to {100 * hi:+.1f})")
        print(f"| {world} | {robots} | " + " | ".join(cells) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", type=Path, help="a folder of run folders (spacemap bench's runs/)")
    parser.add_argument("--reference", default="rrt")
    parser.add_argument("--against", default="space", help="comma-separated planners")
    args = parser.parse_args()
    against = [a for a in args.against.split(",") if a]
    report(compare(args.runs, args.reference, against), args.reference, against)


if __name__ == "__main__":
    main()
