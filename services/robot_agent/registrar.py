"""One frame against a voxel map of the previous ones: small_gicp VGICP, planar poses.

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

from services.common.geometry import T_from_xyyaw, invert, wrap_angle, xyyaw_from_T
from services.robot_agent.drift_filter import FilterParams, drop_weak_translation
from services.robot_agent.odometry_calibration import CalibrationParams
from services.robot_agent.scan_odometry import ScanOdometryParams
from services.robot_agent.voxel_map import LazyLruVoxelMap
from services.robot_agent.wall_heading import WallHeadingParams


@dataclass(frozen=True)
class RegistrationParams:
    downsample_m: float = 0.08  # source frame voxel size
    neighbors: int = 10  # points per covariance (and normal) estimate
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
    max_removed_frac: float = 0.35  # no registration of frames the DRF took more of
    # with the filter: a frame registers with its points within this horizontal range only
    # (m; 0 = all) and joins the map with all of them, so what it aligns lies inside the
    # map: the map's far edge holds half-seen voxels whose means sit toward where the robot
    # was, and along an aisle they pull every frame back (0.2-0.3 % of the distance driven)
    align_max_range_m: float = 0.0
    align_max_bearing_rad: float = 0.0  # ... and within this bearing of straight ahead (0 = all)
    degenerate_ratio: float = 0.0  # weakest / strongest translation information below this:
    # the correction along the weak direction is dropped (0 = never)
    # a Kalman filter on the pose (drift_filter.py) instead of the jump gate; frames it
    # rejects stay out of the map
    filter: FilterParams | None = None
    # with the filter: an accepted frame joins the map only this far (m or rad) from the last
    # frame that did (0 = every frame); fewer inserts, fewer registration errors built in
    insert_min_m: float = 0.0
    insert_min_rad: float = 0.0
    # when the walls take the heading back (wall_heading.py, re-acquisition), the frames'
    # map is forgotten: it was built at the wrong heading and would pull it back
    reset_on_wall_reacquire: bool = False
    # ... and when one frame's walls turn the heading by more than this (rad; 0 = never) and
    # its registration sides with the heading from before (localization.py)
    reset_on_wall_conflict_rad: float = 0.0
    # with the filter: learn odometry's scale, turn scale and heading bias from segments
    # between good registrations, and correct the odometry by them (None = raw odometry)
    calibration: CalibrationParams | None = None
    # with the filter: a frame GICP did not converge on joins the map at the odometry guess
    # (False: it stays out, as frames of new ground do not)
    insert_unconverged: bool = True
    # with the filter: ... and only while the filter's heading σ is at most this (rad; 0 = any)
    unregistered_insert_max_sigma_rad: float = 0.0
    unregistered_insert_max_held: int = 50  # ... for at most this many frames in a row
    # with the filter: GICP's pose on a frame it did not converge on is a measurement like any
    # other (the filter weighs and gates it); False: the frame keeps the odometry guess
    use_unconverged: bool = False
    # with the filter: a second, coarser voxel map (m; 0 = none). A frame GICP did not
    # converge on against the fine map (which finds a correspondence only inside the voxel a
    # point falls in, so a 0.6° guess error puts far points out of reach), or that matched
    # under coarse_below_frac of its points, is aligned on the coarse map first, then on the
    # fine map from there; the alignment that matched more points is kept
    coarse_voxel_m: float = 0.0
    coarse_below_frac: float = 0.5
    # > 0: the coarse route's pose is kept only within this yaw (rad) of the fine map's own
    # answer (converged or not), so it confirms rather than replaces it
    coarse_agree_rad: float = 0.0
    # with the filter: the heading change since the previous frame from the two frames
    # registered to each other (scan_odometry.py) replaces odometry's (None = odometry's)
    scan_odometry: ScanOdometryParams | None = None
    # with the filter: an absolute heading from the frame's wall directions (wall_heading.py)
    wall_heading: WallHeadingParams | None = None


@dataclass(frozen=True)
class RegistrationOutcome:
    T_loc_base: np.ndarray  # (4, 4) planar pose used (refined, or the guess)
    accepted: bool
    reason: str = ""
    T_measured: np.ndarray | None = None  # (4, 4) what registration found, accepted or not
    mahalanobis2: float = float("nan")  # its squared distance from the filter's prediction


def planar(T: np.ndarray) -> np.ndarray:
    """The (x, y, yaw) part of a 4×4 pose (robots move on the floor)."""
    return T_from_xyyaw(*xyyaw_from_T(T))


class FrameRegistrar:
    """A voxel map of recent frames in `loc`, and one-frame alignment against it."""

    def __init__(self, params: RegistrationParams) -> None:
        self.params = params
        self.T_odom_accepted: np.ndarray | None = None  # odometry at the last accepted one
        self.n_accepted = 0
        # frames inserted while this is on wait in `pending` until `flush` (or the next
        # alignment): the map only matters to the next frame, so the agent adds them after
        # its tick's command is out (AgentCore.finish_tick)
        self.defer_inserts = False
        self.reset()

    def reset(self) -> None:
        """An empty map (also to forget one built at a heading now known to be wrong, which
        aligning to would pull the heading back: the next frame starts a new one)."""
        p = self.params
        self.voxelmap = LazyLruVoxelMap(p.map_voxel_m, p.map_horizon)
        self.coarse = (LazyLruVoxelMap(p.coarse_voxel_m, p.map_horizon)
                       if p.coarse_voxel_m > 0 else None)
        self.n_inserted = 0
        self.T_inserted: np.ndarray | None = None  # pose of the last frame inserted
        self.pending: list[tuple[small_gicp.PointCloud, np.ndarray]] = []  # dropped with the map

    def _cloud(self, points_base: np.ndarray) -> small_gicp.PointCloud | None:
        out = self.cloud_tree(points_base)
        return None if out is None else out[0]

    def cloud_tree(self, points_base: np.ndarray,
                   ) -> tuple[small_gicp.PointCloud, small_gicp.KdTree] | None:
        """The frame downsampled, with covariances and its k-d tree (None: too few points)."""
        pts = points_base[points_base[:, 2] > self.params.floor_z_m]
        if pts.shape[0] < self.params.min_points:
            return None
        cloud, tree = small_gicp.preprocess_points(
            np.ascontiguousarray(pts, dtype=np.float64), self.params.downsample_m,
            num_neighbors=self.params.neighbors, num_threads=1,
        )
        return (cloud, tree) if cloud.size() >= self.params.min_points else None

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
        odom = T_loc_base_guess if T_odom_base is None else T_odom_base
        cloud = self._cloud(points_base)
        if cloud is None:
            return RegistrationOutcome(T_loc_base_guess, False, "too few points")
        outcome = RegistrationOutcome(T_loc_base_guess, False, "empty map")
        if self.n_inserted > 0:
            outcome = self._align(cloud, T_loc_base_guess, self.gate(odom))
        if outcome.accepted or self.n_inserted == 0:
            self.T_odom_accepted = odom.copy()
            self.n_accepted += int(outcome.accepted)
        self._insert_maps(cloud, outcome.T_loc_base)
        self.n_inserted += 1
        return outcome

    def align(self, cloud: small_gicp.PointCloud, guess: np.ndarray,
              ) -> tuple[np.ndarray, np.ndarray, float] | str:
        """(planar T_loc_base, GICP Hessian, inlier fraction) of one frame against the map,
        or why not."""
        p = self.params
        self.flush()
        res = self._gicp(self.voxelmap, cloud, guess)
        if self.coarse is not None and (
                not res.converged or res.num_inliers < p.coarse_below_frac * cloud.size()):
            rough = self._gicp(self.coarse, cloud, guess)
            if rough.converged:
                fine = self._gicp(self.voxelmap, cloud, planar(rough.T_target_source))
                agree = p.coarse_agree_rad <= 0 or abs(wrap_angle(
                    xyyaw_from_T(fine.T_target_source)[2]
                    - xyyaw_from_T(res.T_target_source)[2])) < p.coarse_agree_rad
                if fine.converged and agree and (
                        not res.converged or fine.num_inliers > res.num_inliers):
                    res = fine
        if not res.converged and not p.use_unconverged:
            return "not converged"
        if res.num_inliers < p.min_inlier_frac * cloud.size():
            return "few inliers" if res.converged else "not converged"
        return planar(res.T_target_source), np.asarray(res.H), res.num_inliers / cloud.size()

    def _gicp(self, target: LazyLruVoxelMap, cloud: small_gicp.PointCloud,
              guess: np.ndarray) -> small_gicp.RegistrationResult:
        p = self.params
        return small_gicp.align(target, cloud, guess, max_correspondence_distance=p.max_corr_m,
                                num_threads=1, max_iterations=p.max_iterations)

    def _insert_maps(self, cloud: small_gicp.PointCloud, T_loc_base: np.ndarray) -> None:
        self.pending.append((cloud, T_loc_base))
        if not self.defer_inserts:
            self.flush()

    def flush(self) -> None:
        """Insert the frames still pending, in the order they came."""
        pending, self.pending = self.pending, []
        for cloud, T_loc_base in pending:
            self.voxelmap.insert(cloud, T_loc_base)
            if self.coarse is not None:
                self.coarse.insert(cloud, T_loc_base)

    def insert(self, cloud: small_gicp.PointCloud, T_loc_base: np.ndarray) -> None:
        self._insert_maps(cloud, T_loc_base)
        self.n_inserted += 1
        self.T_inserted = T_loc_base

    def moved_since_insert(self, T_loc_base: np.ndarray) -> bool:
        """Whether a registered frame at this pose is far enough from the last one inserted."""
        p = self.params
        if self.T_inserted is None or (p.insert_min_m <= 0 and p.insert_min_rad <= 0):
            return True
        dx, dy, dyaw = xyyaw_from_T(invert(self.T_inserted) @ T_loc_base)
        return bool(np.hypot(dx, dy) >= p.insert_min_m or abs(wrap_angle(dyaw)) >= p.insert_min_rad)

    def _align(self, cloud: small_gicp.PointCloud, guess: np.ndarray,
               gate: tuple[float, float]) -> RegistrationOutcome:
        p = self.params
        self.flush()
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
        if p.degenerate_ratio > 0:
            T = guess @ T_from_xyyaw(*drop_weak_translation(
                np.array([dx, dy, dyaw]), res.H, p.degenerate_ratio))
        return RegistrationOutcome(T, True)
