"""Robot agent section of the mission config."""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field


class AgentConfig(BaseModel):
    """Mapping, localization and navigation of one robot."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    drf: bool = Field(default=True, description="mutual awareness + Dynamic Robot Filter")
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
    # -- local 2D grid ---------------------------------------------------------------------
    cell_m: float = Field(default=0.05, gt=0, description="2D grid and free-cell size")
    grid_half_size_m: float = Field(default=25.0, gt=0, description="local grid ± around spawn")
    obstacle_z_min_m: float = Field(default=0.05, description="points above this are obstacles")
    obstacle_z_max_m: float = Field(default=0.6, description="... and below this (robot + margin)")
    # -- navigation ------------------------------------------------------------------------
    robot_radius_m: float = Field(default=0.18, gt=0)
    inflation_margin_m: float = Field(default=0.05, ge=0)
    plan_through_unknown: bool = True
    goal_tolerance_m: float = Field(default=0.35, gt=0)
    goal_snap_m: float = Field(default=0.6, ge=0, description="snap a blocked goal this far")
    replan_every_ticks: int = Field(default=20, ge=1)
    lookahead_m: float = Field(default=0.4, gt=0)
    turn_in_place_rad: float = Field(
        default=0.7, gt=0, description="heading error above which the robot turns in place"
    )
    k_omega: float = Field(default=1.5, gt=0, description="turn-in-place gain, 1/s")
    spin_omega_radps: float = Field(default=0.4, ge=0, description="rotation while idle")
    stuck_ticks: int = Field(default=80, ge=1, description="no progress this long → invalid")
    progress_m: float = Field(default=0.1, gt=0)
    time_budget_factor: float = Field(default=3.0, gt=0)
    time_budget_slack_s: float = Field(default=10.0, ge=0)
