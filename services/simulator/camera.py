"""RGB-D camera: MuJoCo offscreen GL on the CPU, or ray casting when no GL context exists.

Output: RGB uint8 (H, W, 3), row 0 at the top; depth float32 z-depth in metres along the
optical axis, 0 where there is no return, the return is beyond `range_m` or the sensor model
drops it (grazing incidence, depth edges: sensor_model.py), with its noise. Frames: the
optical frame `cam` is x right, y down, z forward; MuJoCo's camera frame looks along −z with
+y up. Segmentation (geom id per pixel) is for the evaluator only and is never published on
agent-visible keys. A GL context is bound to the thread that created the camera.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

import mujoco
import numpy as np

from services.simulator.robots import RobotIds, T_base_cammj
from services.simulator.sensor_model import PRESETS, SensorModel, apply_depth_model
from services.simulator.worlds import ROBOT_GROUP, SENSED_GROUPS

log = logging.getLogger(__name__)

NEAR_PLANE_M = 0.01  # nothing closer than ~5 cm may be clipped
# Planes are drawn as a grid of quads this far apart (render only): an infinite plane with a
# 5 cm grid (the AWS floor) cost 4 ms of a 160×120 frame; 2 m costs nothing.
PLANE_GRID_M = 2.0
PLANE_GRID_CELLS = 20  # at most this many grid quads along a plane made finite
T_CAMMJ_CAM = np.diag([1.0, -1.0, -1.0, 1.0])  # optical frame in MuJoCo's camera frame
GEOMGROUP = np.array([1 if g in SENSED_GROUPS else 0 for g in range(6)], dtype=np.uint8)


def sensed_groups(robots_visible: bool = True) -> np.ndarray:
    """MuJoCo geom-group mask of what the camera sees (robots hidden: an ablation only)."""
    mask = GEOMGROUP.copy()
    mask[ROBOT_GROUP] = 1 if robots_visible else 0
    return mask

Backend = Literal["auto", "gl", "raycast"]


def intrinsics(width: int, height: int, fovy_deg: float) -> np.ndarray:
    """3×3 pinhole K of a MuJoCo camera (square pixels, pixel centres at integers)."""
    f = (height / 2) / math.tan(math.radians(fovy_deg) / 2)
    return np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])


def T_base_cam(model: mujoco.MjModel, ids: RobotIds) -> np.ndarray:
    """4×4 extrinsics: optical camera frame → robot base frame."""
    return T_base_cammj(model, ids) @ T_CAMMJ_CAM


def prepare_for_rendering(model: mujoco.MjModel, width: int, height: int) -> None:
    """Cheap CPU rendering settings (field notes): no MSAA, near plane at NEAR_PLANE_M, coarse
    plane grids."""
    model.vis.quality.offsamples = 0
    planes = model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE
    model.geom_size[planes, 2] = np.maximum(model.geom_size[planes, 2], PLANE_GRID_M)
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    model.vis.map.znear = NEAR_PLANE_M / model.stat.extent


@contextlib.contextmanager
def finite_planes(model: mujoco.MjModel, range_m: float) -> Iterator[None]:
    """Infinite planes (size 0) made finite while a GL context is made, then restored.

    MuJoCo draws an infinite plane as a fine grid out to the far clip: in the AWS house
    (one infinite floor) that was 2.0 of a 2.4 ms 160×120 frame. The context bakes each
    plane's drawing when it is made, so a plane that reaches every point of the world plus
    the camera's range renders the same floor within range at a sixth of the cost; the model
    keeps its infinite plane for physics and rays."""
    planes = np.nonzero(model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)[0]
    infinite = planes[(model.geom_size[planes, 0] <= 0) | (model.geom_size[planes, 1] <= 0)]
    saved = model.geom_size[infinite].copy()
    centre = np.asarray(model.stat.center)
    for g in infinite.tolist():
        reach = float(np.linalg.norm(centre - model.geom_pos[g])) + model.stat.extent + range_m
        model.geom_size[g, :2] = reach
        model.geom_size[g, 2] = max(model.geom_size[g, 2], 2 * reach / PLANE_GRID_CELLS)
    try:
        yield
    finally:
        model.geom_size[infinite] = saved


def _make_gl_context(width: int, height: int) -> object:
    """An offscreen context of the backend MUJOCO_GL names, else EGL, else OSMesa.

    Chosen here rather than through mujoco.gl_context, which fixes its choice when MuJoCo is
    first imported (possibly before the simulator package set MUJOCO_GL).
    """
    wanted = os.environ.get("MUJOCO_GL", "").lower()
    names = [wanted] if wanted in ("egl", "osmesa", "glfw") else ["egl", "osmesa"]
    errors = []
    for name in names:
        try:
            module = importlib.import_module(f"mujoco.{name}")
            context = module.GLContext(width, height)
            context.make_current()
            return context
        except Exception as exc:  # missing library, no device, wrong PyOpenGL platform
            errors.append(f"{name}: {exc}")
    raise RuntimeError("; ".join(errors))


@dataclass(frozen=True)
class RgbdImage:
    rgb: np.ndarray  # (H, W, 3) uint8
    depth_m: np.ndarray  # (H, W) float32, 0 = no return
    segmentation: np.ndarray | None = None  # (H, W) int32 geom id, -1 = none; evaluator only


class RgbdCamera:
    """Renders any robot's camera of one model; `backend` says which path is in use."""

    def __init__(
        self,
        model: mujoco.MjModel,
        width: int,
        height: int,
        range_m: float,
        sensors: SensorModel = PRESETS["ideal"],
        backend: Backend = "auto",
        robots_visible: bool = True,
    ) -> None:
        self.model = model
        self._geomgroup = sensed_groups(robots_visible)
        self.width, self.height = width, height
        self.range_m = range_m
        self.sensors = sensors
        self.K = intrinsics(width, height, self._fovy())
        prepare_for_rendering(model, width, height)
        self._gl = None
        self.backend: str = "raycast"
        if backend in ("auto", "gl"):
            try:
                self._init_gl()
                self.backend = "gl"
            except Exception as exc:  # any GL failure → ray casting, unless GL was demanded
                if backend == "gl":
                    raise
                log.warning("no GL context (%s): camera falls back to mj_multiRay", exc)
        if self.backend == "raycast":
            self._init_raycast()
        log.info(
            "camera backend %s (%s) at %dx%d", self.backend,
            os.environ.get("MUJOCO_GL", "egl") if self.backend == "gl" else "mj_multiRay",
            width, height,
        )

    # -- GL ----------------------------------------------------------------------------------
    def _init_gl(self) -> None:
        self._gl = _make_gl_context(self.width, self.height)
        self._gl.make_current()
        with finite_planes(self.model, self.range_m):
            self._ctx = mujoco.MjrContext(self.model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._ctx)
        self._ctx.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(self.model, maxgeom=20000)
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        self._scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        self._opt = mujoco.MjvOption()
        self._opt.geomgroup[:] = self._geomgroup
        self._cam = mujoco.MjvCamera()
        self._cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._rect = mujoco.MjrRect(0, 0, self.width, self.height)
        self._rgb = np.empty((self.height, self.width, 3), np.uint8)
        self._zbuf = np.empty((self.height, self.width), np.float32)
        extent = self.model.stat.extent
        near = np.float32(self.model.vis.map.znear * extent)
        far = np.float32(self.model.vis.map.zfar * extent)
        # Inverse of the GL projection for a ZEROFAR depth map (as mujoco.Renderer does).
        self._c = np.float32(0.5 * (far + near) / (far - near) - 0.5)
        self._d = np.float32(far * near / (far - near))

    def _render_gl(self, data: mujoco.MjData, ids: RobotIds, segment: bool) -> RgbdImage:
        self._gl.make_current()
        self._cam.fixedcamid = ids.camera
        mujoco.mjv_updateScene(
            self.model, data, self._opt, None, self._cam, mujoco.mjtCatBit.mjCAT_ALL.value,
            self._scene,
        )
        mujoco.mjr_render(self._rect, self._scene, self._ctx)
        mujoco.mjr_readPixels(self._rgb, self._zbuf, self._rect, self._ctx)
        rgb = np.flipud(self._rgb).copy()
        depth = self._d / (np.flipud(self._zbuf) + self._c)
        return RgbdImage(rgb, depth, self._segment_gl() if segment else None)

    def _segment_gl(self) -> np.ndarray:
        """Geom id per pixel from a second pass with ID colours (same scene)."""
        flags = self._scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
        flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
        try:
            mujoco.mjr_render(self._rect, self._scene, self._ctx)
            mujoco.mjr_readPixels(self._rgb, None, self._rect, self._ctx)
        finally:
            flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = False
            flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = False
        img = np.flipud(self._rgb).astype(np.int32)
        segid = img[..., 0] + (img[..., 1] << 8) + (img[..., 2] << 16)
        lut = np.full(self._scene.ngeom + 1, -1, np.int32)  # segid 0 = background
        for g in self._scene.geoms[: self._scene.ngeom]:
            if g.segid != -1 and g.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                lut[g.segid + 1] = g.objid
        return lut[np.clip(segid, 0, len(lut) - 1)]

    # -- ray casting -------------------------------------------------------------------------
    def _init_raycast(self) -> None:
        K = self.K
        v, u = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        # Directions in MuJoCo's camera frame with z = −1: the hit distance is the z-depth.
        self._dirs_cammj = np.stack(
            [(u - K[0, 2]) / K[0, 0], -(v - K[1, 2]) / K[1, 1], -np.ones_like(u)], axis=-1
        ).reshape(-1, 3)
        n = len(self._dirs_cammj)
        self._geomid = np.empty(n, np.int32)
        self._dist = np.empty(n, np.float64)
        self._normal = np.empty(3 * n, np.float64)
        self._cutoff = self.range_m * float(np.linalg.norm(self._dirs_cammj, axis=1).max()) + 1

    def _fovy(self) -> float:
        return float(self.model.cam_fovy[0]) if self.model.ncam else 45.0

    def _render_raycast(self, data: mujoco.MjData, ids: RobotIds) -> RgbdImage:
        R_world_cammj = data.cam_xmat[ids.camera].reshape(3, 3)
        dirs_world = self._dirs_cammj @ R_world_cammj.T
        mujoco.mj_multiRay(
            self.model, data, data.cam_xpos[ids.camera].copy(), dirs_world.ravel(), self._geomgroup,
            1, ids.body, self._geomid, self._dist, self._normal, len(dirs_world), self._cutoff,
        )
        hit = self._geomid >= 0
        depth = np.where(hit, self._dist, 0.0).astype(np.float32)
        # Flat colour of the hit geom, shaded by the incidence angle so edges read in RGB.
        normals = self._normal.reshape(-1, 3)
        unit = dirs_world / np.linalg.norm(dirs_world, axis=1, keepdims=True)
        shade = 0.4 + 0.6 * np.abs(np.einsum("ij,ij->i", normals, unit))
        rgba = self.model.geom_rgba[np.where(hit, self._geomid, 0)]
        rgb = np.where(hit[:, None], rgba[:, :3] * shade[:, None] * 255, 0).astype(np.uint8)
        shape = (self.height, self.width)
        return RgbdImage(
            rgb.reshape(*shape, 3), depth.reshape(shape), self._geomid.reshape(shape).copy()
        )

    # -- public ------------------------------------------------------------------------------
    def render(
        self,
        data: mujoco.MjData,
        ids: RobotIds,
        rng: np.random.Generator | None = None,
        segmentation: bool = False,
    ) -> RgbdImage:
        """One frame of robot `ids`'s camera; `data` must be forwarded (mj_forward/mj_step)."""
        if self.backend == "gl":
            img = self._render_gl(data, ids, segmentation)
        else:
            img = self._render_raycast(data, ids)
            if not segmentation:
                img = RgbdImage(img.rgb, img.depth_m)
        depth = apply_depth_model(img.depth_m, self.K, self.sensors, self.range_m, rng)
        return RgbdImage(img.rgb, depth, img.segmentation)

    def close(self) -> None:
        if self._gl is not None:
            self._gl.make_current()
            self._ctx.free()
            self._gl.free()
            self._gl = None
