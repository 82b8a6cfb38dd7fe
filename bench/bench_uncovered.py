"""Where a run's 3D coverage is missing: the observable truth points no merged-map point covers.

Prints how many there are, split by height, and for a random sample whether some reachable
viewpoint of the truth lattice sees them at all (range, vertical FoV, a clear ray) and whether
one sees them within the sensor's incidence limit. With --plot, draws them over the merged grid
with the robots' true tracks.

    .venv/bin/python bench/bench_uncovered.py RUN [--sample 1500] [--max-incidence 80]
        [--plot uncovered.png]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from services.evaluator import run_files as rf  # noqa: E402
from services.evaluator.evaluate import RunConfig, load_tracks, probe_for  # noqa: E402
from services.evaluator.observable import _visible_along_rays, viewpoints  # noqa: E402
from services.evaluator.surfaces import sensed_groups, surface_samples  # noqa: E402
from services.simulator.worlds import load_world  # noqa: E402

HEIGHT_BINS_M = (-0.1, 0.3, 0.6, 1.0, 1.5, 2.0, 2.5, 10.0)


def seen_from_some_view(model: mujoco.MjModel, points: np.ndarray, normals: np.ndarray,
                        views: np.ndarray, range_m: float, max_elevation_deg: float,
                        max_incidence_deg: float, tries: int = 200) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """(N,) bool twice: some view sees the point; some view sees it within the incidence."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    groups = sensed_groups(model)
    geomgroup = np.array([g in groups for g in range(6)], np.uint8)
    tree = cKDTree(views[:, :2])
    cos_max = np.cos(np.radians(max_incidence_deg))
    at_all = np.zeros(len(points), bool)
    within = np.zeros(len(points), bool)
    for i, (p, n) in enumerate(zip(points, normals, strict=True)):
        near = views[tree.query_ball_point(p[:2], range_m)]
        delta = p - near
        dist = np.linalg.norm(delta, axis=1)
        elevation = np.degrees(np.arctan2(np.abs(delta[:, 2]), np.hypot(*delta[:, :2].T)))
        allowed = (dist <= range_m) & (elevation <= max_elevation_deg) & (dist > 0)
        near, delta, dist = near[allowed], delta[allowed], dist[allowed]
        square_on = np.abs((delta / dist[:, None]) @ n) >= cos_max
        for mask, out in ((square_on, within), (np.ones(len(near), bool), at_all)):
            for origin in near[mask][:tries]:
                if _visible_along_rays(model, data, origin, p[None], geomgroup,
                                       range_m + 0.1)[0]:
                    out[i] = True
                    break
    return at_all, within


def plot(run: Path, uncovered: np.ndarray, robots: int, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = rf.read_grid(run / rf.MERGED_GRID)
    h, w = grid.cells.shape
    shade = np.where(grid.cells < 0, 0.5, np.where(grid.cells > 50, 0.0, 1.0))
    fig, ax = plt.subplots(figsize=(12, 9))
    ax.imshow(shade, origin="lower", cmap="gray", vmin=0, vmax=1, extent=(
        grid.origin_x, grid.origin_x + w * grid.resolution_m, grid.origin_y,
        grid.origin_y + h * grid.resolution_m))
    dots = ax.scatter(uncovered[:, 0], uncovered[:, 1], c=uncovered[:, 2], s=1, cmap="jet",
                      vmin=0.0, vmax=2.2)
    fig.colorbar(dots, label="height of the uncovered truth point, m")
    for _, xy in load_tracks(run, robots):
        ax.plot(xy[:, 0], xy[:, 1], lw=0.5)
    ax.set_title(f"{run.name}: uncovered observable truth (grid: white free, black occupied)")
    fig.savefig(out, dpi=80)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--sample", type=int, default=1500)
    parser.add_argument("--max-incidence", type=float, default=80.0)
    parser.add_argument("--plot", type=Path)
    args = parser.parse_args()
    config = RunConfig.read(args.run / "config.yaml")
    probe = probe_for(config.sim)
    gt, ev = probe.gt, probe.ev
    covered_by = rf.read_ply(args.run / rf.MERGED_MAP)
    merged = covered_by if isinstance(covered_by, np.ndarray) else covered_by[0]
    observable = np.flatnonzero(gt.observable)
    dist, _ = cKDTree(merged).query(gt.surface_points_world[observable],
                                    distance_upper_bound=ev.coverage_radius_m)
    missing = observable[~np.isfinite(dist)]
    points = gt.surface_points_world[missing]
    print(f"{args.run}: {len(missing)} of {len(observable)} observable truth points uncovered "
          f"({100 * len(missing) / max(len(observable), 1):.2f} %)")
    counts, _ = np.histogram(points[:, 2], bins=HEIGHT_BINS_M)
    for lo, hi, n in zip(HEIGHT_BINS_M[:-1], HEIGHT_BINS_M[1:], counts, strict=True):
        print(f"  height {lo:5.1f} to {hi:4.1f} m: {n}")
    model = load_world(config.sim.world).compile()
    samples, _, normal = surface_samples(model, ev.density_per_m2, seed=ev.seed)
    if samples.shape != gt.surface_points_world.shape or not np.allclose(
            samples, gt.surface_points_world):
        sys.exit("the cached truth's samples differ from the world's: rebuild the cache")
    rng = np.random.default_rng(0)
    pick = rng.choice(len(missing), min(args.sample, len(missing)), replace=False)
    views = viewpoints(gt.free_grid, ev.camera_height_m, ev.viewpoint_spacing_m)
    at_all, within = seen_from_some_view(model, points[pick], normal[missing[pick]],
                                         views, ev.range_m, ev.max_elevation_deg,
                                         args.max_incidence)
    print(f"  of {len(pick)} sampled: seen from some reachable viewpoint {at_all.mean():.3f}, "
          f"within {args.max_incidence:g}° incidence {within.mean():.3f}")
    if args.plot:
        plot(args.run, points, config.sim.robots, args.plot)
        print(f"  plot: {args.plot}")


if __name__ == "__main__":
    main()
