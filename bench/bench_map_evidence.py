"""Would a merged map that leaves out its weakly observed voxels have fewer ghosts?

Replays the edge of a `bench_agent_replay.py record` recording to its end (the mission's own
merged map and final submap poses, `bench_edge_replay.replay`), sums each world voxel's
evidence (the depth points every submap put in it, `Submap.counts`), and scores the merged
map with the evaluator's metrics when the voxels whose evidence is under `ratio` × the
strongest evidence among their horizontal neighbours (same height, within `radius` cells)
are left out. Horizontal only: the agents' drift is planar, so a misplaced wall lies beside
the true one, and the floor under a chair leg must not outvote the leg.

    .venv/bin/python bench/bench_agent_replay.py record /tmp/rec_wh -- --world warehouse \
        --robots 24 --sim-time 300 --seed 1 --sample-every 0
    .venv/bin/python bench/bench_map_evidence.py /tmp/rec_wh --radius 2 --ratios 0.05,0.1,0.2

Offline only: nothing here changes a mission (docs/edge.md, "Leaving out weakly observed
voxels").
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_edge_replay import replay  # noqa: E402

from services.common.voxels import pack, unpack  # noqa: E402
from services.config import load_config  # noqa: E402
from services.edge_server.planner import EdgePlanner  # noqa: E402
from services.evaluator.evaluate import probe_for  # noqa: E402
from services.evaluator.metrics import bounding_volume_pct, coverage_3d, rmse_3d_cm  # noqa: E402


def voxel_evidence(planner: EdgePlanner) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sorted world keys, (N, 3) points, (N,) summed point counts) of the merged map."""
    merged = planner.merged
    table = merged._observations  # every submap's voxels in world keys, sorted by key
    table.compact()
    submap_of_uid = {uid: key for key, uid in merged._uids.items()}
    counts = np.zeros(table.keys.size, np.int64)
    for uid in np.unique(table.uid):
        rows = np.flatnonzero(table.uid == uid)
        counts[rows] = planner.store.submaps[submap_of_uid[int(uid)]].counts[table.idx[rows]]
    first = np.ones(table.keys.size, bool)
    first[1:] = table.keys[1:] != table.keys[:-1]
    start = np.flatnonzero(first)
    assert np.array_equal(table.keys[start], merged.keys)
    return merged.keys, np.asarray(merged.points_world, np.float64), np.add.reduceat(counts, start)


def neighbour_max(keys: np.ndarray, evidence: np.ndarray, radius: int) -> np.ndarray:
    """(N,) the largest evidence among each voxel's horizontal neighbours (not itself)."""
    ijk = unpack(keys)
    best = np.zeros(keys.size, np.int64)
    for dx in range(-radius, radius + 1):
        for dy in range(-radius, radius + 1):
            if dx == dy == 0:
                continue
            near = pack(ijk + np.array([dx, dy, 0]))
            at = np.minimum(np.searchsorted(keys, near), keys.size - 1)
            best = np.maximum(best, np.where(keys[at] == near, evidence[at], 0))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", type=Path)
    parser.add_argument("--radius", type=int, default=2, help="neighbourhood, cells")
    parser.add_argument("--ratios", default="0.05,0.1,0.2")
    args = parser.parse_args()
    _, _, mismatches, planner = replay(args.recording, None)
    if any(v != "identical" for v in mismatches.values()):
        sys.exit(f"the replay is not the mission: {mismatches}")
    probe = probe_for(load_config(args.recording / "run" / "config.yaml", {}).sim)
    keys, points, evidence = voxel_evidence(planner)
    best = neighbour_max(keys, evidence, args.radius)
    surface, observable = probe.gt.surface_points_world, probe.gt.observable_points_world
    print(f"{args.recording}: {keys.size} voxels, evidence median {np.median(evidence):.0f}\n")
    print("| voxels left out | kept % | BV % | 3D cov % | RMSE cm |\n|---|---:|---:|---:|---:|")
    rows = [("none", np.ones(keys.size, bool))] + [
        (f"evidence < {r} × neighbours' (radius {args.radius})", evidence >= r * best)
        for r in map(float, args.ratios.split(","))]
    for name, keep in rows:
        bv = bounding_volume_pct(points[keep], surface)
        print(f"| {name} | {100 * keep.mean():.1f} | {bv:.4f}"
              f" | {coverage_3d(points[keep], observable):.2f}"
              f" | {rmse_3d_cm(points[keep], surface):.2f} |")


if __name__ == "__main__":
    main()
