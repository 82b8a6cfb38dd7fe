"""Localization: the drift filter fusing wheel odometry, frame-to-map registration
(registrar.py), scan turns and wall headings into the pose in `loc`.

Frames: `odom` = the simulator's drifting wheel odometry; `loc` = the agent's locally
registered frame, equal to `odom` at start. `T_loc_odom` absorbs the drift: each registered
frame is aligned to a Gaussian voxel map of the previous frames (in `loc`), starting from the
odometry guess, and the planar part of the result replaces the guess. Submaps live in `loc`,
so the edge's corrections (T_world_submap) give T_world_loc.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import replace

import numpy as np
import small_gicp

from services.common.geometry import T_from_xyyaw, invert, wrap_angle, xyyaw_from_T
from services.robot_agent.drift_filter import (
    FilterParams,
    agree,
    count_inflation,
    fuse,
    measurement_cov,
    overlap_inflation,
    predict,
    translation_information_ratio,
)
from services.robot_agent.odometry_calibration import (
    CalibratedOdometry,
    CalibrationParams,
    is_good_registration,
)
from services.robot_agent.registrar import (
    FrameRegistrar,
    RegistrationOutcome,
    RegistrationParams,
    planar,
)
from services.robot_agent.scan_odometry import ScanOdometry
from services.robot_agent.wall_heading import WallHeading

log = logging.getLogger(__name__)


class Localizer:
    """T_loc_odom, the drift registration found: T_loc_base = T_loc_odom · T_odom_base.

    With odometry calibration `odom` is the corrected odometry chain (`CalibratedOdometry`);
    callers still pass the raw odometry poses, each tick through `observe_odometry`."""

    def __init__(self, params: RegistrationParams) -> None:
        self.registrar = FrameRegistrar(params)
        self.T_loc_odom = np.eye(4)
        self.outcomes: Counter[str] = Counter()  # "accepted" or the rejection reason
        self.P = np.zeros((3, 3))  # covariance of T_loc_base (x, y, yaw): the start is known
        self._T_odom_prev: np.ndarray | None = None
        self._wall_turn: tuple[float, float] | None = None  # this frame's (yaw before, after)
        self.n_held_out = 0  # unregistered frames in a row kept out of the map (σ too large)
        # weakest / strongest translation information of the last frame GICP aligned (1 until
        # one is): low along an aisle or one wall
        self.info_ratio = 1.0
        # frames fused at `weak_inflation_power_uncalibrated` so far; −1 once calibrated
        self.frames_uncalibrated = 0
        # each rejected registration's T_loc_base and its frame's T_odom_base (x, y, yaw)
        self._rejected: list[tuple[np.ndarray, np.ndarray]] = []
        # the frame (cloud, k-d tree) the open calibration segment started at
        self._segment_frame: tuple[small_gicp.PointCloud, small_gicp.KdTree] | None = None
        self.odometry = (CalibratedOdometry(params.calibration)
                         if params.calibration is not None and params.filter is not None
                         else None)
        self.scans = (ScanOdometry(params.scan_odometry)
                      if params.scan_odometry is not None and params.filter is not None
                      else None)
        self.walls = (WallHeading(params.wall_heading)
                      if params.wall_heading is not None and params.filter is not None else None)

    def observe_odometry(self, T_odom_raw: np.ndarray) -> None:
        """Integrate one raw odometry pose into the corrected chain (every tick)."""
        if self.odometry is not None:
            self.odometry.observe(np.array(xyyaw_from_T(T_odom_raw)))

    def _calibrated(self, T_odom_raw: np.ndarray) -> np.ndarray:
        if self.odometry is None:
            return T_odom_raw
        return T_from_xyyaw(*self.odometry.corrected(np.array(xyyaw_from_T(T_odom_raw))))

    def guess(self, T_odom_base: np.ndarray) -> np.ndarray:
        """T_loc_base for a raw odometry pose at or after the last one observed."""
        return self.T_loc_odom @ self._calibrated(T_odom_base)

    def update(self, points_base: np.ndarray, T_odom_base: np.ndarray,
               removed_frac: float = 0.0) -> RegistrationOutcome:
        """Register one frame from the odometry guess; T_loc_odom takes up the drift found.

        A frame mostly hidden by teammates (`removed_frac` of its pixels taken by the DRF)
        keeps the guess and stays out of the map: what is left is a sliver GICP can slide on.
        Except the first: robots start close together, and a map anchored only after the
        initial turn in place would keep that turn's odometry error (0.44° in missions)."""
        filt = self.registrar.params.filter
        self._wall_turn = None
        self.observe_odometry(T_odom_base)
        T_odom_base = self._calibrated(T_odom_base)
        hidden = (removed_frac > self.registrar.params.max_removed_frac
                  and self.registrar.n_inserted > 0)
        # a hidden frame still gives the turn from the previous one, where asked: what the
        # teammates leave of two consecutive frames overlaps as much as the teammates do not
        scan_hidden = hidden and self.scans is not None and self.scans.params.when_hidden
        frame = (None if (hidden and not scan_hidden) or filt is None
                 else self.registrar.cloud_tree(points_base))
        if filt is not None and self._T_odom_prev is not None:
            T_prev = self.T_loc_odom @ self._T_odom_prev
            T_odom_base, filt_step = self._scan_turn(frame, T_odom_base, filt)
            self.P = predict(self.P, np.array(xyyaw_from_T(T_prev)),
                             np.array(xyyaw_from_T(self.T_loc_odom @ T_odom_base)), filt_step)
        elif self.scans is not None and frame is not None:
            self.scans.turn(*frame, T_odom_base)  # the first frame: remembered only
        guess = self.T_loc_odom @ T_odom_base
        if self.walls is not None and frame is not None and not hidden:
            guess = self._wall_heading(frame[0], guess, T_odom_base)
        self._T_odom_prev = T_odom_base.copy()
        if hidden:
            outcome = RegistrationOutcome(guess, False, "hidden by teammates")
        elif filt is not None:
            outcome = self._filtered(frame, guess, self._fusion_params(filt),
                                     self._align_cloud(points_base))
        else:
            outcome = self.registrar.register(points_base, guess, T_odom_base)
        self.outcomes["accepted" if outcome.accepted else outcome.reason] += 1
        # planar() re-orthonormalises, so rounding cannot pile up over thousands of frames
        self.T_loc_odom = planar(outcome.T_loc_base @ invert(T_odom_base))
        return outcome

    def _fusion_params(self, filt: FilterParams) -> FilterParams:
        """The filter's parameters for this frame's registration: while the fleet has not
        yet learned its wheels' scale (`calibrated_segments`), a registration's weak
        direction keeps the uncalibrated power's weight against them."""
        if filt.weak_inflation_power_uncalibrated <= 0 or self.odometry is None \
                or self.frames_uncalibrated < 0:
            return filt
        if self.odometry.calibration.pooled_segments() >= filt.calibrated_segments:
            log.info("wheels calibrated after %d frames: registrations' weak directions at "
                     "power %g from now on", self.frames_uncalibrated, filt.weak_inflation_power)
            self.frames_uncalibrated = -1
            return filt
        self.frames_uncalibrated += 1
        return replace(filt, weak_inflation_power=filt.weak_inflation_power_uncalibrated)

    def _wall_heading(self, cloud: small_gicp.PointCloud, guess: np.ndarray,
                      T_odom_base: np.ndarray) -> np.ndarray:
        """The guess after the heading the frame's walls give; T_loc_odom takes it up."""
        reacquired = self.walls.n_reacquired
        xyyaw, self.P = self.walls.update(np.array(xyyaw_from_T(guess)), self.P,
                                          cloud.points()[:, :3], cloud.normals()[:, :3],
                                          xyyaw_from_T(T_odom_base)[2])
        if self.walls.n_reacquired > reacquired and self.registrar.params.reset_on_wall_reacquire:
            self.registrar.reset()
            self._rejected = []
        turn = float(wrap_angle(xyyaw[2] - xyyaw_from_T(guess)[2]))
        limit = self.registrar.params.reset_on_wall_conflict_rad
        self._wall_turn = (xyyaw_from_T(guess)[2], xyyaw[2]) if 0 < limit < abs(turn) else None
        guess = T_from_xyyaw(*xyyaw)
        self.T_loc_odom = planar(guess @ invert(T_odom_base))
        return guess

    def _sides_against_the_walls(self, yaw_measured: float) -> bool:
        """Whether this frame's walls turned the heading far (`reset_on_wall_conflict_rad`)
        and its registration against the map sides with the heading from before: the map
        was built at the heading the walls corrected (a team's direction overruling the
        robot's own, a turn behind teammates registered wrong), and aligning to it would take
        the correction back frame after frame. A map that agrees with the walls is kept."""
        if self._wall_turn is None:
            return False
        before, after = self._wall_turn
        return abs(float(wrap_angle(yaw_measured - before))) < abs(
            float(wrap_angle(yaw_measured - after)))

    def _scan_turn(self, frame: tuple[small_gicp.PointCloud, small_gicp.KdTree] | None,
                   T_odom_base: np.ndarray, filt: FilterParams,
                   ) -> tuple[np.ndarray, FilterParams]:
        """The odometry pose with its heading change since the last frame fused with the
        frames' own (when they give it), and the process noise that step carries."""
        if self.scans is None:
            return T_odom_base, filt
        if frame is None:
            self.scans.reset()
            return T_odom_base, filt
        scan_turn = self.scans.turn(*frame, T_odom_base)
        if scan_turn is None:
            return T_odom_base, filt
        x0, y0, yaw0 = xyyaw_from_T(self._T_odom_prev)
        x1, y1, yaw1 = xyyaw_from_T(T_odom_base)
        odom_turn = wrap_angle(yaw1 - yaw0)
        # inverse-variance weights: odometry's heading is good driving straight (its error
        # grows with the turn), the frames' is good at any turn rate
        q_odom = (filt.q_rad2 + filt.q_rad2_per_rad * abs(odom_turn)
                  + filt.q_rad2_per_m * float(np.hypot(x1 - x0, y1 - y0)))
        q_scan = self.scans.params.sigma_rad ** 2
        turn = (odom_turn * q_scan + scan_turn * q_odom) / (q_odom + q_scan)
        # the odometry chain stays continuous: what the frames say about this step's heading
        # is absorbed into T_loc_odom, like a registration's correction
        T_fused = T_from_xyyaw(x1, y1, yaw0 + turn)
        self.T_loc_odom = planar(self.T_loc_odom @ T_fused @ invert(T_odom_base))
        return T_odom_base, replace(filt, q_rad2=q_odom * q_scan / (q_odom + q_scan),
                                    q_rad2_per_rad=0.0, q_rad2_per_m=0.0)

    def _calibrate(self, cloud: small_gicp.PointCloud, tree: small_gicp.KdTree,
                   meas: np.ndarray) -> None:
        """Close (or open) a calibration segment at this well-registered frame. With
        `frame_pairs` its motion is the frame aligned to the segment's first; where that
        alignment fails or is weak along a direction, the segment is given up and one opens
        here."""
        odometry = self.odometry
        p = odometry.calibration.params
        if not p.frame_pairs or not odometry.due():
            odometry.registered(meas)
            return
        start = odometry.anchor_xyyaw
        if start is not None and self._segment_frame is not None:
            T_start = T_from_xyyaw(*start)
            T_rel = self._pair_motion(self._segment_frame, cloud,
                                      invert(T_start) @ T_from_xyyaw(*meas), p)
            if T_rel is None:
                odometry.drop_segment()
            else:
                meas = np.array(xyyaw_from_T(T_start @ T_rel))
        odometry.registered(meas)
        self._segment_frame = (cloud, tree)

    @staticmethod
    def _pair_motion(first: tuple[small_gicp.PointCloud, small_gicp.KdTree],
                     cloud: small_gicp.PointCloud, guess: np.ndarray,
                     p: CalibrationParams) -> np.ndarray | None:
        """Planar T_first_cloud of a frame aligned to an earlier one (None: not converged,
        too little overlap, a direction it cannot see, or far from the map's `guess`)."""
        res = small_gicp.align(first[0], cloud, first[1], guess, registration_type="GICP",
                               max_correspondence_distance=p.pair_max_corr_m, num_threads=1,
                               max_iterations=p.pair_max_iterations,
                               rotation_epsilon=1e-4, translation_epsilon=1e-4)
        if not res.converged or res.num_inliers < p.min_inlier_frac * cloud.size() \
                or translation_information_ratio(np.asarray(res.H)) < 1.0 / p.max_weak_ratio:
            return None
        dx, dy, dyaw = xyyaw_from_T(invert(guess) @ res.T_target_source)
        if math.hypot(dx, dy) > p.pair_gate_m or abs(dyaw) > p.pair_gate_rad:
            return None
        return planar(res.T_target_source)

    def _sure_enough_to_insert(self) -> bool:
        """Whether an unregistered frame may join the map at the guess: its heading σ is
        within `unregistered_insert_max_sigma_rad`. A frame inserted 1.4° off (a turn behind
        teammates) becomes what the next frames register against, and they agree with it."""
        params = self.registrar.params
        limit = params.unregistered_insert_max_sigma_rad
        if limit <= 0 or math.sqrt(max(float(self.P[2, 2]), 0.0)) <= limit \
                or self.n_held_out >= params.unregistered_insert_max_held:
            self.n_held_out = 0
            return True
        self.n_held_out += 1
        self.outcomes["kept out of the map"] += 1
        return False

    def _align_cloud(self, points_base: np.ndarray) -> small_gicp.PointCloud | None:
        """The frame's points within `align_max_range_m` and `align_max_bearing_rad`,
        downsampled (None: all of them)."""
        p = self.registrar.params
        if p.align_max_range_m <= 0 and p.align_max_bearing_rad <= 0:
            return None
        keep = np.ones(len(points_base), bool)
        if p.align_max_range_m > 0:
            keep &= np.hypot(points_base[:, 0], points_base[:, 1]) <= p.align_max_range_m
        if p.align_max_bearing_rad > 0:
            keep &= np.abs(np.arctan2(points_base[:, 1], points_base[:, 0])) \
                <= p.align_max_bearing_rad
        return self.registrar._cloud(points_base[keep])

    def _filtered(self, frame: tuple[small_gicp.PointCloud, small_gicp.KdTree] | None,
                  guess: np.ndarray, filt: FilterParams,
                  align_cloud: small_gicp.PointCloud | None = None) -> RegistrationOutcome:
        """Register (`align_cloud` when given), fuse with the odometry guess by the filter,
        insert what it accepts (the whole frame)."""
        reg = self.registrar
        if frame is None:
            return RegistrationOutcome(guess, False, "too few points")
        cloud = frame[0]
        if reg.n_inserted == 0:
            reg.insert(cloud, guess)
            return RegistrationOutcome(guess, False, "empty map")
        aligned = reg.align(cloud if align_cloud is None else align_cloud, guess)
        if isinstance(aligned, str):  # new ground the map does not cover yet: keep odometry
            if (aligned != "not converged" or reg.params.insert_unconverged) and \
                    self._sure_enough_to_insert():
                reg.insert(cloud, guess)
            return RegistrationOutcome(guess, False, aligned)
        T_reg, H, inliers = aligned
        self.info_ratio = translation_information_ratio(H)
        meas = np.array(xyyaw_from_T(T_reg))
        if self._sides_against_the_walls(meas[2]):
            reg.reset()
            reg.insert(cloud, guess)
            self._rejected = []
            return RegistrationOutcome(guess, False, "map reset by the walls", T_reg)
        R_gate = measurement_cov(H, meas[2], filt) * overlap_inflation(inliers, filt)
        R = R_gate * count_inflation(
            inliers, (cloud if align_cloud is None else align_cloud).size(), filt)
        fusion = fuse(np.array(xyyaw_from_T(guess)), self.P, meas, R, filt, R_gate)
        if not fusion.accepted:
            T_odom_base = invert(self.T_loc_odom) @ guess
            self._rejected = self._rejected[-max(filt.reacquire_frames, 1):] + [
                (meas, np.array(xyyaw_from_T(T_odom_base)))]
            if not agree([r for r, _ in self._rejected], [o for _, o in self._rejected], filt):
                return RegistrationOutcome(guess, False, "implausible jump", T_reg,
                                           fusion.mahalanobis2)
            self.outcomes["reacquired"] += 1
            self._rejected = []
            self.P = R
            reg.insert(cloud, T_reg)
            reg.n_accepted += 1
            return RegistrationOutcome(T_reg, True, "", T_reg, fusion.mahalanobis2)
        self._rejected = []
        self.P = fusion.P
        if self.odometry is not None and is_good_registration(
                inliers, R, self.odometry.calibration.params):
            self._calibrate(cloud, frame[1], meas)
        T = T_from_xyyaw(*fusion.xyyaw)
        if reg.moved_since_insert(T):
            reg.insert(cloud, T)
        reg.n_accepted += 1
        return RegistrationOutcome(T, True, "", T_reg, fusion.mahalanobis2)
