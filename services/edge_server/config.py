"""Edge server section of the mission config."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class EdgeConfig(BaseModel):
    """Merging, frontiers and assignment."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    planner: Literal["space", "space-paper", "nearest", "utility", "rrt"] = "space"
    plan_every_edge_ticks: int = Field(
        default=1, ge=1, description="a full plan every this many edge ticks, and at any edge "
        "tick where an active robot holds no goal; the other edge ticks are acknowledged "
        "unplanned (1: plan at every edge tick; 2 measured: +4 % real-time factor, a higher "
        "ATE, docs/edge.md \"Fewer plans\")")
    grid_resolution_m: float = Field(default=0.05, gt=0)
    voxel_m: float = Field(default=0.05, gt=0)
    # merged grid
    grid_bounds_m: tuple[float, float, float, float] | None = Field(
        default=None, description="(xmin, ymin, xmax, ymax) world m; None = grow to fit the data"
    )
    grid_margin_m: float = Field(default=1.0, ge=0, description="unknown border around the data")
    grid_chunk_m: float = Field(default=2.0, gt=0, description="growth step of the grid bounds")
    obstacle_z_min_m: float = Field(default=0.05, description="obstacle band bottom (above floor)")
    obstacle_z_max_m: float = Field(default=0.5, description="obstacle band top (robot height)")
    # frontiers
    robot_radius_m: float = Field(default=0.2, ge=0, description="inflation radius of obstacles")
    frontier_min_cells: int = Field(default=5, ge=1, description="smaller clusters are dropped")
    goal_max_offset_m: float = Field(
        default=1.0, ge=0, description="max distance from a frontier to its translated goal f′"
    )
    start_snap_m: float = Field(
        default=1.0, ge=0, description="a robot off the traversable grid plans from the nearest "
        "traversable cell within this distance (the floor under a robot is never seen)"
    )
    start_island_m2: float = Field(
        default=1.0, ge=0, description="a robot on a traversable island smaller than this plans "
        "from the nearest larger component within start_snap_m: inflated obstacles pinch the "
        "way it came in (house seed 1: a robot on a one-cell island got no goal for 82 s); 0: off"
    )
    # bi-variate spatial frontiers (Alg. 1; choices and evidence: docs/edge.md)
    frontier_voxel_m: float = Field(default=0.05, gt=0, description="ϱ: downsample voxel")
    search_radius_m: float = Field(default=0.15, gt=0, description="r_s")
    density_threshold: float = Field(default=27.0, gt=0, description="δ_d: F_u = ρ < δ_d")
    variance_threshold_m2: float = Field(default=0.0128, gt=0, description="δ_v: F_w = σ² > δ_v")
    frontier_link_m: float = Field(default=0.15, ge=0, description="voxels this close join")
    unexplored_min_voxels: int = Field(
        default=8, ge=1, description="smaller F_u regions are dropped (30 made SPACE faster but "
        "left 97.9 % 3D coverage in one of five house missions: docs/edge.md, \"Coordinated "
        "space and the endgame\")")
    weak_min_voxels: int = Field(default=25, ge=1)
    unexplored_unknown_m: float = Field(
        default=0.5, ge=0, description="an F_u region is worth visiting only this close (xy) to "
        "unknown space on the merged grid; edges of what a camera can ever see are not")
    floor_rim_z_m: float | None = Field(
        default=None, description="F_u regions whose mean height is at most this are kept "
        "however far from unknown grid cells: the unseen floor inside rooms the grid already "
        "calls free (None: every F_u region must be near unknown space)")
    frontier_z_max_m: float = Field(default=1.5, description="voxels above are never frontiers")
    floor_unseen_min_m2: float = Field(
        default=1.0, ge=0, description="`space`: free grid cells with no returned floor "
        "nearby, in patches of at least this area, are F_u regions too (0 = off; "
        "unseen_floor.py; docs/edge.md \"Floor the cameras never returned\")")
    floor_unseen_when: Literal["always", "endgame"] = Field(
        default="endgame", description="unseen floor patches compete with the other regions "
        "always, or only once the assignable F_u regions are down to "
        "complete_unexplored_fraction of the map (none left included)")
    floor_endgame_grid_frontiers: bool = Field(
        default=True, description="... and in that endgame the grid's frontier clusters of "
        "space_grid_fallback_min_cells or more join them too")
    floor_z_m: float = Field(default=0.1, description="voxels whose centre is at most this "
                             "high are floor returns")
    floor_seen_radius_m: float = Field(default=0.1, ge=0, description="a cell this close to a "
                                       "floor return counts as seen")
    floor_seen_window_m: float = Field(default=0.5, ge=0, description="... and a free cell "
                                       "is seen when enough of this window around it is")
    floor_seen_min_fraction: float = Field(default=0.5, ge=0, le=1, description="the "
                                           "fraction of the window's free cells that must be "
                                           "seen")
    floor_unseen_erode_m: float = Field(default=0.1, ge=0, description="unseen floor slivers "
                                        "narrower than twice this are dropped")
    goal_max_offset_3d_m: float = Field(default=1.5, ge=0, description="f′ offset for 3D regions")
    # importance and revenue
    importance_lambda: float = Field(default=0.005, gt=0, description="λ, 1/s")
    importance_xi_s: float = Field(default=-400.0, description="ξ, s")
    revenue_kappa: float = Field(default=1.0, gt=0, description="κ, 1/m")
    revenue_min_path_m: float = Field(default=0.5, gt=0, description="h floor, m")
    # coordinated space (coordination.py; docs/edge.md, "Coordinated space and the endgame")
    space_view_radius_m: float = Field(
        default=1.5, ge=0, description="regions this close to f′ are seen from it; a teammate's "
        "goal this close discounts them")
    space_teammate_discount: float = Field(default=0.25, ge=0, le=1)
    space_teammate_radius_m: float = Field(
        default=0.0, ge=0, description="regions this close to a teammate's goal are discounted "
        "(0: space_view_radius_m)")
    space_joint: bool = Field(default=True, description="assignment problem instead of greedy")
    space_size_exponent: float = Field(
        default=0.5, ge=0, le=1, description="`space`: an F_u region's information also grows as "
        "(its voxels / unexplored_min_voxels)^this, so a large region outbids a speck at the "
        "same distance; 0: I_t·I_g alone, whatever the size")
    space_size_ref_voxels: int = Field(
        default=200, ge=0, description="`space` with space_size_exponent: the size factor is "
        "max(1, voxels / this)^exponent, so regions up to this size keep their information; "
        "0: unexplored_min_voxels")
    space_size_from_fraction: float = Field(
        default=0.01, gt=0, le=1, description="`space` with space_size_exponent: the size "
        "factor applies once the assignable F_u voxels are at most this fraction of the "
        "merged map (late in a mission, when a large region left far away would be the last "
        "trip); 1: always")
    space_partition_discount: float = Field(
        default=1.0, gt=0, le=1, description="`space`: a goal nearer (straight line) to a "
        "teammate or a teammate's goal than to the robot counts this much (each robot's "
        "Voronoi cell of the team in full); 1: no partition")
    space_grid_gain_per_m: float = Field(
        default=0.0, ge=0, description="`space`: a goal is also worth this per metre of 2D "
        "grid frontier within space_grid_view_m of it (the unknown floor it looks into), so "
        "the team spreads out before it cleans up; 0: 3D regions only")
    space_time_exponent: float = Field(
        default=1.0, gt=0, le=2, description="`space`: a goal's view information is divided "
        "by its travel time to this power; under 1 a farther goal that sees more gains on a "
        "near one that sees little (1: information per second)")
    space_view_gain_per_m2: float = Field(
        default=0.05, ge=0, description="`space`: a goal is also worth this per m² of unknown "
        "floor in line of sight within space_view_range_m of it on the merged grid "
        "(visible_unknown.py: a door to an unmapped room outbids a speck); 0: off")
    space_view_range_m: float = Field(default=3.0, gt=0, description="reach of that view, m")
    space_view_min_frontier_cells: int = Field(
        default=40, ge=1, description="unknown floor counts in that view only where it borders "
        "a grid frontier cluster of this many cells (an unmapped room, not a cabinet's inside)")
    space_grid_goals_min_cells: int = Field(
        default=0, ge=0, description="`space`: 2D grid frontier clusters of at least this many "
        "cells are goals too, worth the unknown floor in sight of them (with "
        "space_view_gain_per_m2) and the regions near them; 0: 3D regions only (the grid "
        "only as the fallback)")
    space_grid_view_m: float = Field(
        default=2.5, gt=0, description="half-side of the square around f′ whose grid frontier "
        "counts, m")
    space_reached_final: bool = Field(
        default=True, description="a reached goal's place is set aside for good (with 100 "
        "ticks, 20-38 of 57-77 reached goals of a house mission went back to a place already "
        "reached: docs/edge.md, \"Coordinated space and the endgame\")")
    space_second_look_m: float = Field(
        default=0.0, ge=0, description="> 0: a reached place is no goal again within this "
        "radius, but the region it looked at may be looked at again from elsewhere (among "
        "shelves one side is not enough); 0: space_reached_final alone")
    space_look_at_region: bool = Field(default=False, description="goals carry the region's "
                                       "centroid: the robot faces it before reporting reached")
    space_view_goals: bool = Field(
        default=False, description="an F_u region too high to be seen from beside it gets "
        "its f′ where the camera sees above it (view_goals.py) and the robot faces it there")
    space_view_quantile: float = Field(default=0.75, ge=0, le=1, description="a region's "
                                       "height for its view: this quantile of its voxels'")
    space_view_margin_m: float = Field(default=0.4, ge=0, description="the view reaches "
                                       "this far above the region's height")
    space_view_min_z_m: float = Field(default=0.0, description="only regions at least this "
                                      "high get a far view")
    space_view_split: bool = Field(
        default=False, description="F_u voxels at or above space_view_min_z_m form regions of "
        "their own, kept only where a far view of them exists")
    camera_height_m: float = Field(default=0.35, gt=0, description="the robots' camera "
                                   "(the mission config copies sim.camera_height_m)")
    camera_half_vfov_deg: float = Field(default=34.0779, gt=0, lt=90, description="vertical "
                                        "half-FoV (copied from sim's hfov, width, height)")
    camera_range_m: float = Field(default=5.0, gt=0, description="copied from sim.range_m")
    space_successor_m: float = Field(
        default=0.0, ge=0, description="a robot this close to its goal (m, straight line) "
        "gets its next goal ahead (Goal.queued, successors.py); 0: it waits for the next plan")
    space_grid_fallback: bool = Field(
        default=True, description="when no 3D frontier region is usable (allowed and "
        "reachable), assign the 2D grid's free/unknown frontiers instead of counting the plan "
        "toward completion: an AWS-house mission ended at 59.7 % 3D coverage with a whole room "
        "unknown on the grid and no F_u region there")
    space_grid_fallback_min_cells: int = Field(
        default=40, ge=1, description="... only grid frontier clusters this long (cells; 40 "
        "= 2 m): an unknown room has a frontier of metres, while the rims a normal completion "
        "leaves are short (every rim taken: missions +18 to +39 %; 2 m: +5 %, docs/edge.md)")
    space_tour: bool = Field(
        default=False, description="`space`: robots needing a goal take the first stop of a "
        "min-max tour over every usable region (tours.py) instead of the revenue's best")
    space_tour_stop_s: float = Field(default=2.0, ge=0, description="seconds a tour counts "
                                     "at each region (stopping, turning to the next)")
    space_tour_sum_weight: float = Field(
        default=1.0, ge=0, description="a tour insertion costs what it adds to the longest "
        "route plus this times what it adds per route (0: pure min-max)")
    space_tour_coarse: int = Field(default=4, ge=1, description="region-to-region times on "
                                   "the grid coarsened by this factor")
    nav_v_mps: float = Field(default=0.5, gt=0, description="the agents' max_v_mps (the "
                             "mission config copies it)")
    nav_omega_radps: float = Field(default=0.7853981633974483, gt=0,
                                   description="the agents' max_omega_radps (copied likewise)")
    # baselines
    utility_gain_scale: float = Field(default=1.0, ge=0, description="explore_lite gain_scale")
    utility_potential_scale: float = Field(default=3.0, ge=0, description="explore_lite "
                                           "potential_scale (per m of path)")
    rrt_iterations: int = Field(default=600, ge=1)
    rrt_step_m: float = Field(default=0.5, gt=0, description="RRT steer step η")
    rrt_keep_tree: bool = Field(
        default=True, description="the tree grows on from the nodes of earlier plans, as "
        "rrt_exploration's global detector (false: a fresh tree each plan, which stopped "
        "finding the last frontiers and ended house missions at 88-95 % 3D)")
    seed: int = Field(default=0, description="mission seed (RRT sampling)")
    # map merger
    merge: bool = Field(default=True, description="pose graph + registration corrections "
                        "(with its registration gates and precheck it lowers the ATE in every "
                        "world and the warehouse's ghosts at 300 s, for 2-3x the edge's CPU; "
                        "docs/edge.md)")
    merge_worker: bool = Field(
        default=True, description="the edge server runs the merger's update in a worker "
        "process beside the rest of its plan (merge_runner.py; the same results)")
    max_registrations: int = Field(default=2, ge=0, description="pair registrations per plan")
    merge_registrations_per_robot: float = Field(
        default=0.34, ge=0, description="... or this many per robot with submaps, where that "
        "is more (a large team needs more: 8 at 24 robots; docs/edge.md, \"Registrations the "
        "merger can trust\")")
    merge_registrations_per_robot_pair: float = Field(
        default=0.087, ge=0, description="... or this many per pair of robots with submaps, "
        "where that is more (24 at 24 robots, 2 up to 6; docs/edge.md, \"Registrations per "
        "update by pairs of robots\")")
    merge_odometry_sigma_m: float = Field(
        default=0.01, gt=0, description="σ x, y of the odometry edge between consecutive submaps")
    merge_odometry_sigma_per_m: float = Field(
        default=0.01, ge=0, description="... plus this per metre between them")
    merge_odometry_sigma_rad: float = Field(
        default=0.003, gt=0, description="σ yaw of the odometry edge between consecutive submaps")
    merge_odometry_sigma_rad_per_rad: float = Field(
        default=0.01, ge=0, description="... plus this per radian turned between them")
    merge_report_sigma_m: float = Field(
        default=0.0, ge=0, description="σ x, y of an absolute prior at every submap's reported "
        "pose (0: none, the chain alone carries the reports)")
    merge_report_sigma_per_m: float = Field(
        default=0.0, ge=0, description="... plus this per metre the robot's chain has run")
    merge_report_sigma_rad: float = Field(default=0.02, gt=0, description="... its σ yaw")
    merge_pcm_tol_m: float = Field(
        default=0.05, gt=0, description="PCM: two registrations agree when the loop they close "
        "through both robots' reported chains is within this ...")
    merge_pcm_tol_m_per_m: float = Field(
        default=0.005, ge=0, description="... plus this per metre the loop spans")
    merge_pcm_tol_rad: float = Field(default=0.02, gt=0, description="PCM loop rotation ...")
    merge_pcm_tol_rad_per_m: float = Field(
        default=0.005, ge=0, description="... plus this per metre the loop spans")
    merge_pcm_min_clique: int = Field(
        default=2, ge=1, description="PCM: a robot pair's registrations are used once this many "
        "agree (1: a lone registration is trusted)")
    merge_registration_sigma_m: float = Field(
        default=0.05, gt=0, description="a registration edge's information is scaled to this "
        "mean translational σ (its shape is the registration's Hessian)")
    merge_precheck_m: float = Field(
        default=0.25, ge=0, description="> 0: a candidate pair is registered only when this "
        "share of the source's points lie within this of the target's at the current estimate "
        "(merge_precheck_frac); the others are set aside without costing a registration")
    merge_precheck_frac: float = Field(default=0.4, ge=0, le=1, description="... this share")
    merge_max_shift_m: float = Field(
        default=0.25, gt=0, description="a registration that moves the pair's estimate further "
        "is rejected (repeating shelves alias by their spacing, 40 cm in the bookstore)")
    merge_max_mean_error: float = Field(
        default=0.015, ge=0, description="a registration whose GICP residual per inlier "
        "is above this is rejected (0: no test)")
    merge_max_condition: float = Field(
        default=20.0, ge=0, description="a registration whose planar translation "
        "information is this much weaker in one direction than the other is rejected (0: no "
        "test)")
    # the two faces of a partition laid on each other: AWS house, seed 3 (size exponent
    # 0.25): six robot 0 / robot 2 registrations 10.5-11.4 cm off, back to back 0.04-0.68,
    # every right one of 144 in two missions at most 0.07 (docs/edge.md, "Two faces")
    merge_max_opposed_frac: float = Field(
        default=0.15, ge=0, le=1, description="a registration whose flat point pairs are "
        "back to back (normals turned toward each submap's camera) more often than this "
        "share has matched the two faces of a thin wall, and is rejected (1: no test)")
    merge_agent_frame: bool = Field(
        default=False, description="odometry edges and PCM's chains from the submap poses in "
        "each agent's own frame (Submap.T_odom_submap), which corrections never move, instead "
        "of the reported world poses, which step wherever a correction reached the agent "
        "between two reports")
    merge_own_loop_gap: int = Field(
        default=0, ge=0, description="> 0: a robot's own submaps this many or more apart (same "
        "epoch) are candidate pairs too, loop closures within its chain, judged like any "
        "registration; 0: pairs of different robots only")
    # assignment
    keep_radius_m: float = Field(
        default=0.5, ge=0, description="hysteresis: a goal is kept while a frontier lies this close"
    )
    keep_by_anchor: bool = Field(
        default=False, description="a goal whose region has the same anchor cell as before is "
        "kept, even where an F_w region drawn over it took its cells on the label grid (the "
        "window search alone re-issued one far view every plan: docs/edge.md, \"Far views\")")
    retarget_goals: bool = Field(
        default=False, description="a kept region whose goal cell the robot can no longer reach "
        "(an obstacle seen next to it) but whose new f′ it can: the robot keeps the region and "
        "gets the new f′, instead of a new assignment (a third of the goals dropped in an "
        "AWS-house replay)")
    blacklist_radius_m: float = Field(default=0.5, ge=0)
    blacklist_ticks: int = Field(
        default=300, ge=0, description="how long invalid/unreachable goals are set aside, ticks"
    )
    reached_blacklist_ticks: int = Field(
        default=100, ge=0, description="how long a reached goal's spot is set aside, ticks"
    )
    weak_visited_ticks: int = Field(
        default=100000, ge=0, description="a reached F_w spot: revisiting would not improve it"
    )
    blacklist_strikes: int = Field(
        default=3, ge=1, description="the n-th invalid/unreachable/reached report at one place "
        "sets it aside for good (a frontier that survives repeated visits cannot be cleared)")
    weak_visit_range_m: float = Field(
        default=2.0, ge=0, description="an F_w region inside a robot's FoV this close has been "
        "looked at from close by and is no longer assignable (completion.py)")
    weak_visit_fov_deg: float = Field(default=84.1, gt=0, le=360, description="camera FoV")
    # completion
    complete_after_plans: int = Field(
        default=3, ge=1, description="consecutive plans without a reachable frontier"
    )
    complete_warmup_s: float = Field(default=3.0, ge=0, description="never complete before, sim s")
    complete_min_known_cells: int = Field(default=400, ge=0, description="map must be this big")
    complete_unexplored_fraction: float = Field(
        default=0.0005, ge=0, lt=1, description="`space` also completes when the assignable "
        "F_u regions hold at most this fraction of the merged map's voxels for "
        "complete_unexplored_plans plans in a row (the tail: specks that add little "
        "coverage; docs/edge.md, 'The tail'); 0 = only when no frontier is assignable")
    space_tail_fraction: float = Field(
        default=0.002, ge=0, lt=1, description="`space` with space_tail_min_voxels: the tail "
        "begins when the assignable F_u regions hold at most this fraction of the merged map")
    space_tail_min_voxels: int = Field(
        default=50, ge=0, description="`space`: in the tail, F_u regions smaller than this are "
        "no goal (0 = off; docs/edge.md, \"Specks in the tail\")")
    space_tail_weak: bool = Field(
        default=True, description="`space`: F_w regions stay goals in the tail (False: once "
        "the tail begins only F_u regions are, and robots finish what completion waits for)")
    complete_unexplored_plans: int = Field(
        default=6, ge=1, description="consecutive plans under complete_unexplored_fraction")
