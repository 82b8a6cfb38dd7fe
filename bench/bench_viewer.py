"""What the recordings and the live view cost a mission: `spacemap run` with the recorders
off (`--set record.rrd=false --set record.mcap=false`), with them on (the default: mission.rrd
and mission.mcap) and with the live view too (`--view --view-to serve:PORT`: a rerun gRPC
server, so no display is needed, plus the cameras), interleaved, medians of wall time and
launcher CPU; sizes of mission.mcap/.rrd; whether metrics.json is the same in every mode.

    .venv/bin/python bench/bench_viewer.py --repeats 3            # the default mission
    .venv/bin/python bench/bench_viewer.py --sim-time 60 --repeats 1
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_mission import run_once  # noqa: E402

from services.processes import free_tcp_port  # noqa: E402

MODES = {
    "off": ["--set", "record.rrd=false", "--set", "record.mcap=false"],
    "record": [],
    "view": ["--view", "--view-to", "serve:{port}"],
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--world", default="house")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sim-time", type=float, default=None,
                        help="sim-time cap (default: the config's, the default mission)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--modes", default="off,record,view")
    parser.add_argument("--keep", type=Path, default=None, help="keep the run folders here")
    opts = parser.parse_args()
    base = ["--robots", str(opts.robots), "--world", opts.world, "--seed", str(opts.seed)]
    if opts.sim_time is not None:
        base += ["--sim-time", str(opts.sim_time)]
    modes = opts.modes.split(",")
    results: dict[str, list[tuple[dict, dict, dict[str, int]]]] = {m: [] for m in modes}
    with tempfile.TemporaryDirectory() as tmp:
        root = opts.keep or Path(tmp)
        for i in range(opts.repeats):
            for mode in modes:  # interleaved, so a change in the machine's load hits all
                out = root / f"{mode}{i}"
                args = base + [a.format(port=free_tcp_port()) for a in MODES[mode]]
                metrics, profile = run_once(out, args)
                sizes = {p.name: p.stat().st_size for p in out.glob("mission.*")}
                results[mode].append((metrics, profile, sizes))
                print(f"{mode} run {i}: wall {profile['wall_time_s']:.1f} s, launcher CPU "
                      f"{profile['cpu_s']['launcher']:.1f} s, {sizes}", file=sys.stderr)
    print(f"spacemap run {' '.join(base)}; modes interleaved, {opts.repeats} runs each, "
          "medians\n")
    print("| mode | wall s | launcher CPU s | total CPU s | mission.mcap MB | mission.rrd MB |")
    print("|---|---:|---:|---:|---:|---:|")
    walls = {}
    for mode, runs in results.items():
        walls[mode] = statistics.median(p["wall_time_s"] for _, p, _ in runs)
        launcher = statistics.median(p["cpu_s"]["launcher"] for _, p, _ in runs)
        total = statistics.median(p["cpu_s_total"] for _, p, _ in runs)
        mb = [statistics.median(s.get(n, 0) for _, _, s in runs) / 1e6
              for n in ("mission.mcap", "mission.rrd")]
        print(f"| {mode} | {walls[mode]:.1f} | {launcher:.1f} | {total:.1f} | {mb[0]:.1f} | "
              f"{mb[1]:.1f} |")
    if "off" in walls:
        for mode in modes:
            if mode != "off":
                print(f"\n{mode} vs off: wall {100 * (walls[mode] / walls['off'] - 1):+.1f} %")
    first = [{k: v for k, v in r[0].items() if k != "wall_time_s"}
             for runs in results.values() for r in runs]
    print(f"\nmetrics.json identical apart from wall_time_s in every run and mode: "
          f"{all(f == first[0] for f in first)}")
    print(json.dumps({m: [p["real_time_factor"] for _, p, _ in r] for m, r in results.items()}))


if __name__ == "__main__":
    main()
