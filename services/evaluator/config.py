"""Evaluator parameters: one frozen config for the ground truth and the metrics."""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field


class EvalConfig(BaseModel):
    """Ground-truth and metric parameters (SPEC §5); defaults follow the paper's robot/camera."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    resolution_m: float = Field(default=0.05, gt=0, description="2D truth cell size")
    robot_radius_m: float = Field(
        default=0.17, gt=0, description="clearance of the robot centre (Waffle half-width + margin)"
    )
    band_z_m: tuple[float, float] = Field(
        default=(0.03, 0.40), description="robot height band: obstacles intersecting it block"
    )
    density_per_m2: float = Field(default=1000.0, gt=0, description="surface samples per m²")
    camera_height_m: float = Field(default=0.35, gt=0)
    range_m: float = Field(default=5.0, gt=0, description="camera max range γ")
    max_elevation_deg: float | None = Field(
        default=math.degrees(math.atan(math.tan(math.radians(84.1 / 2)) * 3 / 4)),
        description="half the vertical FoV of a level 4:3 camera; None = any direction",
    )
    max_incidence_deg: float | None = Field(
        default=None, gt=0, le=90, description="the camera returns nothing where a ray meets "
        "a surface further than this off its normal (the simulator's depth_max_incidence_deg):"
        " the observable truth keeps only what some viewpoint sees within it; None = no limit"
    )
    viewpoint_spacing_m: float = Field(default=0.25, gt=0, description="lattice of camera spots")
    visibility_rounds: int = Field(default=24, ge=1, description="random viewpoints tried/sample")
    coverage_radius_m: float = Field(default=0.10, gt=0)
    voxel_m: float = Field(default=0.05, gt=0, description="bounding-volume voxel")
    ghost_dist_m: float = Field(default=0.10, gt=0)
    seed: int = 0
