"""The simulation core: world + robots + cameras + odometry, stepped one tick at a time.

No bus, no wall clock, no global RNG: every random draw comes from generators seeded by
`SimConfig.seed`, so the same config and the same commands give the same trajectories,
odometry and images.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import mujoco
import numpy as np

from services.simulator.camera import RgbdCamera, RgbdImage, T_base_cam, intrinsics
from services.simulator.config import SimConfig
from services.simulator.odometry import OdometryNoise, WheelOdometry
from services.simulator.robots import (
    RobotIds,
    add_robots,
    robot_ids,
    vertical_fov_deg,
    world_pose,
)
from services.simulator.sensor_model import sensor_model
from services.simulator.worlds import Pose, load_world, spawn_poses

log = logging.getLogger(__name__)

CONTROL_PERIOD_S = 0.01  # body → world velocity conversion is refreshed this often


@dataclass(frozen=True)
class WorldModel:
    """A compiled world with its robots: what the simulator runs and the evaluator measures."""

    model: mujoco.MjModel
    spawns: list[Pose]
    robots: list[RobotIds]


def build_spec(cfg: SimConfig) -> tuple[mujoco.MjSpec, list[Pose]]:
    """World of `cfg.world` with `cfg.robots` robots at their spawn poses (not compiled)."""
    spec = load_world(cfg.world)
    spec.option.timestep = cfg.physics_dt_s  # planar robots need no finer step; 2.5× cheaper
    spawns = spawn_poses(cfg.world, cfg.robots, cfg.spawn)
    add_robots(
        spec, spawns, cfg.camera_height_m, vertical_fov_deg(cfg.hfov_deg, cfg.width, cfg.height)
    )
    return spec, spawns


def build_model(cfg: SimConfig) -> WorldModel:
    spec, spawns = build_spec(cfg)
    model = spec.compile()
    return WorldModel(model, spawns, [robot_ids(model, i) for i in range(len(spawns))])


def odometry_noise(cfg: SimConfig, robot: int = 0) -> OdometryNoise:
    """Robot `robot`'s wheels: the fleet's systematic errors, each scaled by its own seeded
    draw when `odom_error_spread` > 0 (no draw otherwise: missions stay as they were)."""
    sensors = sensor_model(cfg)
    k = np.ones(3)
    if cfg.odom_error_spread > 0:
        k += cfg.odom_error_spread * np.random.default_rng([cfg.seed, 3, robot]).standard_normal(3)
    return OdometryNoise(
        scale_error=cfg.odom_scale_error * float(k[0]),
        yaw_scale_error=cfg.odom_yaw_scale_error * float(k[1]),
        heading_bias_rad_per_m=cfg.odom_heading_bias_rad_per_m * float(k[2]),
        noise_m_per_sqrt_m=sensors.odom_noise_m_per_sqrt_m,
        noise_rad_per_sqrt_rad=sensors.odom_noise_rad_per_sqrt_rad,
    )


@dataclass(frozen=True)
class OdometryReading:
    pose: Pose
    v_mps: float
    omega_radps: float


class Simulation:
    """Robots in a world, advanced by `step`; sensors read the current state."""

    def __init__(self, cfg: SimConfig) -> None:
        self.cfg = cfg
        self.sensors = sensor_model(cfg)
        log.info("sensors %s: %s", cfg.sensors, self.sensors)
        world = build_model(cfg)
        self.model, self.spawns, self.robots = world.model, world.spawns, world.robots
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        self.tick = 0
        self.substeps = max(1, round(cfg.tick_s / self.model.opt.timestep))
        self._control_every = max(1, round(CONTROL_PERIOD_S / self.model.opt.timestep))
        self._bodies = np.array([r.body for r in self.robots])
        self._act = np.array([r.actuators for r in self.robots])  # (N, 3): x, y, yaw
        self._cmd = np.zeros((len(self.robots), 2))  # applied (v, ω) per robot
        self._odom = [
            WheelOdometry(spawn, odometry_noise(cfg, i), np.random.default_rng([cfg.seed, 2, i]))
            for i, spawn in enumerate(self.spawns)
        ]
        self._odom_readings = [OdometryReading(s, 0.0, 0.0) for s in self.spawns]
        self._depth_rng = np.random.default_rng([cfg.seed, 1])
        self._camera: RgbdCamera | None = None
        self.fovy_deg = vertical_fov_deg(cfg.hfov_deg, cfg.width, cfg.height)
        self.K = intrinsics(cfg.width, cfg.height, self.fovy_deg)

    @property
    def n_robots(self) -> int:
        return len(self.robots)

    @property
    def stamp_ns(self) -> int:
        return self.tick * round(self.cfg.tick_s * 1e9)

    # -- dynamics ----------------------------------------------------------------------------
    def step(self, commands: Mapping[int, tuple[float, float]]) -> None:
        """Apply body-frame (v, ω) per robot (absent = stop) and integrate one tick."""
        self._cmd[:] = 0.0
        for i, (v, omega) in commands.items():
            self._cmd[i] = (v, omega)
        self._cmd[:, 0] = np.clip(self._cmd[:, 0], -self.cfg.max_v_mps, self.cfg.max_v_mps)
        self._cmd[:, 1] = np.clip(
            self._cmd[:, 1], -self.cfg.max_omega_radps, self.cfg.max_omega_radps
        )
        done = 0
        while done < self.substeps:
            self._apply_controls()
            n = min(self._control_every, self.substeps - done)
            mujoco.mj_step(self.model, self.data, nstep=n)
            done += n
        mujoco.mj_forward(self.model, self.data)  # sensors see the state at the new stamp
        self.tick += 1
        for i, odom in enumerate(self._odom):
            pose, v, omega = odom.update(self.true_pose(i), self.cfg.tick_s)
            self._odom_readings[i] = OdometryReading(pose, v, omega)

    def _apply_controls(self) -> None:
        q = self.data.xquat[self._bodies]
        yaw = np.arctan2(2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]),
                         1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2))
        self.data.ctrl[self._act[:, 0]] = self._cmd[:, 0] * np.cos(yaw)
        self.data.ctrl[self._act[:, 1]] = self._cmd[:, 0] * np.sin(yaw)
        self.data.ctrl[self._act[:, 2]] = self._cmd[:, 1]

    # -- state and sensors -------------------------------------------------------------------
    def true_pose(self, i: int) -> Pose:
        return world_pose(self.data, self.robots[i])

    def odometry(self, i: int) -> OdometryReading:
        return self._odom_readings[i]

    def T_base_cam(self, i: int) -> np.ndarray:
        return T_base_cam(self.model, self.robots[i])

    @property
    def camera(self) -> RgbdCamera:
        """Created on first use, in the calling thread (a GL context is bound to its thread)."""
        if self._camera is None:
            cfg = self.cfg
            self._camera = RgbdCamera(
                self.model, cfg.width, cfg.height, cfg.range_m, self.sensors,
                cfg.render_backend, cfg.robots_visible,
            )
        return self._camera

    def render(self, i: int, segmentation: bool = False) -> RgbdImage:
        """Robot i's RGB-D frame; `segmentation` (geom ids) is for the evaluator only."""
        return self.camera.render(self.data, self.robots[i], self._depth_rng, segmentation)

    def robot_contacts(self) -> list[tuple[int, int]]:
        """Active contacts that involve a robot geom, as (geom1, geom2) pairs."""
        robot_geoms = {g for r in self.robots for g in r.geoms}
        n = self.data.ncon
        g1, g2 = self.data.contact.geom1[:n], self.data.contact.geom2[:n]
        return [
            (int(a), int(b)) for a, b in zip(g1, g2, strict=True)
            if a in robot_geoms or b in robot_geoms
        ]

    def close(self) -> None:
        if self._camera is not None:
            self._camera.close()
            self._camera = None

