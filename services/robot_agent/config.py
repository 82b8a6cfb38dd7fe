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
