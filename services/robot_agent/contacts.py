"""Obstacles the robot drove into but never saw: a bumper's layer of the local costmap.

The camera sees a chair's legs and the floor between them; MuJoCo collides with the chair's
convex hull, as a real robot meets a seat edge above its obstacle band, a glass pane or a
cable. Commanded forward for a second without moving, the robot is against something: the
cells just ahead, across the front of the robot, are marked occupied for its planner for a
while (ROS costmaps keep bumper hits in a layer of their own, cleared after a time, for the
same reason: a mark kept for good can close a passage the robot stalled in for another
reason, and with it every goal beyond). Without it a
robot pushed against an AWS-house chair for 30 s at a time, each goal ending "invalid" and
the next taking the same line (docs/agent.md, "Blocked by what the camera misses").

Stalls with a teammate close by are the yield rule's (yielding.py), not an obstacle's, and
leave no mark. Pure: poses and commands in, marks out.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from services.common.grid import GridSpec
from services.robot_agent.local_grid import OCCUPIED


@dataclass(frozen=True)
class ContactParams:
    window_ticks: int = 10  # commanded forward this many ticks in a row ...
    min_v_mps: float = 0.1
    max_moved_m: float = 0.02  # ... and moved less than this: blocked
    teammate_clear_m: float = 1.0  # no mark with a teammate this close
    ahead_m: float = 0.05  # the mark lies this far beyond the robot's radius
    arc_rad: float = math.radians(40.0)  # across ± this of the heading
    arc_points: int = 9
    ttl_ticks: int = 150  # a mark is forgotten after this long


class ContactLayer:
    """Where the robot met what it could not see, in world xy."""

    def __init__(self, params: ContactParams, robot_radius_m: float) -> None:
        self.params = params
        self.robot_radius_m = robot_radius_m
        self.points_xy = np.zeros((0, 2))
        self.ticks = np.zeros(0, np.int64)  # when each point was marked
        self.n_contacts = 0
        self._history: deque[tuple[float, float, float]] = deque(
            maxlen=params.window_ticks + 1)  # (x, y, commanded v) per tick

    def observe(self, tick: int, pose: tuple[float, float, float], v_cmd_mps: float,
                teammates_xy: np.ndarray) -> bool:
        """Tick `tick`'s pose and the command sent from it; True when it adds a contact."""
        p = self.params
        self._history.append((pose[0], pose[1], v_cmd_mps))
        if len(self._history) <= p.window_ticks:
            return False
        first, last = self._history[0], self._history[-1]
        commanded = all(v >= p.min_v_mps for _, _, v in list(self._history)[:-1])
        if not commanded or math.hypot(last[0] - first[0], last[1] - first[1]) >= p.max_moved_m:
            return False
        self._history.clear()
        near = np.asarray(teammates_xy, np.float64).reshape(-1, 2) - np.array(pose[:2])
        if len(near) and np.min(np.hypot(near[:, 0], near[:, 1])) < p.teammate_clear_m:
            return False
        self._add(tick, pose)
        return True

    def _add(self, tick: int, pose: tuple[float, float, float]) -> None:
        p = self.params
        live = self.ticks > tick - p.ttl_ticks
        bearing = pose[2] + np.linspace(-p.arc_rad, p.arc_rad, p.arc_points)
        r = self.robot_radius_m + p.ahead_m
        arc = np.column_stack([pose[0] + r * np.cos(bearing), pose[1] + r * np.sin(bearing)])
        self.points_xy = np.vstack([self.points_xy[live], arc])
        self.ticks = np.concatenate([self.ticks[live], np.full(len(arc), tick)])
        self.n_contacts += 1

    def clear(self) -> None:
        """Forget every mark (the robot is boxed in by them: `Navigator._plan`)."""
        self.points_xy = np.zeros((0, 2))
        self.ticks = np.zeros(0, np.int64)

    def active(self, tick: int) -> bool:
        """Whether any mark is still in force at `tick`."""
        return bool(len(self.ticks)) and int(self.ticks.max()) > tick - self.params.ttl_ticks

    def mark(self, cells: np.ndarray, spec: GridSpec, tick: int) -> np.ndarray:
        """`cells` (a window of the local grid described by `spec`) with the contacts of the
        last `ttl_ticks` occupied."""
        live = self.ticks > tick - self.params.ttl_ticks
        if not live.any():
            return cells
        rc = spec.cell_of(self.points_xy[live])
        rc = rc[spec.contains(rc)]
        if not len(rc):
            return cells
        cells = cells.copy()
        cells[rc[:, 0], rc[:, 1]] = OCCUPIED
        return cells
