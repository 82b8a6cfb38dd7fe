"""Frame-to-local-map registration (small_gicp VGICP) that bounds wheel-odometry drift.

Frames: `odom` = the simulator's drifting wheel odometry; `loc` = the agent's locally
registered frame, equal to `odom` at start. `T_loc_odom` absorbs the drift: each registered
frame is aligned to a Gaussian voxel map of the previous frames (in `loc`), starting from the
odometry guess, and the planar part of the result replaces the guess. Submaps live in `loc`,
so the edge's corrections (T_world_submap) give T_world_loc.

Guards: too few points, no convergence, too few inliers, or a jump larger than odometry can
plausibly drift between two registrations (a wall seen head-on lets GICP slide) keep the guess.
The jump gate is the odometry error model: `step_m + step_per_m · d` and `step_rad +
step_rad_per_rad · |Δψ| + step_rad_per_m · d`, with d and Δψ the odometry motion since the last
*accepted* registration (so a run of rejections widens it as drift can grow). Missions showed the
fixed 8 cm / 0.05 rad gate letting GICP slide 10 cm and 1.6° within a few frames in doorways
(ghost walls 0.13 m off); real drift per 0.2 s frame is a few mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import small_gicp

from services.common.geometry import T_from_xyyaw, wrap_angle, xyyaw_from_T


@dataclass(frozen=True)
class RegistrationParams:
    downsample_m: float = 0.08  # source frame voxel size
    map_voxel_m: float = 0.15  # Gaussian voxel map resolution
    max_corr_m: float = 0.3
    max_iterations: int = 15
    min_points: int = 150
    min_inlier_frac: float = 0.5
    step_m: float = 0.02  # accepted correction of the odometry guess: base ...
    step_per_m: float = 0.06  # ... + this per metre driven since the last accepted one (3 × 2 %)
    step_rad: float = 0.02  # tighter lost yaw corrections in missions (2.6-4.4° error)
    step_rad_per_rad: float = 0.03  # 3 × the 1 % turn-scale error
    step_rad_per_m: float = 0.015  # 3 × the 0.005 rad/m heading bias
    cap_m: float = 0.08  # the gate never grows past these (AgentConfig sets a fixed gate:
    cap_rad: float = 0.05  # 300 s missions drifted less with it than with a growing one)
    floor_z_m: float = 0.03  # floor points carry no planar information: dropped
    map_horizon: int = 100  # map voxels not re-observed in this many inserted frames are dropped


@dataclass(frozen=True)
class RegistrationOutcome:
    T_loc_base: np.ndarray  # (4, 4) planar pose used (refined, or the guess)
    accepted: bool
    reason: str = ""


def planar(T: np.ndarray) -> np.ndarray:
    """The (x, y, yaw) part of a 4×4 pose (robots move on the floor)."""
    return T_from_xyyaw(*xyyaw_from_T(T))


class FrameRegistrar:
    """A voxel map of recent frames in `loc`, and one-frame alignment against it."""

    def __init__(self, params: RegistrationParams) -> None:
        self.params = params
        self.voxelmap = small_gicp.GaussianVoxelMap(params.map_voxel_m)
        self.voxelmap.set_lru(params.map_horizon, 10)
        self.n_inserted = 0
        self.T_odom_accepted: np.ndarray | None = None  # odometry at the last accepted one
        self.n_accepted = 0

    def _cloud(self, points_base: np.ndarray) -> small_gicp.PointCloud | None:
        pts = points_base[points_base[:, 2] > self.params.floor_z_m]
        if pts.shape[0] < self.params.min_points:
            return None
        cloud, _ = small_gicp.preprocess_points(
            np.ascontiguousarray(pts, dtype=np.float64), self.params.downsample_m,
            num_neighbors=10, num_threads=1,
        )
        return cloud if cloud.size() >= self.params.min_points else None

    def gate(self, T_odom_base: np.ndarray) -> tuple[float, float]:
        """(m, rad) largest correction odometry drift can explain since the last acceptance."""
        p = self.params
        if self.T_odom_accepted is None:
            return p.step_m, p.step_rad
        dx, dy, dyaw = xyyaw_from_T(np.linalg.inv(self.T_odom_accepted) @ T_odom_base)
        d = float(np.hypot(dx, dy))
        return (min(p.cap_m, p.step_m + p.step_per_m * d),
                min(p.cap_rad, p.step_rad + p.step_rad_per_rad * abs(wrap_angle(dyaw))
                    + p.step_rad_per_m * d))

    def register(
        self, points_base: np.ndarray, T_loc_base_guess: np.ndarray,
        T_odom_base: np.ndarray | None = None,
    ) -> RegistrationOutcome:
        """Refine the guess against the map, then add the frame at the pose used.

        `T_odom_base` (the raw odometry) sizes the jump gate; without it the gate is the base."""
        cloud = self._cloud(points_base)
        if cloud is None:
            return RegistrationOutcome(T_loc_base_guess, False, "too few points")
        outcome = RegistrationOutcome(T_loc_base_guess, False, "empty map")
        odom = T_loc_base_guess if T_odom_base is None else T_odom_base
        if self.n_inserted > 0:
            outcome = self._align(cloud, T_loc_base_guess, self.gate(odom))
        if outcome.accepted or self.n_inserted == 0:
            self.T_odom_accepted = odom.copy()
            self.n_accepted += int(outcome.accepted)
        self.voxelmap.insert(cloud, outcome.T_loc_base)
        self.n_inserted += 1
        return outcome

    def _align(self, cloud: small_gicp.PointCloud, guess: np.ndarray,
               gate: tuple[float, float]) -> RegistrationOutcome:
        p = self.params
        res = small_gicp.align(
            self.voxelmap, cloud, guess, max_correspondence_distance=p.max_corr_m,
            num_threads=1, max_iterations=p.max_iterations,
        )
        if not res.converged:
            return RegistrationOutcome(guess, False, "not converged")
        if res.num_inliers < p.min_inlier_frac * cloud.size():
            return RegistrationOutcome(guess, False, "few inliers")
        T = planar(res.T_target_source)
        dx, dy, dyaw = xyyaw_from_T(np.linalg.inv(guess) @ T)
        if np.hypot(dx, dy) > gate[0] or abs(wrap_angle(dyaw)) > gate[1]:
            return RegistrationOutcome(guess, False, "implausible jump")
        return RegistrationOutcome(T, True)
