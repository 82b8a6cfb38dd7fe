"""The launcher's progress display: a rich live panel on a terminal (sim time, real-time
factor, coverage, BV, frontiers, each robot's state and goal), a plain log line otherwise.
Pure renderers of the monitor's state; `run._watch` refreshes them."""

from __future__ import annotations

from typing import Any

from rich.console import Group
from rich.panel import Panel
from rich.progress_bar import ProgressBar
from rich.table import Table

from services.evaluator.plots import world_label
from services.launcher.monitor import Monitor, RobotTrack


def current_goal(track: RobotTrack) -> str:
    """The robot's goal now: the last one assigned unless a status or cancel ended it."""
    for event in reversed(track.events):
        if event["kind"] == "goal":
            if event["cancel"]:
                return "-"
            return (f"#{event['goal_id']} ({event['x']:.1f}, {event['y']:.1f}) "
                    f"{'F_u' if event['frontier_class'] == 'unexplored' else 'F_w'}")
        if event["kind"] == "status" and event["status"] != "active":
            return f"- (#{event['goal_id']} {event['status']})"
    return "-"


def _frontier_counts(monitor: Monitor) -> tuple[int, int]:
    fr = monitor.frontiers.frontiers if monitor.frontiers else []
    unexplored = sum(f.frontier_class == "unexplored" for f in fr)
    return unexplored, len(fr) - unexplored


def _pct(row: dict[str, Any] | None, key: str, digits: int = 1) -> str:
    value = None if row is None else row.get(key)
    return "-" if value is None else f"{value:.{digits}f} %"


def status_line(monitor: Monitor, row: dict[str, Any] | None = None) -> str:
    """One line for logs: known area, coverage, frontiers and every robot's state."""
    known = monitor.series[-1].known_cells if monitor.series else 0
    area = known * (monitor.grid.resolution_m**2 if monitor.grid else 0.0)
    fu, fw = _frontier_counts(monitor)
    states = " ".join(f"r{i}:{t.state or '-'}" for i, t in monitor.tracks.items())
    cov = "" if row is None else f"  cov3d {_pct(row, 'coverage_3d_pct')}"
    return f"known {area:6.1f} m²{cov}  frontiers {fu + fw:3d}  {states}"


def mission_panel(monitor: Monitor, world: str, cap_s: float, wall_s: float,
                  row: dict[str, Any] | None) -> Panel:
    """The terminal panel; `row`: the latest coverage sample (None before the first)."""
    sim_s = monitor.sim_time_s
    rtf = sim_s / wall_s if wall_s > 0 else 0.0
    fu, fw = _frontier_counts(monitor)
    known = monitor.series[-1].known_cells if monitor.series else 0
    area = known * (monitor.grid.resolution_m**2 if monitor.grid else 0.0)
    head = Table.grid(padding=(0, 2))
    head.add_row(f"[bold]sim[/] {sim_s:6.1f} / {cap_s:.0f} s", f"[bold]wall[/] {wall_s:6.1f} s",
                 f"[bold]real-time factor[/] {rtf:4.2f}×")
    head.add_row(f"[bold]coverage 3D[/] {_pct(row, 'coverage_3d_pct')}",
                 f"[bold]2D[/] {_pct(row, 'coverage_2d_pct')}",
                 f"[bold]BV[/] {_pct(row, 'bounding_volume_pct', 4)}")
    head.add_row(f"[bold]frontiers[/] F_u {fu}  F_w {fw}", f"[bold]known[/] {area:.1f} m²",
                 "[green]complete[/]" if monitor.complete_tick is not None else "")
    robots = Table(box=None, padding=(0, 2), header_style="bold")
    for name in ("robot", "state", "goal", "goals", "reached"):
        robots.add_column(name)
    for i, t in monitor.tracks.items():
        robots.add_row(str(i), t.state or "-", current_goal(t), str(t.goals_assigned),
                       str(t.goals_reached))
    bar = ProgressBar(total=cap_s, completed=min(sim_s, cap_s))
    return Panel(Group(bar, head, robots),
                 title=f"spacemap · {world_label(world)} · {monitor.robots} robots")
