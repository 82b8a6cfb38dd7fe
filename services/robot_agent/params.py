"""The algorithm parameter sets of the agent's modules, built from its config section."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from services.robot_agent.config import AgentConfig
from services.robot_agent.drf import DrfParams
from services.robot_agent.drift_filter import FilterParams
from services.robot_agent.odometry_calibration import CalibrationParams
from services.robot_agent.registrar import RegistrationParams
from services.robot_agent.scan_odometry import ScanOdometryParams
from services.robot_agent.wall_heading import WallHeadingParams

if TYPE_CHECKING:
    from services.robot_agent.keyframe_graph import LoopParams


def registration_params(cfg: AgentConfig) -> RegistrationParams:
    return RegistrationParams(
        step_m=cfg.reg_step_m, step_per_m=cfg.reg_step_per_m, step_rad=cfg.reg_step_rad,
        min_inlier_frac=cfg.reg_min_inlier_frac, map_horizon=cfg.reg_map_horizon,
        map_voxel_m=cfg.reg_map_voxel_m, degenerate_ratio=cfg.reg_degenerate_ratio,
        max_removed_frac=cfg.reg_max_removed_frac, min_points=cfg.reg_min_points,
        insert_min_m=cfg.reg_insert_min_m, insert_min_rad=cfg.reg_insert_min_rad,
        use_unconverged=cfg.reg_use_unconverged,
        unregistered_insert_max_sigma_rad=cfg.reg_unregistered_insert_max_sigma_rad,
        unregistered_insert_max_held=cfg.reg_unregistered_insert_max_held,
        reset_on_wall_reacquire=cfg.reg_wall_reacquire_reset,
        reset_on_wall_conflict_rad=cfg.reg_wall_reset_conflict_rad,
        max_corr_m=cfg.reg_max_corr_m,
        align_max_range_m=cfg.reg_align_max_range_m,
        neighbors=cfg.reg_neighbors,
        align_max_bearing_rad=math.radians(cfg.reg_align_max_bearing_deg),
        coarse_voxel_m=cfg.reg_coarse_voxel_m, coarse_below_frac=cfg.reg_coarse_below_frac,
        coarse_agree_rad=cfg.reg_coarse_agree_rad,
        filter=FilterParams(reacquire_rad_per_rad=cfg.reg_reacquire_rad_per_rad,
                            reacquire_frames=cfg.reg_reacquire_frames,
                            coupled_length_m=cfg.reg_coupled_length_m,
                            r_m=cfg.reg_sigma_m, r_rad=cfg.reg_sigma_rad,
                            weak_inflation_power=cfg.reg_weak_inflation_power,
                            weak_inflation_knee=cfg.reg_weak_inflation_knee,
                            weak_inflation_power_uncalibrated=(
                                cfg.reg_weak_inflation_power_uncalibrated),
                            calibrated_segments=cfg.reg_weak_inflation_calibrated_segments,
                            full_overlap_frac=cfg.reg_full_overlap_frac,
                            full_inliers=cfg.reg_full_inliers,
                            max_jump_sigmas=cfg.reg_max_jump_sigmas,
                            q_rad2_per_rad=cfg.odom_turn_sigma_per_sqrt_rad**2,
                            q_rad2_per_m=cfg.odom_heading_sigma_per_sqrt_m**2)
        if cfg.reg_fusion == "filter" else None,
        calibration=CalibrationParams(segment_m=cfg.odom_calibration_segment_m,
                                      max_weak_ratio=cfg.odom_calibration_max_weak_ratio,
                                      prior_segments=cfg.odom_calibration_prior_segments,
                                      fleet_weight=cfg.odom_calibration_fleet_weight,
                                      frame_pairs=cfg.odom_calibration_frame_pairs,
                                      turn_corrected_chords=(
                                          cfg.odom_calibration_turn_corrected_chords),
                                      fleet_prior_segments=(
                                          cfg.odom_calibration_fleet_prior_segments),
                                      fleet_prior_from_spread=(
                                          cfg.odom_calibration_fleet_prior_from_spread))
        if cfg.odom_calibration else None,
        scan_odometry=ScanOdometryParams(sigma_rad=cfg.reg_scan_sigma_rad,
                                         when_hidden=cfg.reg_scan_when_hidden)
        if cfg.reg_scan_heading else None,
        wall_heading=WallHeadingParams(min_points=cfg.reg_wall_min_points,
                                       sigma_rad=cfg.reg_wall_sigma_rad,
                                       learn_max_sigma_rad=cfg.reg_wall_learn_max_sigma_rad,
                                       learn_frames=cfg.reg_wall_learn_frames,
                                       team_inlier_rad=cfg.reg_wall_team_inlier_rad or None,
                                       reacquire_frames=cfg.reg_wall_reacquire_frames or None,
                                       along_gap_m=cfg.reg_wall_segment_max_gap_m)
        if cfg.reg_wall_heading else None,
    )


def loop_params(cfg: AgentConfig) -> LoopParams:
    from services.robot_agent.keyframe_graph import LoopParams  # gtsam: only with the back end

    return LoopParams(search_radius_m=cfg.loop_search_radius_m,
                      max_candidates=cfg.loop_max_candidates)


def drf_params(cfg: AgentConfig) -> DrfParams:
    return DrfParams(
        c=cfg.drf_c, radius_m=cfg.robot_size_m, robot_top_m=cfg.robot_top_m,
        floor_z_m=0.012, eps_m=cfg.drf_eps_m, min_points=cfg.drf_min_points,
        voxel_m=cfg.drf_voxel_m, margin_m=cfg.drf_margin_m,
    )
