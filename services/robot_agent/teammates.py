"""Teammate pose estimates as the DRF and the yield rule need them (pure)."""

from __future__ import annotations

import numpy as np

from schemas.messages import RobotPose


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
