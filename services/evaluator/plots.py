"""PNG figures (matplotlib Agg): coverage over time, the merged map from above, Fig. 5 style
coverage curves per method."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib import pyplot

MAP_CELL_M = 0.05  # the map from above: one pixel per voxel column


def _pyplot() -> pyplot:
    """matplotlib's pyplot on the Agg backend (headless: no display on the evaluation
    machine), imported when a figure is drawn: it costs about 1 CPU-s, and the launcher
    imports this module for its labels at a mission's start."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot

    return pyplot


def world_label(world: str) -> str:
    """A short name for a world given by name or MJCF path ("../worlds/small_house.xml" →
    "small_house"), for titles, tables and the terminal panel."""
    return Path(world).stem if world.endswith(".xml") or "/" in world else world


def plot_label(metrics: Mapping[str, Any]) -> str:
    """"world, N robots, planner[, no DRF]" of a run's metrics, for figure titles."""
    return (f"{world_label(str(metrics['world']))}, {metrics['robots']} robots, "
            f"{metrics['planner']}" + ("" if metrics.get("drf", True) else ", no DRF"))


def _column(rows: Sequence[Mapping[str, Any]], key: str) -> np.ndarray:
    return np.array([np.nan if r.get(key) is None else r[key] for r in rows], dtype=float)


def plot_coverage(rows: Sequence[Mapping[str, Any]], path: Path, title: str = "") -> None:
    """3D / 2D coverage and 3D overlap (%) over sim time, bounding volume on a second axis."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    t = _column(rows, "sim_time_s")
    for key, label in (("coverage_3d_pct", "3D coverage"), ("coverage_2d_pct", "2D coverage"),
                       ("overlap_3d_pct", "3D overlap")):
        ax.plot(t, _column(rows, key), marker=".", label=label)
    ax.set(xlabel="sim time (s)", ylabel="%", ylim=(0, 100), title=title or "coverage over time")
    ax.grid(alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(t, _column(rows, "bounding_volume_pct"), color="tab:red", ls="--", label="BV %")
    ax2.set_ylabel("bounding volume (%)", color="tab:red")
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def top_heights(points_world: np.ndarray, cell_m: float
                ) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """(H, W) highest z of the points in each `cell_m` column seen from above (NaN where
    none), and its (x0, x1, y0, y1) extent: the map from above as one image, which draws in
    a fraction of the time a scatter of its points takes."""
    pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    lo = np.floor(pts[:, :2].min(axis=0) / cell_m) * cell_m
    ij = np.floor((pts[:, :2] - lo) / cell_m).astype(np.int64)
    shape = (int(ij[:, 1].max()) + 1, int(ij[:, 0].max()) + 1)
    top = np.full(shape, -np.inf)
    np.maximum.at(top, (ij[:, 1], ij[:, 0]), pts[:, 2])
    top[np.isinf(top)] = np.nan
    return top, (lo[0], lo[0] + shape[1] * cell_m, lo[1], lo[1] + shape[0] * cell_m)


def plot_map_top(
    points_world: np.ndarray,
    trajectories_xy: Sequence[np.ndarray],
    frontiers_xy: np.ndarray,
    path: Path,
    title: str = "",
    cell_m: float = MAP_CELL_M,
) -> None:
    """The merged map seen from above (colour = the highest point's z in each `cell_m`
    column), trajectories and last frontiers."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 6), dpi=110)
    pts = np.asarray(points_world).reshape(-1, 3)
    if len(pts):
        top, extent = top_heights(pts, cell_m)
        image = ax.imshow(top, origin="lower", extent=extent, cmap="viridis",
                          interpolation="nearest")
        fig.colorbar(image, ax=ax, label="z (m)", shrink=0.8)
    for robot, xy in enumerate(trajectories_xy):
        if len(xy):
            ax.plot(xy[:, 0], xy[:, 1], lw=1.5, label=f"robot {robot}")
            ax.plot(xy[0, 0], xy[0, 1], "k^", ms=5)
    fxy = np.asarray(frontiers_xy).reshape(-1, 2)
    if len(fxy):
        ax.plot(fxy[:, 0], fxy[:, 1], "rx", ms=6, label="frontiers")
    ax.set(xlabel="x (m)", ylabel="y (m)", title=title or "merged map from above")
    ax.set_aspect("equal")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_methods_coverage(
    curves: Mapping[str, Sequence[tuple[np.ndarray, np.ndarray]]],
    path: Path,
    title: str = "",
    key_label: str = "3D coverage (%)",
) -> None:
    """Fig. 5 style: mean coverage over sim time per method (band = ± std over seeds)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    for method, runs in curves.items():
        runs = [(t, c) for t, c in runs if len(t)]
        if not runs:
            continue
        end = max(float(t[-1]) for t, _ in runs)
        grid = np.linspace(0.0, end, 200)
        # step-hold each run's last value: a finished mission keeps its coverage
        stack = np.array([np.interp(grid, t, c, left=0.0) for t, c in runs])
        mean, std = stack.mean(axis=0), stack.std(axis=0)
        (line,) = ax.plot(grid, mean, label=f"{method} (n={len(runs)})")
        ax.fill_between(grid, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    ax.set(xlabel="sim time (s)", ylabel=key_label, ylim=(0, 100), title=title)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
