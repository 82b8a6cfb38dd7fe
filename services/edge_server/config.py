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
