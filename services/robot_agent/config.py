"""Robot agent section of the mission config."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class AgentConfig(BaseModel):
    """Mapping, localization and navigation of one robot."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    drf: bool = Field(default=True, description="mutual awareness + Dynamic Robot Filter")
    # -- mutual awareness + DRF (docs/agent.md: how c was chosen) ----------------------------
    drf_c: float = Field(
        default=0.25, ge=0, description="buffer c: c/d rad in awareness, ≈ c m around the robot"
    )
    awareness: Literal["paper", "partial"] = Field(
        default="partial",
        description="paper = whole robot in view (paper's inequality); partial = any part",
    )
    robot_size_m: float = Field(default=0.306, gt=0, description="R: largest robot dimension")
    robot_top_m: float = Field(default=0.42, gt=0, description="top of a teammate + margin")
    drf_eps_m: float = Field(default=0.08, gt=0, description="DBSCAN eps")
    drf_min_points: int = Field(default=1, ge=1)
    drf_voxel_m: float = Field(default=0.03, gt=0, description="voxelize before DBSCAN")
    teammate_max_age_ticks: int = Field(default=30, ge=1, description="older estimates unused")
    drf_margin_m: float = Field(
        default=0.12, ge=0, description="footprint grown by this is removed whatever DBSCAN says"
    )
    predict_max_ticks: int = Field(
        default=3, ge=0, description="extrapolate a teammate's last motion at most this far"
    )
    map_wait_ticks: int = Field(
        default=20, ge=0, description="map nothing until every teammate's pose is known, or this"
    )
    # -- localization ----------------------------------------------------------------------
    registration: bool = Field(default=True, description="refine odometry by frame-to-map GICP")
    register_every_frames: int = Field(default=1, ge=1)
    map_heading_tolerance_m: float = Field(
        default=0.03, ge=0, description="a frame's points join the 3D map only within the "
        "range at which the filter's heading σ moves them this far (m; 0 = all points): a "
        "frame 2° off puts a wall 4 m away 14 cm out, a ghost, while the robot is still "
        "lost (docs/agent.md, \"A frame the map should not keep\")")
    # A fixed 8 cm / 0.05 rad gate and a map that never forgets beat the motion-scaled gate
    # with a 100-frame map in 300 s house missions: BV 5.8 % vs 17.9 %, drift ≤ 0.19 m / 2.1°
    # vs 0.36 m / 3.5° (docs/agent.md, "Registration gate").
    reg_step_m: float = Field(
        default=0.08, gt=0, description="accepted correction: base + per metre (localization.py)"
    )
    reg_step_per_m: float = Field(default=0.0, ge=0)
    reg_step_rad: float = Field(default=0.05, gt=0)
    # 0.2 left robots that start side by side (6 in the bookstore) unregistered through their
    # first turn: bookstore 6 robots BV 2.25 % → 0.0004 %, AWS house 0.035 % → 0.0002 % at 0.35
    reg_max_removed_frac: float = Field(
        default=0.35, ge=0, le=1, description="no registration when the DRF took more of a frame"
    )
    # 0.5 left a robot turning in place into unseen ground unregistered: its odometry yaw
    # error (1-2° in a 90° turn) was mapped and kept (house seed 4, AWS house); the filter
    # rejects what a frame with few matches gets wrong (docs/agent.md, "Drift filter")
    reg_min_inlier_frac: float = Field(default=0.15, ge=0, le=1)
    # bench/bench_localization.py (replays of house and bookstore missions): a 5 cm Gaussian
    # voxel map and dropping GICP's step along degenerate directions took the team map's ghost
    # volume from 4.4 % (house) and 39.7 % (bookstore) to 0.0000 %; docs/agent.md.
    reg_map_voxel_m: float = Field(
        default=0.05, gt=0, description="Gaussian voxel map resolution (15 cm voxels biased "
        "doorway registrations by up to 0.65° even on a perfect map)"
    )
    reg_degenerate_ratio: float = Field(
        default=0.05, ge=0, lt=1, description="with reg_fusion=gate: weak/strong translation "
        "information below this keeps odometry along the weak direction (aisles, one wall); 0 = "
        "never. The filter weighs the weak direction by its covariance instead")
    # bench/bench_localization.py replays of noisy house missions (docs/agent.md, "Drift
    # filter"): robots whose pose error passed 8 cm, 2 of 18 with the jump gate, 0 of 21 with
    # the filter, 30-point frames and 15 % inliers (team map BV median 0.17 % → 0 %)
    reg_fusion: Literal["filter", "gate"] = Field(
        default="filter", description="fuse registration with odometry by a Kalman filter on "
        "the pose (drift_filter.py) or accept it within the jump gate"
    )
    # 0.03 (3 × the 1 % turn-scale error): the lost turn of docs/agent.md re-acquired, bookstore
    # seed 2 BV 18.2 % → 0.05 %; house seeds 0-4 and AWS seeds 0-1 unchanged (never fires)
    reg_reacquire_rad_per_rad: float = Field(
        default=0.03, ge=0, description="re-acquisition: how far (rad per rad turned) the "
        "drift rejected registrations imply may change between them (odometry turn error)")
    # 0 (forty-fifth session, docs/agent.md "Calibration from frame pairs, and the
    # re-acquisitions that go wrong in the warehouse"): every warehouse re-acquisition
    # replayed moved the pose away from the truth (3.7-17 cm, most near the crowded start);
    # warehouse 300 s seeds 0-4 BV median 2.82 -> 2.40 %, worst 8.25 -> 2.71 %; it fired
    # once in 25 room missions
    reg_reacquire_frames: int = Field(
        default=0, ge=0, description="re-acquisition: this many registrations in a row the "
        "filter rejected, telling one story with odometry, reset the pose to theirs (0 = "
        "never; 3 brought back a lost turn in the early bookstore missions)")
    reg_wall_reset_conflict_rad: float = Field(
        default=0.0, ge=0, description="forget the registration map when one frame's walls "
        "turn the heading by more than this (rad; 0 = never) and the frame's registration "
        "against the map sides with the heading from before: the map was built at the heading "
        "the walls corrected, and aligning to it would take the correction back")
    reg_wall_reacquire_reset: bool = Field(
        default=True, description="with reg_wall_reacquire_frames: when the walls take the "
        "heading back, the registration map (built at the wrong heading, it would pull it "
        "back) is forgotten and started again from the next frame")
    reg_max_jump_sigmas: float = Field(
        default=4.0, ge=0, description="a registration whose position lies more than this many "
        "σ (P's position, floored at 3 cm) from the filter's prediction is rejected whatever "
        "its own covariance (a GICP local minimum); 0 = the χ² gate alone")
    reg_max_corr_m: float = Field(
        default=0.3, gt=0, description="GICP's largest correspondence distance, m; the voxel "
        "map looks only in the voxel a point falls in, so above its diagonal (8.7 cm at 5 cm) "
        "it changes nothing: 0.15 and 0.3 gave 15 identical missions")
    reg_coarse_voxel_m: float = Field(
        default=0.0, ge=0, description="> 0: frames the registration map matched poorly are "
        "aligned first on a second map of this voxel size (localization.py); 0 = none")
    reg_coarse_below_frac: float = Field(
        default=0.5, ge=0, le=1, description="with the coarse map: frames GICP converged on "
        "but matched under this share of their points try it too (0 = unconverged ones only)")
    reg_coarse_agree_rad: float = Field(
        default=0.0, ge=0, description="with the coarse map: its pose is kept only within this "
        "yaw of the fine map's own answer, rad (0 = always)")
    reg_scan_heading: bool = Field(
        default=False, description="the heading change between consecutive frames measured "
        "from the frames registered to each other too, fused with odometry's by their "
        "variances (scan_odometry.py; needs the filter fusion)")
    reg_scan_sigma_rad: float = Field(
        default=0.0025, gt=0, description="with reg_scan_heading: σ of that heading change per "
        "frame, rad")
    reg_scan_when_hidden: bool = Field(
        default=False, description="with reg_scan_heading: frames too hidden by teammates to "
        "register against the map still give the turn from the previous frame (what the DRF "
        "left of them), so a turn behind teammates is not on odometry alone")
    reg_wall_heading: bool = Field(
        default=True, description="an absolute heading from the directions of the walls in "
        "each frame, modulo 90°, against the world's direction learned from the first frames "
        "(wall_heading.py; needs the filter fusion)")
    reg_wall_min_points: int = Field(
        default=100, ge=10, description="with reg_wall_heading: wall points a frame needs")
    reg_wall_sigma_rad: float = Field(
        default=0.0035, gt=0, description="with reg_wall_heading: σ of a frame's heading, rad")
    reg_wall_learn_frames: int = Field(
        default=20, ge=1, description="with reg_wall_heading: the world's wall direction is "
        "learned from this many early frames with walls; teammates get it once learned")
    reg_wall_learn_max_sigma_rad: float = Field(
        default=0.017453292519943295, gt=0, description="with reg_wall_heading: the world's "
        "wall direction is learned only from early frames whose filter yaw σ is at most this, "
        "rad (1°)")
    reg_wall_team_inlier_rad: float = Field(
        default=0.005235987755982988, ge=0, description="with reg_wall_heading: a robot whose "
        "learned wall direction lies more than this from the robots' median (teammates' arrive "
        "with their poses) takes the mean of those within it instead, rad (0.3°); 0 = each "
        "robot its own")
    reg_wall_segment_max_gap_m: float = Field(
        default=1.0, ge=0, description="with reg_wall_heading: a straight wall segment is "
        "split where its points leave a gap this long along it (two walls in line, metres "
        "apart, are not one line), m; 0 = never")
    reg_wall_reacquire_frames: int = Field(
        default=5, ge=0, description="with reg_wall_heading: this many wall headings in a row "
        "rejected by the χ² gate and agreeing within 0.5° make the filter take them (its yaw "
        "variance grows by their mean innovation squared); 0 = never")
    reg_use_unconverged: bool = Field(
        default=False, description="GICP's pose on a frame it did not converge on (15 "
        "iterations) is fused by the filter like a converged one; false: the frame keeps the "
        "odometry guess and joins the map there")
    # 0.0087 (0.5°) with map_heading_tolerance_m 0.03: six-robot AWS house seed 0 BV 0.81 → 0 %,
    # warehouse (24 robots, 60 s) seeds 0-3 lower in every seed (docs/agent.md)
    reg_unregistered_insert_max_sigma_rad: float = Field(
        default=0.0087, ge=0, description="a frame that did not register (not converged, few "
        "inliers) joins a non-empty registration map at the odometry guess only while the "
        "filter's heading σ is at most this, rad (0 = always): after a turn behind teammates "
        "the guess can be 1-1.5° off, and the map would keep it (docs/agent.md, \"A frame "
        "the map should not keep\")")
    reg_unregistered_insert_max_held: int = Field(
        default=50, ge=0, description="with reg_unregistered_insert_max_sigma_rad: after this "
        "many frames in a row kept out, the next unregistered one joins whatever the σ (a "
        "robot far from anything its map holds, with no walls to take its heading, still "
        "builds a map to register against)")
    reg_insert_min_m: float = Field(
        default=0.0, ge=0, description="a registered frame joins the registration map only "
        "this far from the last one that did (0 = every frame)")
    reg_insert_min_rad: float = Field(
        default=0.0, ge=0, description="... or turned this much from it, rad")
    # 0.7 (docs/agent.md, "Weaker measurements from frames that matched few points"): worst BV
    # over house 0-4, AWS 0-1, bookstore 0-2 5.54 % → 0.19 % (AWS 1.17 / 5.54 → 0.065 / 0.11 %),
    # bookstore 0.02-0.06 → 0.08-0.19 %; 0.5 left house seed 2 at 4.8 %
    reg_full_overlap_frac: float = Field(
        default=0.7, ge=0, le=1, description="a registration whose inlier share is below "
        "this is weaker by the ratio (R inflated); 0 = every registration alike")
    reg_full_inliers: int = Field(
        default=1000, ge=0, description="... and one that matched fewer points than this "
        "(after downsampling) is weaker by the ratio too, gated at its own precision: a few "
        "hundred far points carry less than a room's thousand (warehouse BV median 1.25 -> "
        "0.32 %, docs/agent.md \"A frame of a few far points\"); 0 = the count does not matter")
    reg_sigma_m: float = Field(
        default=0.005, gt=0, description="σ of one registration along its strong directions, m")
    reg_sigma_rad: float = Field(
        default=0.002, gt=0, description="σ of one registration's yaw, rad")
    # 2 since the forty-sixth session (docs/agent.md, "Power 2 by default"): warehouse 300 s
    # BV median 2.40 → 1.00 % over seeds 0-4; the rooms stay within issue 11's bounds, the
    # 3-robot house and bookstore missions take 17-21 % longer
    reg_weak_inflation_power: float = Field(
        default=2.0, ge=1, le=3, description="a registration's σ² along a weaker direction "
        "grows by its information ratio to the strongest, to this power (2: along an aisle, "
        "where the view's edges pull frames back, the wheels count for more; 1: the ratio "
        "itself)")
    reg_weak_inflation_knee: float = Field(
        default=1.0, ge=1, description="... for the part of that ratio above this only (ratio "
        "r ≤ knee: σ² × r; above: × knee·(r / knee)^power): the rooms' mildly lopsided "
        "registrations keep power 1's weight, the aisles' (r ~ 100) get the wheels")
    # 1 since the fifty-fourth session (docs/agent.md, "The first minute's wheels"):
    # warehouse 300 s, seeds 0-4, BV median 0.084 → 0.059 %, worst 1.415 → 0.798 %, ATE 5.68
    # → 4.85 cm; the rooms' 15 missions all at BV 0
    reg_weak_inflation_power_uncalibrated: float = Field(
        default=1.0, ge=0, le=3, description="> 0: this power instead until the fleet knows "
        "its wheels' scale from `reg_weak_inflation_calibrated_segments` pooled unit "
        "segments: uncalibrated wheels read as long as they were made, and the first "
        "minute's map, stretched by them, is what later frames register against")
    reg_weak_inflation_calibrated_segments: float = Field(
        default=40.0, ge=0, description="... the fleet's pooled calibration segments (1 m "
        "each, this robot's and the teammates') after which the wheels count as calibrated")
    reg_coupled_length_m: float = Field(
        default=0.0, ge=0, description="> 0: a registration's covariance from its whole planar "
        "information, yaw compared at this lever arm (drift_filter.measurement_cov)")
    # on (docs/agent.md, "Odometry calibration"): over house, AWS and bookstore seeds 0-4,
    # BV median 0.082 → 0.035 %, worst 6.6 → 4.8 %, ATE mean 2.96 → 2.22 cm
    odom_calibration: bool = Field(
        default=True, description="learn odometry's scale, turn scale and heading bias from "
        "the motion between well-registered frames and correct odometry by them (needs the "
        "filter fusion)")
    odom_turn_sigma_per_sqrt_rad: float = Field(
        default=0.02, gt=0, description="heading error per √rad turned the drift filter "
        "expects of the odometry (its process noise; 0.02 covers a 1 % turn-scale error and "
        "the 1 % random walk)")
    # 0.01 let a registration walk the heading 1.6° in 2 s of straight driving along a
    # corridor the walls did not help with (AWS house), each frame taking 75 % of the yaw it
    # asked; the calibrated wheels drift far less (docs/agent.md, "A heading the registration
    # walks away with")
    odom_heading_sigma_per_sqrt_m: float = Field(
        default=0.003, gt=0, description="heading error per √m driven the drift filter expects "
        "of the odometry (its process noise; the simulator's heading bias of 0.005 rad/m is "
        "learned by the calibration, what is left is a fraction of it)")
    odom_calibration_segment_m: float = Field(
        default=1.0, gt=0, description="a calibration segment closes after this much driving")
    reg_align_max_range_m: float = Field(
        default=0.0, ge=0, description="register a frame with its points within this range "
        "only (m; 0 = all); it joins the map whole")
    reg_neighbors: int = Field(
        default=10, ge=3, description="points per covariance and normal estimate of a "
        "frame's downsampled points (more: smoother normals where far points are noisy)")
    reg_align_max_bearing_deg: float = Field(
        default=0.0, ge=0, lt=90, description="... and within this bearing of straight ahead "
        "(base frame, deg; 0 = all): the view's side edges pull back too (docs/agent.md, "
        "'Both edges of the view pull back')")
    reg_whole_voxels: Literal["off", "view", "pixels", "sphere"] = Field(
        default="off", description="register (and map for registration) only the points "
        "whose registration-map voxel the frame saw whole: a voxel the view cuts holds its "
        "inner part only and pulls the next frames back (view_voxels.py). 'view': all the "
        "voxel's corners inside the image and the range; 'pixels': inside the image, with a "
        "return at every pixel of its footprint (cuts by range, grazing angles, the DRF); "
        "'sphere': as 'pixels' for the voxel's bounding sphere, its far side within range")
    reg_whole_voxels_below_ratio: float = Field(
        default=1.0, gt=0, le=1, description="... only while the last registration's "
        "weakest / strongest translation information is below this (an aisle or one wall: "
        "~0.01; 1 = always)")
    odom_calibration_prior_segments: float = Field(
        default=2.0, ge=0, description="the calibration's prior at 'no error' weighs this many "
        "1 m segments (fewer: learned sooner, trusting the first segments more)")
    odom_calibration_fleet_weight: float = Field(
        default=0.0, ge=0, le=1, description="teammates' calibration segments (sent with their "
        "poses) count this much each in this agent's fit: 1 pools the fleet's (robots of one "
        "model, the same wheel errors), 0 each its own (docs/agent.md, 'The fleet's wheels')")
    odom_calibration_fleet_prior_segments: float = Field(
        default=8.0, ge=0, description="teammates' pooled calibration (sent with their poses) "
        "is the centre of this agent's prior, worth this many 1 m segments more than the 'no "
        "error' one, which its own segments outweigh as they accumulate (robots of one model "
        "whose wheels may differ; 0 = its own segments only; docs/agent.md, 'The fleet's "
        "wheels as a prior')")
    odom_calibration_fleet_prior_from_spread: bool = Field(
        default=False, description="the fleet prior's weight learned from how much the "
        "teammates' own fits differ beyond their noise (empirical Bayes, per parameter): up to "
        "10 000 segments when the wheels are alike, down to fleet_prior_segments when they "
        "differ; needs 5 teammates with fits (docs/agent.md, 'The fleet prior's weight from "
        "the fleet's spread')")
    # true since the fifty-fifth session, with power 1 until calibrated (docs/agent.md, "The
    # turn-corrected chords on by default"): warehouse 300 s seeds 0-4 BV median 0.059 →
    # 0.052 %, worst 0.798 → 0.424 %, ATE 4.85 → 3.73 cm; rooms' BV ≤ 0.002 % in 15 of 15
    odom_calibration_turn_corrected_chords: bool = Field(
        default=True, description="a calibration segment's odometry chord from its increments "
        "with the learned turn errors taken out, not from its two raw poses: the wheels' "
        "over-turning bends the raw path and shortens its chord, and the scale learned from "
        "raw chords falls short (false: the raw chords; docs/agent.md, 'The segments' chords "
        "bent by the turns')")
    odom_calibration_max_weak_ratio: float = Field(
        default=10.0, ge=1, description="a registration ends a calibration segment only when "
        "its weakest translation direction is at most this many times weaker (variance) than "
        "its strongest")
    odom_calibration_frame_pairs: bool = Field(
        default=False, description="a calibration segment's motion from its end frame "
        "aligned to its first, not from the two frames' poses against the map: the map the "
        "end meets was built during the segment on the uncorrected wheels and pulls the end "
        "back toward them (the fleet learned 1.7-1.96 % of the simulator's 2 %)")
    reg_min_points: int = Field(
        default=30, ge=10, description="points a frame needs (after 8 cm voxels) to register"
    )
    reg_map_horizon: int = Field(
        default=100_000, ge=1, description="registered frames a map voxel survives unobserved"
    )
    # -- back end: keyframe pose graph (keyframe_graph.py) ---------------------------------
    # Off by default: in replays its closures (median 1.4 cm / 0.2° off, a few 10-55 cm off
    # and accepted) do not yet beat the front end alone (docs/agent.md, "Back end").
    loop_closure: bool = Field(
        default=False, description="keyframe pose graph with loop closures (needs registration)"
    )
    loop_search_radius_m: float = Field(
        default=3.0, gt=0, description="older keyframes within this are loop candidates"
    )
    # 1: a map of several older keyframes at drifted estimates is blurred (replays: 10 cm
    # closures that two closing keyframes agreed on); one keyframe's voxel means are not
    loop_max_candidates: int = Field(
        default=1, ge=1, description="older keyframes a closing one is registered to"
    )
    voxel_m: float = Field(default=0.05, gt=0)
    max_v_mps: float = Field(default=0.5, gt=0)
    max_omega_radps: float = Field(default=math.pi / 4, gt=0)

    # -- perception ------------------------------------------------------------------------
    pixel_stride: int = Field(default=1, ge=1, description="use every n-th pixel for the map")
    ray_bin_rad: float = Field(
        default=0.01, gt=0, description="bearing bin of the free-space scan (~cell / range)"
    )
    # -- keyframe submaps ------------------------------------------------------------------
    keyframe_dist_m: float = Field(default=1.5, gt=0)
    keyframe_yaw_rad: float = Field(default=math.pi / 4, gt=0)
    keyframe_max_ticks: int = Field(default=300, ge=1)
    submap_every_ticks: int = Field(
        default=10, ge=1, description="publish the pending delta every n ticks (and on switch)"
    )
    color_resend: int = Field(
        default=24, ge=0, description="resend a voxel when its mean colour moves this much"
    )
    # 2 (counts within 2x, unused by the edge) cost 21-32 kB/s with means; 8: 19 kB/s (house)
    resend_growth: int = Field(
        default=8, ge=2, description="a voxel is sent again when its point count reaches the "
        "next power of this (the edge's counts are within this factor; means and colours refine)"
    )
    # means as int16 mm made the submap traffic 1.7-2.3x that of centres (zstd); a centre
    # plus one byte of L^3 cells costs about +30 % on the points (docs/agent.md)
    mean_levels: int = Field(
        default=5, ge=1, le=6, description="a voxel's mean point is sent as one of L×L×L cells "
        "of the voxel (5: 1 cm cells, 2.9 mm RMS at 5 cm voxels); 1: voxel centres only"
    )
    # -- local 2D grid ---------------------------------------------------------------------
    cell_m: float = Field(default=0.05, gt=0, description="2D grid and free-cell size")
    grid_half_size_m: float = Field(
        default=25.0, gt=0, description="local grid ± around spawn; it grows by half this "
        "around a goal beyond it")
    obstacle_z_min_m: float = Field(default=0.05, description="points above this are obstacles")
    obstacle_z_max_m: float = Field(default=0.6, description="... and below this (robot + margin)")
    # -- navigation ------------------------------------------------------------------------
    robot_radius_m: float = Field(default=0.18, gt=0)
    inflation_margin_m: float = Field(default=0.05, ge=0)
    plan_through_unknown: bool = True
    # 0 ends the 17-39 s drives around the outside of the house to a goal cut off inside,
    # yet over ten seeds × three worlds 9 missions of 30 ended under 98 % 3D coverage
    # against 3 (docs/agent.md, "A path around the outside of the house"): 1 m stays
    plan_beyond_known_m: float = Field(
        default=1.0, ge=0, description="how far beyond the box of every known cell (and the "
        "robot and its goal) a path may run through unknown space, m (0: a goal cut off "
        "inside is not reached by a path around the outside of the world's walls)")
    goal_tolerance_m: float = Field(default=0.35, gt=0)
    goal_snap_m: float = Field(default=0.6, ge=0, description="snap a blocked goal this far")
    start_island_m2: float = Field(
        default=1.0, ge=0, description="a robot on a traversable island smaller than this plans "
        "from the nearest larger component within start_island_snap_m (as the edge assigns "
        "goals: edge.start_island_m2); 0: off")
    start_island_snap_m: float = Field(default=1.0, ge=0)
    replan_every_ticks: int = Field(default=20, ge=1)
    lookahead_m: float = Field(default=0.4, gt=0)
    smooth_paths: bool = Field(
        default=False, description="cut A*'s 0°/45° staircase short along lines of sight "
        "(path_smoothing.py), so the robot drives straight instead of weaving")
    turn_in_place_rad: float = Field(
        default=0.7, gt=0, description="heading error above which the robot turns in place"
    )
    k_omega: float = Field(default=1.5, gt=0, description="turn-in-place gain, 1/s")
    look_tolerance_rad: float = Field(
        default=0.35, gt=0, description="on arrival, a goal's look point this far off the "
        "heading counts as faced (well inside the camera's half FoV)")
    spin_omega_radps: float = Field(default=0.4, ge=0, description="rotation while idle")
    # False: warehouse, 24 robots, 60 s, seeds 0 / 1: BV 43.3 / 26.9 → 29.1 / 23.2 %, ATE 19.0 /
    # 10.8 → 9.3 / 9.0 cm; 3 robots, 9 missions in three worlds: 8 identical (docs/agent.md)
    idle_spin_when_hidden: bool = Field(
        default=False, description="spin while idle even when teammates hide the view (False: "
        "hold still while the last frame was too hidden to register: the turn would go "
        "unregistered and odometry's turn error would stay in the map)")
    hidden_turn_hold_s: float = Field(
        default=0.0, ge=0, description="hold a turn in place for up to this long (s) while the "
        "last frame was too hidden by teammates to register, so the turn is registered once "
        "they pass (0 = never hold): a turn on odometry alone ends 1-1.5° off, and the first "
        "frame after it registers into half-seen ground (docs/agent.md, \"Turns behind "
        "teammates\")")
    hidden_hold_driving: bool = Field(
        default=False, description="with hidden_turn_hold_s: driving is held too, not only "
        "turns in place (along-track, odometry alone runs 2 % long until it is calibrated)")
    spin_before_first_goal: bool = Field(
        default=True, description="spin while idle before the first goal too (False: hold "
        "still: robots that start side by side see mostly teammates, so the turn goes "
        "unregistered and odometry's turn error stays in the map)")
    # True: 3 robots, seeds 0-4, mapping time AWS house 228 → 193 s, house 125 → 131,
    # bookstore 95 → 86; robot-seconds stalled 280 → 69 in the AWS house (docs/agent.md)
    contact_layer: bool = Field(
        default=True, description="commanded forward for a second without moving, the robot "
        "marks the cells just ahead occupied for its planner for 15 s (contacts.py: what the "
        "camera misses, such as a chair's seat over its legs); a goal only reachable through "
        "such a mark ends unreachable")
    contact_boxed_in_goals: int = Field(
        default=3, ge=0, description="after this many goals in a row found unreachable only "
        "through the contact marks, the robot forgets its marks and takes the path (they box "
        "it in where it stands); 0: never")
    yield_dist_m: float = Field(
        default=0.7, ge=0, description="stop driving when a teammate centre is this close ahead"
    )
    yield_half_angle_rad: float = Field(default=math.pi / 3, ge=0)
    yield_detour_ticks: int = Field(
        default=10, ge=0, description="after yielding this long to a teammate of lower id "
        "(3× as long to any), plan around it (0 = never: two robots face to face both yield "
        "until the validator ends a goal, and goal after goal through the same place; "
        "docs/agent.md, 'Face to face at a shelf end')")
    detour_radius_m: float = Field(
        default=0.25, gt=0, description="a teammate blocks this radius of the planning grid "
        "while detouring (the robot's own radius is added by the inflation)")
    validator_beta: int = Field(default=5, ge=1, description="β: path points in the window")
    validator_slack_s: float = Field(
        default=4.0, ge=0, description="added to Σ t_e over the window (acceleration, slow-down)"
    )
    # -- edge away (issue 7) ---------------------------------------------------------------
    local_explore: bool = Field(default=True, description="own frontiers while the edge is away")
    frontier_min_cells: int = Field(default=4, ge=1, description="smallest local frontier")
    local_goal_retry_ticks: int = Field(default=20, ge=1)
