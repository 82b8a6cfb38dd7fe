"""Tables I and II (mean ± std) and Fig. 5 from finished run folders, as `spacemap bench`
writes them, for missions run one by one (`spacemap run ... --out DIR`).

    .venv/bin/python bench/bench_tables.py OUT_DIR RUN_DIR [RUN_DIR ...]

A run's method is its planner (`standalone` when it ran without the DRF, `space-no-merger`
with the map merger off: `tables.method_name`), its world and
robot count come from its metrics.json; Fig. 5 needs runs with a time series
(`--sample-every` > 0). Folders without metrics.json are listed and left out; other paths
(logs beside the runs) are ignored.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from services.evaluator.evaluate import RunConfig
from services.evaluator.plots import world_label
from services.evaluator.tables import method_name
from services.launcher.bench import write_outputs


def record(run_dir: Path) -> dict[str, Any]:
    """One bench record from a run folder's metrics.json."""
    metrics = json.loads((run_dir / "metrics.json").read_text())
    merge = metrics.get("merge")
    if merge is None:  # a run from before metrics.json named it
        config = run_dir / "config.yaml"
        merge = config.exists() and RunConfig.read(config).merge
    method = method_name(metrics["planner"], metrics.get("drf", True), bool(merge))
    return {**metrics, "method": method, "world_label": world_label(str(metrics["world"])),
            "run_dir": str(run_dir)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder for table1/2 .md/.csv and fig5 PNGs")
    parser.add_argument("runs", type=Path, nargs="+", help="run folders")
    args = parser.parse_args(argv)
    records, missing = [], []
    for run in (r for r in args.runs if r.is_dir()):
        (records if (run / "metrics.json").exists() else missing).append(run)
    records = [record(r) for r in sorted(records)]
    args.out.mkdir(parents=True, exist_ok=True)
    write_outputs(records, args.out)
    for run in missing:
        print(f"left out (no metrics.json): {run}", file=sys.stderr)
    print((args.out / "table2.md").read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
