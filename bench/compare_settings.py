"""Two settings compared seed for seed: the mean change of each mission metric, with a
bootstrap confidence interval over the seeds, and how many seeds a change of a given size needs.

Missions are chaotic: one changed goal sends a robot elsewhere, and a setting that is no better
moves single missions by ±20 %. Runs of the same (world, robots, seed) under both settings are
paired; the change of a metric is mean(variant) / mean(base) − 1 over the pairs of a group, and
its interval comes from resampling the pairs (seeded, so the same folders print the same
table). Where the interval holds 0 the seeds cannot tell the settings apart.

    .venv/bin/spacemap bench --robots 3 --worlds house,bookstore --seeds 0,1,2,3,4 \
        --methods space --out /tmp/base
    .venv/bin/spacemap bench --robots 3 --worlds house,bookstore --seeds 0,1,2,3,4 \
        --methods space --out /tmp/variant   # with the change (or its --set)
    .venv/bin/python bench/compare_settings.py /tmp/base/runs /tmp/variant/runs

Any folder of run folders works (`spacemap run --out DIR/NAME` per mission): runs are
recognised by their metrics.json and keyed by its world, robots and seed.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

METRICS = (  # (metrics.json key, label)
    ("mapping_time_s", "mapping time s"),
    ("total_distance_m", "distance m"),
    ("coverage_3d_pct", "3D cov %"),
    ("overlap_3d_pct", "3D overlap %"),
    ("ate_rmse_cm", "ATE cm"),
)
COVERAGE_BAR_PCT = 98.0  # issue 12's every-run bar

Key = tuple[str, int, int]  # (world stem, robots, seed)


def read_runs(folder: Path) -> dict[Key, dict]:
    """metrics.json of every run folder directly under `folder`, by (world, robots, seed)."""
    out: dict[Key, dict] = {}
    for run in sorted(p for p in folder.iterdir() if (p / "metrics.json").is_file()):
        m = json.loads((run / "metrics.json").read_text())
        key = (Path(str(m["world"])).stem, int(m["robots"]), int(m["seed"]))
        if key in out:
            raise ValueError(f"{folder}: two runs of world {key[0]}, {key[1]} robots, "
                             f"seed {key[2]}")
        out[key] = m
    return out


def relative_change(base: np.ndarray, variant: np.ndarray, rng: np.random.Generator,
                    resamples: int = 10_000, level: float = 0.95) -> tuple[float, float, float]:
    """(change, low, high): mean(variant) / mean(base) − 1 over paired values, and the
    percentile bootstrap interval of it from resampling the pairs."""
    base, variant = np.asarray(base, float), np.asarray(variant, float)
    if base.shape != variant.shape or base.ndim != 1 or base.size == 0:
        raise ValueError("base and variant must be paired 1-D arrays of equal, nonzero length")
    change = variant.mean() / base.mean() - 1.0
    picks = rng.integers(0, base.size, size=(resamples, base.size))
    boot = variant[picks].mean(axis=1) / base[picks].mean(axis=1) - 1.0
    low, high = np.quantile(boot, [(1 - level) / 2, (1 + level) / 2])
    return float(change), float(low), float(high)


def seeds_for(base: np.ndarray, variant: np.ndarray, half_width: float) -> int:
    """Seeds whose 95 % interval on the relative change would be ±`half_width` (normal
    approximation, from the spread of the pairs' relative differences seen here)."""
    rel = np.asarray(variant, float) / np.asarray(base, float) - 1.0
    if rel.size < 2:
        return 0
    return math.ceil((1.96 * float(np.std(rel, ddof=1)) / half_width) ** 2)


@dataclass(frozen=True)
class GroupComparison:
    world: str
    robots: int
    seeds: list[int]
    changes: dict[str, tuple[float, float, float, float, float]]  # key → base, variant mean,
    # change, low, high
    under_bar: tuple[int, int]  # runs under COVERAGE_BAR_PCT 3D: base, variant
    worst_bv: tuple[float, float]  # worst bounding_volume_pct: base, variant
    seeds_for_2pct: int  # mapping time


def compare(base: dict[Key, dict], variant: dict[Key, dict], seed: int = 0,
            ) -> tuple[list[GroupComparison], list[Key]]:
    """One comparison per (world, robots) over the seeds both hold, and the unpaired keys."""
    rng = np.random.default_rng(seed)
    paired = sorted(set(base) & set(variant))
    groups = sorted({(w, r) for w, r, _ in paired})
    out = []
    for world, robots in groups:
        keys = [k for k in paired if k[:2] == (world, robots)]
        b = [base[k] for k in keys]
        v = [variant[k] for k in keys]
        changes = {}
        for name, _ in METRICS:
            bx = np.array([float(m[name]) for m in b])
            vx = np.array([float(m[name]) for m in v])
            changes[name] = (float(bx.mean()), float(vx.mean()), *relative_change(bx, vx, rng))
        times = [np.array([float(m["mapping_time_s"]) for m in runs]) for runs in (b, v)]
        out.append(GroupComparison(
            world, robots, [k[2] for k in keys], changes,
            (sum(float(m["coverage_3d_pct"]) < COVERAGE_BAR_PCT for m in b),
             sum(float(m["coverage_3d_pct"]) < COVERAGE_BAR_PCT for m in v)),
            (max(float(m["bounding_volume_pct"]) for m in b),
             max(float(m["bounding_volume_pct"]) for m in v)),
            seeds_for(*times, 0.02)))
    return out, sorted(set(base) ^ set(variant))


def table(groups: list[GroupComparison]) -> str:
    """Markdown: per group and metric, base → variant means and the change with its CI."""
    head = " | ".join(label for _, label in METRICS)
    lines = [f"| world | robots | seeds | {head} | runs < 98 % | BV % worst | seeds for ±2 % |",
             "|---|---:|---:|" + "---|" * len(METRICS) + "---:|---:|---:|"]
    for g in groups:
        cells = []
        for name, _ in METRICS:
            b, v, c, lo, hi = g.changes[name]
            cells.append(f"{b:.2f} → {v:.2f} ({100 * c:+.1f} %, {100 * lo:+.1f} to "
                         f"{100 * hi:+.1f})")
        lines.append(f"| {g.world} | {g.robots} | {len(g.seeds)} | " + " | ".join(cells)
                     + f" | {g.under_bar[0]} → {g.under_bar[1]} | {g.worst_bv[0]:.4f} → "
                     f"{g.worst_bv[1]:.4f} | {g.seeds_for_2pct} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("base", type=Path, help="a folder of the base setting's run folders")
    parser.add_argument("variant", type=Path, help="a folder of the variant's run folders")
    parser.add_argument("--seed", type=int, default=0, help="the bootstrap's seed")
    args = parser.parse_args()
    try:
        groups, unpaired = compare(read_runs(args.base), read_runs(args.variant), args.seed)
    except (OSError, ValueError, KeyError) as exc:
        raise SystemExit(f"compare_settings: {exc!r}") from exc
    if not groups:
        raise SystemExit("no (world, robots, seed) run in both folders")
    print("Change of the mean, variant against base, with its 95 % bootstrap interval over the "
          "paired seeds:\n")
    print(table(groups))
    if unpaired:
        print(f"\nleft out, in one folder only: {unpaired}")


if __name__ == "__main__":
    main()
