"""Simulator section of the mission config."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

SensorPreset = Literal["realistic", "ideal"]


class SimConfig(BaseModel):
    """World, robots, sensors and clock."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    world: str = Field(default="house", description="registered world name or MJCF path")
    robots: int = Field(default=3, ge=1, le=64)
    seed: int = 0
    spawn: list[tuple[float, float, float]] | None = Field(
        default=None, description="(x m, y m, yaw rad) per robot; None = the world's defaults"
    )
    tick_s: float = Field(default=0.1, gt=0, description="control period = one lockstep tick")
    physics_dt_s: float = Field(
        default=0.005, gt=0, le=0.01,
        description="MuJoCo timestep, whatever the world file says (≤ contact time constant / 2)",
    )
    camera_every_ticks: int = Field(default=2, ge=1)
    edge_every_ticks: int = Field(default=10, ge=1, description="edge planning period, ticks")
    edge_pipeline_ticks: int | None = Field(
        default=0, ge=0, description="lockstep pipelining L: the edge's plan for edge tick "
        "k is waited for at tick k + L and its outputs apply from tick k + L + 1, so the plan "
        "runs while the fleet goes on (0 = the fleet waits at tick k); < edge_every_ticks; "
        "None = edge_every_ticks - 1, the most overlap; 0 by default: +5 % real-time factor "
        "measured, and goals that arrive L ticks later lengthen each wait for a next goal"
    )
    width: int = Field(default=160, ge=16, le=640)
    height: int = Field(default=120, ge=12, le=480)
    hfov_deg: float = Field(default=84.1, gt=0, lt=180)
    range_m: float = Field(default=5.0, gt=0)
    camera_height_m: float = Field(default=0.35, gt=0)
    max_v_mps: float = Field(default=0.5, gt=0)
    max_omega_radps: float = Field(default=math.pi / 4, gt=0)
    realtime: float | None = Field(default=None, gt=0, description="None = lockstep")
    max_sim_time_s: float = Field(default=600.0, gt=0)
    wait_for_peers_s: float = Field(default=120.0, gt=0)
    # Sensor and odometry models (spacemap additions). The random terms default to None =
    # "take the value of the preset `sensors`" (sensor_model.sensor_model resolves them), so an
    # explicit value wins over either preset and `sensors` can still be switched afterwards.
    sensors: SensorPreset = Field(
        default="realistic", description="realistic = Kinect v2-like depth and drifting "
        "odometry with random walks; ideal = every random term and invalid return off"
    )
    depth_noise_per_m2: float | None = Field(
        default=None, ge=0, description="depth noise std = this × depth², metres (realistic "
        "0.0005, Kinect v2-like: ~1 mm at 1.5 m, ~1 cm at 4.5 m; ideal 0)"
    )
    depth_max_incidence_deg: float | None = Field(
        default=None, gt=0, le=90, description="no return where the angle between the ray "
        "and the surface normal exceeds this (realistic 80; 90 = off)"
    )
    depth_edge_rel_jump: float | None = Field(
        default=None, ge=0, description="no return on the far side of a depth jump larger "
        "than this fraction of the depth between neighbour pixels (realistic 0.1; 0 = off)"
    )
    render_backend: Literal["auto", "gl", "raycast"] = Field(
        default="auto", description="auto = offscreen GL, ray casting when no GL context"
    )
    robots_visible: bool = Field(
        default=True, description="False: cameras do not see robots at all (an ablation: the "
        "map a perfect Dynamic Robot Filter would allow; never a mission setting)"
    )
    odom_scale_error: float = Field(default=0.02, description="relative distance error")
    odom_yaw_scale_error: float = Field(default=0.01, description="relative turn error")
    odom_heading_bias_rad_per_m: float = Field(default=0.005, description="yaw drift per metre")
    odom_error_spread: float = Field(
        default=0.0, ge=0, le=1, description="robots' wheels differ: each robot's scale, turn "
        "scale and heading bias are the fleet's above times (1 + this × a seeded standard "
        "normal draw of its own; 0 = every robot the same wheels)"
    )
    odom_noise_m_per_sqrt_m: float | None = Field(
        default=None, ge=0, description="random-walk translation noise, seeded (realistic 0.01)"
    )
    odom_noise_rad_per_sqrt_rad: float | None = Field(
        default=None, ge=0, description="random-walk rotation noise, seeded (realistic 0.01)"
    )

    @model_validator(mode="after")
    def _one_plan_in_flight(self) -> SimConfig:
        # With L ≥ edge_every_ticks the clock would publish the next edge tick before the
        # completion verdict of the previous one is due, so the edge could plan past the stop
        # tick and the final map would depend on when the launcher halts the simulator.
        if self.edge_pipeline_ticks is not None and \
                self.edge_pipeline_ticks >= self.edge_every_ticks:
            raise ValueError("edge_pipeline_ticks must be < edge_every_ticks")
        return self

    @property
    def edge_lag_ticks(self) -> int:
        """L: ticks between an edge tick and the one its answer is due at, which the agents
        hold the edge's outputs for; none in real time, where nothing waits and outputs are
        used as soon as they arrive."""
        if self.realtime is not None:
            return 0
        if self.edge_pipeline_ticks is None:
            return self.edge_every_ticks - 1
        return self.edge_pipeline_ticks
