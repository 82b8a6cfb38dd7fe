"""Yielding to teammates: no driving into one just ahead, and a detour when two wait face to face.

The DRF keeps teammates out of the map and so out of the grid the planner avoids; without the
yield rule two robots pushed into each other for a minute in a mission. Two robots that meet
head on both yield, though, until the validator ends a goal (10 s and more in missions with
straight paths): after `yield_detour_ticks` the one of higher id (after three times as long,
either: the other may be parked) has its navigator plan around the teammate, and yields to it
only where the bodies would touch while it drives past.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from schemas.messages import RobotPose
from services.robot_agent.config import AgentConfig
from services.robot_agent.navigation import Command, Navigator
from services.robot_agent.teammates import predict_xy


@dataclass(frozen=True)
class Blocker:
    """The teammate a robot yields to this tick: its id and predicted world xy."""

    robot_id: int
    xy: np.ndarray


def blocker_ahead(
    pose_world: tuple[float, float, float], teammates: dict[int, RobotPose],
    teammates_prev: dict[int, RobotPose], tick: int, config: AgentConfig,
    passing: int | None = None,
) -> Blocker | None:
    """The first teammate (by id) within the yield distance and half-angle ahead; `passing`:
    a teammate being planned around, which counts only within touching distance."""
    cfg = config
    for rid, p in sorted(teammates.items()):
        if tick - p.tick > cfg.teammate_max_age_ticks:
            continue
        xy = predict_xy(p, teammates_prev.get(rid), tick, cfg.predict_max_ticks)
        rel = xy - np.array(pose_world[:2])
        bearing = math.atan2(rel[1], rel[0]) - pose_world[2]
        bearing = math.atan2(math.sin(bearing), math.cos(bearing))
        near = (2 * cfg.robot_radius_m + cfg.inflation_margin_m if rid == passing
                else cfg.yield_dist_m)
        if np.hypot(*rel) < near and abs(bearing) < cfg.yield_half_angle_rad:
            return Blocker(rid, xy)
    return None


class YieldRule:
    """Per robot: how long it has been yielding to whom, and when to detour."""

    def __init__(self, config: AgentConfig, robot_id: int) -> None:
        self.config = config
        self.robot_id = robot_id
        self.since: tuple[int, int] | None = None  # (teammate, tick) yielding to it since
        self.passing: int | None = None  # the teammate the navigator plans around

    def detour_due(self, blocker: Blocker | None, tick: int) -> bool:
        """Record this tick's blocker; True when it is time to plan around it."""
        cfg = self.config
        if blocker is None:
            self.since = None
            return False
        if self.since is None or self.since[0] != blocker.robot_id:
            self.since = (blocker.robot_id, tick)
        due = cfg.yield_detour_ticks * (1 if self.robot_id > blocker.robot_id else 3)
        if cfg.yield_detour_ticks == 0 or tick - self.since[1] < due:
            return False
        self.passing = blocker.robot_id
        self.since = (blocker.robot_id, tick)  # the next detour only after another wait
        return True


    def command(self, cmd: Command, pose_world: tuple[float, float, float],
                teammates: dict[int, RobotPose], teammates_prev: dict[int, RobotPose],
                nav: Navigator, tick: int) -> Command:
        """`cmd` without forward motion into a teammate just ahead; `nav` plans around it
        when the wait is long."""
        if cmd.v_mps <= 0.0:
            return cmd
        passing = self.passing if nav.avoid_xy is not None else None
        blocker = blocker_ahead(pose_world, teammates, teammates_prev, tick, self.config,
                                passing)
        if self.detour_due(blocker, tick):
            assert blocker is not None
            nav.avoid(blocker.xy, tick)
        return cmd if blocker is None else yielded(cmd)


def yielded(cmd: Command) -> Command:
    """The command without its forward motion (turning kept)."""
    return Command(0.0, cmd.omega_radps)
