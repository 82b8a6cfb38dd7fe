"""Edge server section of the mission config."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class EdgeConfig(BaseModel):
    """Merging, frontiers and assignment."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    planner: Literal["space", "nearest", "utility", "rrt"] = "space"
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
    # assignment
    keep_radius_m: float = Field(
        default=0.5, ge=0, description="hysteresis: a goal is kept while a frontier lies this close"
    )
    blacklist_radius_m: float = Field(default=0.5, ge=0)
    blacklist_ticks: int = Field(
        default=300, ge=0, description="how long invalid/unreachable goals are set aside, ticks"
    )
    reached_blacklist_ticks: int = Field(
        default=100, ge=0, description="how long a reached goal's spot is set aside, ticks"
    )
    # completion
    complete_after_plans: int = Field(
        default=3, ge=1, description="consecutive plans without a reachable frontier"
    )
    complete_warmup_s: float = Field(default=3.0, ge=0, description="never complete before, sim s")
    complete_min_known_cells: int = Field(default=400, ge=0, description="map must be this big")
