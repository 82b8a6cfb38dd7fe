"""The paper's adaptive exploration goal validator (§III-G).

t_e of the A* path P = {p_1 … p_n} toward f′ is summed segment by segment: driving at the
linear speed limit plus turning at the turn-rate limit (`expected_times`). While the robot
follows the path, every path point it passes is logged with the t_e of the segment that led
to it (`PassLog`). The goal is invalid when the robot's time over the last β points exceeds
their summed estimate:

    (t_now − t(p_{i−β})) > Σ_{k=i−β+1..i+1} t_e(p_{k−1}, p_k) + slack

The sum includes the segment being driven (i → i+1), so a robot standing still is caught one
window after it stopped, whatever β. `slack_s` absorbs what t_e does not model (acceleration,
the controller's slow-down near the goal); it is measured with β in docs/agent.md.
The log survives replans: passed points stay passed, new points come from the new path.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from services.common.geometry import wrap_angle


def expected_times(
    path_xy: np.ndarray, yaw0: float, max_v: float, max_omega: float
) -> np.ndarray:
    """(K−1,) t_e per path segment: length / v_max + heading change / ω_max.

    The first segment's turn is from the robot's heading `yaw0`.
    """
    d = np.diff(np.asarray(path_xy, dtype=np.float64), axis=0)
    if d.shape[0] == 0:
        return np.zeros(0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    turn = np.abs(wrap_angle(np.diff(heading, prepend=yaw0)))
    return np.hypot(d[:, 0], d[:, 1]) / max_v + turn / max_omega


@dataclass
class PassLog:
    """Ticks at which path points were passed and the t_e that led to each."""

    start_tick: int
    ticks: list[int] = field(default_factory=list)
    t_e: list[float] = field(default_factory=list)

    def passed(self, tick: int, t_e_segments: np.ndarray) -> None:
        """Log points reached this tick, one per segment driven (oldest first)."""
        for t in np.asarray(t_e_segments, dtype=np.float64).reshape(-1):
            self.ticks.append(tick)
            self.t_e.append(float(t))


def window_exceeded(
    log: PassLog, tick: int, tick_s: float, current_t_e: float, beta: int, slack_s: float
) -> bool:
    """True when the time over the last β points (plus the current one) exceeds its t_e."""
    n = len(log.ticks)
    first = max(0, n - beta)
    since_tick = log.ticks[first - 1] if first > 0 else log.start_tick
    robot_s = (tick - since_tick) * tick_s
    estimate_s = float(sum(log.t_e[first:])) + current_t_e
    return robot_s > estimate_s + slack_s
