"""TurtleBot3-Waffle-sized robots injected into a world with MjSpec.

Each robot is one body on planar joints (slide x, slide y, hinge z) driven by velocity
actuators, so it stops at walls and at other robots. The slide axes are expressed in the body's
spawn frame so that they point along world x and y whatever the spawn yaw; slide qpos is
therefore relative to the spawn: read world poses from `data.xpos` / `data.xquat`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from services.simulator.worlds import ROBOT_GROUP, Pose

FOOTPRINT_M = (0.281, 0.306)  # TurtleBot3 Waffle, length (x) × width (y)
BODY_TOP_M = 0.2
GROUND_CLEARANCE_M = 0.02  # clears floor-level proxies (rug edges, plinths) of file worlds
MASS_KG = 1.8
CAMERA_X_M = 0.05  # camera ahead of the mast, so no robot geom is in front of the lens
KV_SLIDE = 200.0
KV_YAW = 20.0
ROBOT_RGBA = (0.1, 0.1, 0.12, 1.0)
MAST_RGBA = (0.9, 0.45, 0.05, 1.0)

# Camera axes (MuJoCo: looks along -z, +y up) in the base frame: view +x, up +z.
R_BASE_CAMMJ = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def robot_name(i: int) -> str:
    return f"robot{i}"


def vertical_fov_deg(hfov_deg: float, width: int, height: int) -> float:
    """MuJoCo's `fovy` for a horizontal FoV at this aspect ratio (square pixels)."""
    half = math.radians(hfov_deg) / 2
    return math.degrees(2 * math.atan(math.tan(half) * height / width))


def add_robots(
    spec: mujoco.MjSpec,
    spawns: Sequence[Pose],
    camera_height_m: float,
    fovy_deg: float,
) -> None:
    """Add one robot per spawn pose, with its camera, joints and velocity actuators."""
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST  # stiff kv stays stable
    quat_cam = np.zeros(4)
    mujoco.mju_mat2Quat(quat_cam, R_BASE_CAMMJ.flatten())
    lx, ly = FOOTPRINT_M
    for i, (x, y, yaw) in enumerate(spawns):
        name = robot_name(i)
        body = spec.worldbody.add_body(
            name=name, pos=[x, y, 0.0], quat=[math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)]
        )
        # Explicit inertia: some MJCF files compile with inertiafromgeom="false".
        body.explicitinertial = True
        body.mass = MASS_KG
        body.ipos = [0, 0, BODY_TOP_M / 2]
        body.inertia = [
            MASS_KG / 12 * (ly**2 + BODY_TOP_M**2),
            MASS_KG / 12 * (lx**2 + BODY_TOP_M**2),
            MASS_KG / 12 * (lx**2 + ly**2),
        ]
        c, s = math.cos(yaw), math.sin(yaw)
        # World x / y expressed in the spawn frame of the body.
        for suffix, axis in (("x", [c, -s, 0.0]), ("y", [s, c, 0.0])):
            body.add_joint(name=f"{name}_{suffix}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
        body.add_joint(name=f"{name}_yaw", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
        half_h = (BODY_TOP_M - GROUND_CLEARANCE_M) / 2
        body.add_geom(
            name=f"{name}_chassis", type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[lx / 2, ly / 2, half_h], pos=[0, 0, GROUND_CLEARANCE_M + half_h],
            rgba=list(ROBOT_RGBA), group=ROBOT_GROUP,
        )
        # A mast carrying the camera, behind the lens (x < CAMERA_X_M), visible to teammates.
        mast_top = camera_height_m + 0.03
        body.add_geom(
            name=f"{name}_mast", type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.03, 0.06, (mast_top - BODY_TOP_M) / 2],
            pos=[CAMERA_X_M - 0.045, 0, (mast_top + BODY_TOP_M) / 2],
            rgba=list(MAST_RGBA), group=ROBOT_GROUP,
        )
        body.add_camera(
            name=f"{name}_cam", pos=[CAMERA_X_M, 0, camera_height_m], quat=quat_cam.tolist(),
            fovy=fovy_deg,
        )
        for suffix, kv in (("x", KV_SLIDE), ("y", KV_SLIDE), ("yaw", KV_YAW)):
            act = spec.add_actuator(
                name=f"{name}_{suffix}", target=f"{name}_{suffix}",
                trntype=mujoco.mjtTrn.mjTRN_JOINT,
            )
            act.set_to_velocity(kv=kv)


@dataclass(frozen=True)
class RobotIds:
    """Indices of one robot's elements in a compiled model."""

    body: int
    camera: int
    actuators: tuple[int, int, int]  # x, y, yaw
    geoms: tuple[int, ...]


def robot_ids(model: mujoco.MjModel, i: int) -> RobotIds:
    name = robot_name(i)
    body = model.body(name).id
    return RobotIds(
        body=body,
        camera=model.camera(f"{name}_cam").id,
        actuators=tuple(model.actuator(f"{name}_{s}").id for s in ("x", "y", "yaw")),
        geoms=tuple(int(g) for g in np.flatnonzero(model.geom_bodyid == body)),
    )


def yaw_from_quat(q: np.ndarray) -> float:
    """Yaw about +z of a (w, x, y, z) quaternion."""
    w, x, y, z = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def world_pose(data: mujoco.MjData, ids: RobotIds) -> Pose:
    """True (x, y, yaw) of the robot base in the world frame."""
    x, y, _ = data.xpos[ids.body]
    return float(x), float(y), yaw_from_quat(data.xquat[ids.body])


def set_velocity(
    data: mujoco.MjData, ids: RobotIds, v: float, omega: float, max_v: float, max_omega: float
) -> tuple[float, float]:
    """Command body-frame (v, ω), clipped to the limits; returns the applied pair."""
    v = float(np.clip(v, -max_v, max_v))
    omega = float(np.clip(omega, -max_omega, max_omega))
    yaw = yaw_from_quat(data.xquat[ids.body])
    ax, ay, ayaw = ids.actuators
    data.ctrl[ax] = v * math.cos(yaw)
    data.ctrl[ay] = v * math.sin(yaw)
    data.ctrl[ayaw] = omega
    return v, omega


def T_base_cammj(model: mujoco.MjModel, ids: RobotIds) -> np.ndarray:
    """4×4 pose of the MuJoCo camera frame (−z forward, +y up) in the base frame."""
    T = np.eye(4)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, model.cam_quat[ids.camera])
    T[:3, :3] = R.reshape(3, 3)
    T[:3, 3] = model.cam_pos[ids.camera]
    return T
