"""spacemap's bus messages and run data as rerun entities, pure: each function returns
(entity path, archetype) pairs; `services.launcher.recorders.RerunRecorder` logs them.

Entity tree: `world/` (3D, z up: `map/cloud`, `robots/{i}` pose with a box body,
`trajectories/{i}/estimate|ground_truth`, `frontiers/unexplored|weak`, `goals`), `grid/`
(2D: `image` of the merged grid, `frontiers`, `robots`), `cameras/{i}/rgb|depth`, `plots/`
(coverage and BV time series) and `events` (goals and statuses as text). `blueprint` lays
them out in the viewer.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from schemas import messages as m

Entity = tuple[str, Any]
CloudColors = Literal["robot", "height", "rgb"]

ROBOT_RGB = np.array([[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40],
                      [148, 103, 189], [140, 86, 75], [227, 119, 194], [127, 127, 127],
                      [188, 189, 34], [23, 190, 207]], dtype=np.uint8)
CLASS_RGB = {"unexplored": (255, 140, 0), "weak": (153, 51, 230)}
GOAL_RGB = (26, 204, 51)
PLOTS = ("coverage_3d_pct", "coverage_2d_pct", "bounding_volume_pct", "overlap_3d_pct",
         "known_area_m2", "frontiers")
PERCENT_PLOTS = PLOTS[:4]


def robot_rgb(robot: int) -> np.ndarray:
    return ROBOT_RGB[robot % len(ROBOT_RGB)]


def light_rgb(robot: int, white: float = 0.45) -> np.ndarray:
    """The robot's colour mixed with `white` of white."""
    rgb = robot_rgb(robot).astype(np.float64)
    return np.rint(rgb + (255.0 - rgb) * white).astype(np.uint8)


def height_rgb(z: np.ndarray, lo: float = 0.0, hi: float = 2.5) -> np.ndarray:
    """(N, 3) uint8 colours of heights `z` on a blue → green → red ramp over [lo, hi]."""
    t = np.clip((np.asarray(z, dtype=np.float64) - lo) / (hi - lo), 0.0, 1.0)
    r = np.clip(2.0 * t - 1.0, 0.0, 1.0)
    g = 1.0 - np.abs(2.0 * t - 1.0)
    b = np.clip(1.0 - 2.0 * t, 0.0, 1.0)
    return (np.stack([r, g, b], axis=1) * 255).astype(np.uint8)


def cloud_colors(points: np.ndarray, robot_ids: np.ndarray | None, rgb: np.ndarray | None,
                 mode: CloudColors) -> np.ndarray | None:
    if mode == "robot" and robot_ids is not None:
        return ROBOT_RGB[np.asarray(robot_ids, dtype=np.int64) % len(ROBOT_RGB)]
    if mode == "height" or (mode == "robot" and robot_ids is None):
        return height_rgb(points[:, 2]) if len(points) else None
    return rgb


def cloud(path: str, points: np.ndarray, colors: np.ndarray | None) -> list[Entity]:
    return [(path, rr.Points3D(np.asarray(points, dtype=np.float32), colors=colors,
                               radii=0.025))]


def merged_cloud(c: m.Cloud, mode: CloudColors) -> list[Entity]:
    """The merged map P*, coloured by first observer (`robot`), height or camera colour.
    The points are copied: rerun may read them after `log` returns (zero-copy Arrow), and
    the live sampler's cloud changes in place after each sample."""
    colors = cloud_colors(c.points_world, c.robot_ids, c.colors, mode)
    return cloud("world/map/cloud", c.points_world.copy(),
                 colors.copy() if colors is c.colors else colors)


def robot_body(robot: int) -> list[Entity]:
    """Static: a box on the floor in each robot's frame, in its colour."""
    return [(f"world/robots/{robot}/body",
             rr.Boxes3D(centers=[[0.0, 0.0, 0.15]], half_sizes=[[0.25, 0.18, 0.15]],
                        colors=[robot_rgb(robot)], labels=[f"robot {robot}"]))]


def robot_poses(robot: int, ticks: Sequence[int], xyyaw: Sequence[tuple[float, float, float]],
                tick_s: float) -> tuple[str, list[Any], Any]:
    """Several poses of one robot as rerun columns (entity path, time columns, transform
    columns) for `send_columns`: one call per batch instead of one `log` per pose."""
    a = np.asarray(xyyaw, dtype=np.float64).reshape(-1, 3)
    ticks_arr = np.asarray(ticks, dtype=np.int64)
    translation = np.column_stack([a[:, 0], a[:, 1], np.zeros(len(a))])
    half = a[:, 2] / 2.0
    zeros = np.zeros(len(a))
    quaternion = np.column_stack([zeros, zeros, np.sin(half), np.cos(half)])  # x y z w
    indexes = [rr.TimeColumn("tick", sequence=ticks_arr),
               rr.TimeColumn("sim_time", duration=ticks_arr * tick_s)]
    return (f"world/robots/{robot}", indexes,
            rr.Transform3D.columns(translation=translation, quaternion=quaternion))


def trajectory(robot: int, xyyaw: Sequence[tuple[float, float, float]], which: str,
               step: int = 1) -> list[Entity]:
    """One robot's track so far as a line strip (`which`: estimate or ground_truth); every
    `step`-th pose and the last."""
    if len(xyyaw) < 2:
        return []
    step = max(step, 1)
    picked = list(xyyaw[::step]) + ([xyyaw[-1]] if (len(xyyaw) - 1) % step else [])
    xy = np.asarray(picked, dtype=np.float32)[:, :2]
    # above the map's floor points (radius 0.025 at z ~ 0), which hid lines at 1-2 cm; the
    # estimate in a light tint of the robot's colour, which also colours the floor it saw
    estimate = which == "estimate"
    z = 0.08 if estimate else 0.06
    strip = np.column_stack([xy, np.full(len(xy), z, dtype=np.float32)])
    rgb = light_rgb(robot) if estimate else np.array([90, 90, 90], np.uint8)
    return [(f"world/trajectories/{robot}/{which}",
             rr.LineStrips3D([strip], colors=[rgb], radii=0.03 if estimate else 0.02))]


def grid_image(grid: m.OccupancyGrid) -> list[Entity]:
    """The merged 2D grid as a grey image (unknown 128, free 255, occupied 0), row 0 at the
    top and y up, as `map_server` draws it."""
    cells = grid.cells
    img = np.full(cells.shape, 128, dtype=np.uint8)
    img[cells == 0] = 255
    img[cells > 50] = 0
    return [("grid/image", rr.Image(np.ascontiguousarray(img[::-1])))]


def _grid_pixels(grid: m.OccupancyGrid, xy: np.ndarray) -> np.ndarray:
    """World (x, y) → pixel (u, v) of `grid_image` (y flipped)."""
    h = grid.cells.shape[0]
    u = (xy[:, 0] - grid.origin_x) / grid.resolution_m
    v = h - (xy[:, 1] - grid.origin_y) / grid.resolution_m
    return np.column_stack([u, v]).astype(np.float32)


def frontiers(f: m.Frontiers, robot_xy: dict[int, tuple[float, float]],
              grid: m.OccupancyGrid | None) -> list[Entity]:
    """F_u and F_w regions at their centroids (radius grows with the region), the goals f′,
    and a line from each robot to its assigned goal; on the grid image too."""
    out: list[Entity] = []
    for cls in ("unexplored", "weak"):
        sel = [fr for fr in f.frontiers if fr.frontier_class == cls]
        centroids = np.array([fr.centroid for fr in sel], dtype=np.float32).reshape(-1, 3)
        radii = np.array([0.08 + 0.03 * np.log1p(fr.size) for fr in sel], dtype=np.float32)
        out.append((f"world/frontiers/{cls}",
                    rr.Points3D(centroids, radii=radii, colors=[CLASS_RGB[cls]])))
    by_id = {fr.frontier_id: fr for fr in f.frontiers}
    pairs = [(r, by_id[fid]) for r, fid in sorted(f.assigned.items())
             if fid in by_id and r in robot_xy]
    goals = np.array([[*fr.goal_xy, 0.05] for _, fr in pairs], dtype=np.float32).reshape(-1, 3)
    strips = [np.array([[*robot_xy[r], 0.05], [*fr.goal_xy, 0.05]], dtype=np.float32)
              for r, fr in pairs]
    out.append(("world/goals", rr.Points3D(goals, radii=0.1, colors=[GOAL_RGB],
                                            labels=[f"goal r{r}" for r, _ in pairs])))
    out.append(("world/goals/paths", rr.LineStrips3D(strips, colors=[GOAL_RGB], radii=0.02)))
    if grid is not None:
        all_goal_xy = np.array([fr.goal_xy for fr in f.frontiers], dtype=np.float64)
        colors = [CLASS_RGB[fr.frontier_class] for fr in f.frontiers]
        out.append(("grid/frontiers", rr.Points2D(_grid_pixels(grid, all_goal_xy.reshape(-1, 2)),
                                                  colors=colors or None, radii=2.0)))
        if robot_xy:
            ids = sorted(robot_xy)
            xy = np.array([robot_xy[i] for i in ids], dtype=np.float64)
            out.append(("grid/robots", rr.Points2D(_grid_pixels(grid, xy), radii=3.0,
                                                   colors=[robot_rgb(i) for i in ids],
                                                   labels=[str(i) for i in ids])))
    return out


def camera(frame: m.RgbdFrame) -> list[Entity]:
    """One robot's camera: colour and depth (millimetres, 16 bit: half the bytes; JPEG
    would cost ~10 ms a frame). The DRF mask is agent-internal and not on the bus, so it is
    not shown."""
    base = f"cameras/{frame.robot_id}"
    depth_mm = np.clip(np.rint(frame.depth_m * 1000.0), 0, 65535).astype(np.uint16)
    return [(f"{base}/rgb", rr.Image(frame.rgb)),
            (f"{base}/depth", rr.DepthImage(depth_mm, meter=1000.0))]


def series(row: dict[str, Any]) -> list[Entity]:
    """A coverage time-series row (services.launcher.sampler.series_row) as scalars."""
    return [(f"plots/{key}", rr.Scalars(float(row[key]))) for key in PLOTS
            if row.get(key) is not None]


def event(robot: int, msg: m.Goal | m.GoalStatus) -> list[Entity]:
    if isinstance(msg, m.Goal):
        verb = "cancel" if msg.cancel else f"goal ({msg.x:.2f}, {msg.y:.2f}) {msg.frontier_class}"
        text = f"robot {robot}: {verb} #{msg.goal_id}"
    else:
        text = f"robot {robot}: goal #{msg.goal_id} {msg.status} {msg.reason}".rstrip()
    return [("events", rr.TextLog(text))]


def blueprint(robots: int) -> rrb.Blueprint:
    """The viewer's layout of a mission: the 3D map with robots, trajectories, frontiers and
    goals (left, the largest), the 2D grid with frontiers and robots, the coverage curves (%)
    and, in tabs, the frontier count and known area, the goal events and each robot's camera
    (logged with a live view only). The time panel shows `sim_time` and follows the latest
    data, so a finished recording opens at its end."""
    cameras = [rrb.Spatial2DView(origin=f"cameras/{i}", name=f"camera {i}")
               for i in range(robots)]
    # the curves from the start of the mission to the time cursor (rerun's default is a
    # window around the cursor), the legend where the curves are not: top left
    from_start = rrb.TimeAxis(view_range=rr.TimeRange(
        start=rrb.TimeRangeBoundary.absolute(seconds=0.0),
        end=rrb.TimeRangeBoundary.cursor_relative()))
    legend = rrb.PlotLegend(corner="LeftTop")
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="map (3D)"),
            rrb.Vertical(
                rrb.Spatial2DView(origin="grid", name="grid (2D)"),
                rrb.TimeSeriesView(origin="plots", name="coverage (%)",
                                   contents=[f"plots/{key}" for key in PERCENT_PLOTS],
                                   axis_x=from_start, plot_legend=legend),
                rrb.Tabs(
                    rrb.TimeSeriesView(origin="plots", name="frontiers, known area (m²)",
                                       contents=["plots/frontiers", "plots/known_area_m2"],
                                       axis_x=from_start, plot_legend=legend),
                    rrb.TextLogView(origin="events", name="goal events"),
                    *cameras),
                row_shares=[5, 3, 2]),
            column_shares=[3, 2]),
        rrb.TimePanel(timeline="sim_time", play_state="following"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )
