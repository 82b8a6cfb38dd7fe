"""The paper's tables from bench records: Table I (mapping: standalone vs SPACE) and Table II
(exploration: nearest, utility, rrt vs SPACE as written and SPACE coordinated), mean ± std
over seeds, as markdown and CSV."""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from services.edge_server.config import EdgeConfig

MERGE_DEFAULT: bool = EdgeConfig.model_fields["merge"].default


class Method(NamedTuple):
    """What a bench method sets in the mission config."""

    planner: str  # edge.planner
    drf: bool  # agent.drf (False: the standalone mapping baseline)
    merge: bool | None = None  # edge.merge; None: as the base config has it


METHODS: dict[str, Method] = {
    "standalone": Method("space", False),
    "space": Method("space", True),
    # the paper's coherent map merger (pose graph + LM) off: Table I's column beside SPACE
    "space-no-merger": Method("space", True, merge=False),
    "space-merger": Method("space", True, merge=True),  # on whatever the base config says
    "space-paper": Method("space-paper", True),
    "nearest": Method("nearest", True),
    "utility": Method("utility", True),
    "rrt": Method("rrt", True),
}
TABLE1_METHODS = ("standalone", "space-no-merger", "space")
# a bench's methods unless named: `space-merger` is `space` under the default config
BENCH_METHODS = tuple(m for m in METHODS if m != "space-merger")


def method_name(planner: str, drf: bool, merge: bool = MERGE_DEFAULT) -> str:
    """The bench method a run's config amounts to (the planner's name when none fits); a
    method that leaves the merger to the base config names the runs with its default."""
    for name, how in METHODS.items():
        wants = MERGE_DEFAULT if how.merge is None else how.merge
        if (how.planner, how.drf, wants) == (planner, drf, merge):
            return name
    return planner if drf else "standalone"


TABLE2_METHODS = ("nearest", "utility", "rrt", "space-paper", "space")
TABLE1_METRICS = {
    "coverage_3d_pct": "3D coverage (%)", "bounding_volume_pct": "bounding volume (%)",
    "rmse_3d_cm": "3D RMSE (cm)", "ate_rmse_cm": "ATE (cm)",
    "overlap_3d_pct": "3D overlap (%)", "coverage_2d_pct": "2D coverage (%)",
    "mapping_time_s": "mapping time (s)",
}
TABLE2_METRICS = {
    "mapping_time_s": "mapping time (s)", "t90_s": "T90 3D (s)", "total_distance_m":
    "total distance (m)", "coverage_2d_pct": "2D coverage (%)", "coverage_3d_pct":
    "3D coverage (%)", "overlap_2d_pct": "2D overlap (%)", "overlap_3d_pct": "3D overlap (%)",
    "completed": "completed runs",
}


def mean_std(values: Iterable[Any]) -> tuple[float | None, float | None, int]:
    """(mean, sample std (0 for one value), n) of the non-null values; bools count as 0/1."""
    xs = [float(v) for v in values if v is not None]
    if not xs:
        return None, None, 0
    mean = sum(xs) / len(xs)
    var = sum((x - mean) ** 2 for x in xs) / (len(xs) - 1) if len(xs) > 1 else 0.0
    return mean, math.sqrt(var), len(xs)


def fmt_mean_std(mean: float | None, std: float | None, n: int, total: int) -> str:
    if mean is None:
        return "n/a"
    text = f"{mean:.3g} ± {std:.2g}" if abs(mean) < 1 else f"{mean:.1f} ± {std:.1f}"
    return text if n == total else f"{text} (n={n}/{total})"


def group(records: Sequence[Mapping[str, Any]]) -> dict[tuple[str, int, str], list[Mapping]]:
    """Records keyed by (world, robots, method), in first-seen order."""
    out: dict[tuple[str, int, str], list[Mapping]] = {}
    for rec in records:
        out.setdefault((rec["world_label"], int(rec["robots"]), rec["method"]), []).append(rec)
    return out


def table_markdown(
    records: Sequence[Mapping[str, Any]], methods: Sequence[str], metrics: Mapping[str, str],
    title: str,
) -> str:
    """One markdown table per (world, robots): rows = metrics, columns = methods."""
    groups = group(records)
    scenes = list(dict.fromkeys((w, r) for w, r, _ in groups))
    lines = [f"### {title}", ""]
    for world, robots in scenes:
        present = [mt for mt in methods if (world, robots, mt) in groups]
        if not present:
            continue
        lines += [f"**{world}, {robots} robots**", "",
                  "| metric | " + " | ".join(present) + " |",
                  "|---|" + "---:|" * len(present)]
        for key, label in metrics.items():
            cells = []
            for mt in present:
                recs = groups[(world, robots, mt)]
                if key == "completed":  # a count reads better than a mean of booleans
                    cells.append(f"{sum(bool(r.get(key)) for r in recs)}/{len(recs)}")
                    continue
                cells.append(fmt_mean_std(*mean_std(r.get(key) for r in recs), len(recs)))
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def write_table_csv(
    path: Path, records: Sequence[Mapping[str, Any]], methods: Sequence[str],
    metrics: Mapping[str, str],
) -> None:
    """Long format: world, robots, method, metric, mean, std, n, runs."""
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["world", "robots", "method", "metric", "mean", "std", "n", "runs"])
        for (world, robots, method), recs in group(records).items():
            if method not in methods:
                continue
            for key in metrics:
                mean, std, n = mean_std(r.get(key) for r in recs)
                writer.writerow([world, robots, method, key, "" if mean is None else mean,
                                 "" if std is None else std, n, len(recs)])


def bv_ratio_lines(records: Sequence[Mapping[str, Any]]) -> list[str]:
    """Standalone BV ÷ SPACE BV per scene (the issue's ≥ 100× check)."""
    groups, lines = group(records), []
    for (world, robots, method), recs in groups.items():
        if method != "space" or (world, robots, "standalone") not in groups:
            continue
        space, _, _ = mean_std(r.get("bounding_volume_pct") for r in recs)
        alone, _, _ = mean_std(r.get("bounding_volume_pct") for r in
                               groups[(world, robots, "standalone")])
        if space is None or alone is None:
            continue
        ratio = "∞ (SPACE has no ghost voxels)" if space == 0 else f"{alone / space:.1f}×"
        lines.append(f"- {world}, {robots} robots: BV standalone {alone:.4f} % vs SPACE "
                     f"{space:.4f} % → {ratio} (target ≥ 100×, SPACE ≤ 0.01 %)")
    return lines
