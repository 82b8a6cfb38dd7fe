"""Bi-variate frontier detection (Alg. 1) on a merged map of the house; prints a markdown table.

The map: the built-in house's sensed surfaces (services.evaluator.surfaces) sampled at
`--density` points/m², voxelized at ϱ = 0.05 m (what P* looks like once explored: voxel
centres), optionally cropped to z ≤ `--z-max`. Timed (medians of `--repeats`):
- ours: `detect_point_frontiers` (downsample, exact ρ and σ² within r_s from per-column z bit
  masks and lookup tables, `ball_sums.py`, both masks);
- baseline: the paper's per-point loop with a scipy cKDTree (query_ball_point per point, then
  count and variance per point), the same cloud and r_s, timed once (it is slow).
Both are checked to give the same ρ and σ².
- incremental (what a plan runs, frontier_cache.py): the same map less `--new` voxels (a
  contiguous run of the sorted keys: a patch of newly seen surface, ~ one edge tick's growth in
  house missions) is loaded untimed, then the update that adds them and reads ρ, σ² for all
  voxels (and for z ≤ 1.5 m, the frontier band the planner reads) is timed; checked equal.

Run: .venv/bin/python bench/bench_frontiers.py [--repeats 7] [--density 400]
"""

from __future__ import annotations

import argparse
import logging
import statistics
import time

import numpy as np
from scipy.spatial import cKDTree

from services.common.voxels import pack
from services.edge_server.config import EdgeConfig
from services.edge_server.frontier_cache import IncrementalFrontiers
from services.edge_server.frontiers3d import detect_point_frontiers
from services.evaluator.surfaces import surface_samples
from services.simulator.worlds import load_world

log = logging.getLogger("bench_frontiers")


def house_map(density: float, z_max: float, voxel_m: float) -> np.ndarray:
    model = load_world("house").compile()
    points, _, _ = surface_samples(model, density_per_m2=density)
    points = points[points[:, 2] <= z_max]
    idx = np.unique(np.floor(points / voxel_m).astype(np.int64), axis=0)
    return (idx + 0.5) * voxel_m


def kdtree_loop(points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The per-point loop of Alg. 1 with a KD-tree (the reference implementation's way)."""
    tree = cKDTree(points)
    rho = np.zeros(len(points), np.int64)
    var = np.zeros(len(points))
    for i, p in enumerate(points):
        nb = points[tree.query_ball_point(p, radius)]
        rho[i] = len(nb)
        var[i] = ((nb - nb.mean(axis=0)) ** 2).sum(axis=1).mean()
    return rho, var


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--density", type=float, default=400.0)
    ap.add_argument("--z-max", type=float, default=2.0)
    ap.add_argument("--new", type=int, default=3000, help="voxels added per incremental plan")
    args = ap.parse_args()
    cfg = EdgeConfig()
    points = house_map(args.density, args.z_max, cfg.frontier_voxel_m)
    radius = cfg.search_radius_m

    def ours():
        return detect_point_frontiers(points, cfg.frontier_voxel_m, radius,
                                      cfg.density_threshold, cfg.variance_threshold_m2)

    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        pf = ours()
        times.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    # + 1e-9: the lattice points at exactly r_s count, as in ours (float round-off)
    rho, var = kdtree_loop(pf.points_world, radius + 1e-9)
    t_loop = time.perf_counter() - t0
    assert np.array_equal(rho, pf.rho) and np.allclose(var, pf.var_m2, atol=1e-9)
    ms = 1000 * statistics.median(times)
    keys = np.sort(pack(pf.indices))
    start = len(keys) // 2
    new = keys[start : start + args.new]
    old = np.concatenate([keys[:start], keys[start + args.new :]])
    inc_ms = {}
    for z_max in (np.inf, cfg.frontier_z_max_m):
        t_inc = []
        for _ in range(args.repeats):
            inc = IncrementalFrontiers(cfg.frontier_voxel_m, radius, cfg.density_threshold,
                                       cfg.variance_threshold_m2, z_max)
            inc.update(old)
            t0 = time.perf_counter()
            got = inc.update(keys, new)
            t_inc.append(time.perf_counter() - t0)
        inc_ms[z_max] = 1000 * statistics.median(t_inc)
    assert np.array_equal(got.rho, pf.rho[pf.points_world[:, 2] <= cfg.frontier_z_max_m])
    log.info("house merged map: %d voxels (ϱ = %.2f m), r_s = %.2f m, %d F_u and %d F_w points",
             len(pf.rho), cfg.frontier_voxel_m, radius, int(pf.unexplored.sum()),
             int(pf.weak.sum()))
    log.info("| method | time (ms) | ratio |\n|---|---|---|")
    log.info("| ours: lattice stencil, exact ρ + σ² (median of %d) | %.1f | 1× |", args.repeats, ms)
    log.info("| per-point cKDTree loop (once) | %.0f | %.1f× slower |", 1000 * t_loop,
             1000 * t_loop / ms)
    for z_max, t in inc_ms.items():
        log.info("| ours incremental: +%d voxels, read all with z ≤ %s m (median of %d) | %.1f "
                 "| %.1f× faster |", len(new), z_max, args.repeats, t, ms / t)


if __name__ == "__main__":
    main()
