"""Synthetic RGB-D frames of box worlds, for tests and benchmarks (no MuJoCo).

Rays are cast analytically against a floor plane (z = 0) and axis-aligned boxes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.geometry import T_from_xyyaw

Box = tuple[float, float, float, float, float, float]  # xmin, xmax, ymin, ymax, zmin, zmax


@dataclass(frozen=True)
class BoxWorld:
    boxes: tuple[Box, ...]

    @staticmethod
    def room(
        x0: float, x1: float, y0: float, y1: float, h: float = 1.0, t: float = 0.1
    ) -> BoxWorld:
        """Four walls of thickness t enclosing [x0, x1] × [y0, y1]."""
        return BoxWorld((
            (x0 - t, x1 + t, y0 - t, y0, 0.0, h), (x0 - t, x1 + t, y1, y1 + t, 0.0, h),
            (x0 - t, x0, y0, y1, 0.0, h), (x1, x1 + t, y0, y1, 0.0, h),
        ))

    def with_box(self, box: Box) -> BoxWorld:
        return BoxWorld((*self.boxes, box))


def render(
    world: BoxWorld, K: np.ndarray, shape: tuple[int, int], T_world_cam: np.ndarray,
    range_max_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) float32 z-depth (0 = no return) and (H, W, 3) uint8 colour."""
    H, W = shape
    v, u = np.mgrid[0:H, 0:W]
    dirs_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((H, W))], -1)
    d = dirs_cam.reshape(-1, 3) @ T_world_cam[:3, :3].T  # t along d is the z-depth
    o = T_world_cam[:3, 3]
    best = np.full(d.shape[0], np.inf)
    label = np.full(d.shape[0], -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(d[:, 2] < 0, -o[2] / d[:, 2], np.inf)
        best, label = np.minimum(best, t_floor), np.where(t_floor < best, 0, label)
        for i, box in enumerate(world.boxes, start=1):
            lo, hi = np.array(box[0::2]), np.array(box[1::2])
            t1, t2 = (lo - o) / d, (hi - o) / d
            t_near = np.nanmax(np.minimum(t1, t2), axis=1)
            t_far = np.nanmin(np.maximum(t1, t2), axis=1)
            hit = (t_near <= t_far) & (t_far > 0) & (t_near > 0) & (t_near < best)
            best, label = np.where(hit, t_near, best), np.where(hit, i, label)
    depth = np.where(best <= range_max_m, best, 0.0).reshape(H, W).astype(np.float32)
    palette = (np.arange(len(world.boxes) + 2)[:, None] * np.array([53, 97, 151])) % 256
    rgb = palette[label.reshape(H, W) + 1].astype(np.uint8)
    return depth, rgb


def T_world_cam_of(x: float, y: float, yaw: float, T_base_cam: np.ndarray) -> np.ndarray:
    return T_from_xyyaw(x, y, yaw) @ T_base_cam
