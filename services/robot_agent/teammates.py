"""Teammate pose estimates as the DRF and the yield rule need them (pure)."""

from __future__ import annotations

import numpy as np

from schemas.messages import RgbdFrame, RobotPose
from services.robot_agent.awareness import in_view_partial, visible_paper
from services.robot_agent.config import AgentConfig
from services.robot_agent.projection import hfov_of


def predict_xy(last: RobotPose, prev: RobotPose | None, tick: int, max_ticks: int) -> np.ndarray:
    """(2,) teammate xy at `tick`: its last estimate moved on by its last velocity.

    Teammate poses of tick k are applied from tick k + 1 (node.TICKED), so the estimate is at
    least one tick (≈ 5 cm, 4.5°) behind the frame; extrapolation is capped at `max_ticks`.
    """
    p = last.pose_world
    xy = np.array([p.x, p.y])
    if prev is None or last.tick <= prev.tick:
        return xy
    q = prev.pose_world
    v = (xy - np.array([q.x, q.y])) / (last.tick - prev.tick)
    return xy + v * min(max(tick - last.tick, 0), max_ticks)


def teammates_xy(teammates: dict[int, RobotPose]) -> np.ndarray:
    """(N, 2) the teammates' last estimated xy, world frame."""
    return np.array([[p.pose_world.x, p.pose_world.y] for p in teammates.values()],
                    np.float64).reshape(-1, 2)


def teammates_in_view(
    teammates: dict[int, RobotPose], teammates_prev: dict[int, RobotPose],
    pose_world: tuple[float, float, float], frame: RgbdFrame, tick: int, cfg: AgentConfig,
) -> np.ndarray:
    """(N, 2) world xy of fresh teammate estimates that mutual awareness puts in view."""
    fresh = [predict_xy(p, teammates_prev.get(rid), tick, cfg.predict_max_ticks)
             for rid, p in sorted(teammates.items())
             if tick - p.tick <= cfg.teammate_max_age_ticks]
    if not fresh:
        return np.empty((0, 2))
    xy = np.array(fresh)
    test = visible_paper if cfg.awareness == "paper" else in_view_partial
    seen = test(pose_world, xy, radius_m=cfg.robot_size_m,
                fov_rad=hfov_of(frame.K, frame.depth_m.shape[1]),
                range_m=frame.range_max_m, c=cfg.drf_c)
    return xy[seen]
