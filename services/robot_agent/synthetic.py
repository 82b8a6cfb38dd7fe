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


def aisle_points(rng: np.random.Generator, n_face: int = 60_000) -> np.ndarray:
    """(N, 3) world points of a warehouse aisle: two rack faces at y = ±1.2 m from x = −2 to
    20 m, 0.05-1.5 m high, with 8 cm uprights every 2.7 m on both."""
    faces = np.c_[rng.uniform(-2.0, 20.0, n_face), rng.choice([-1.2, 1.2], n_face),
                  rng.uniform(0.05, 1.5, n_face)]
    uprights = [np.c_[x0 + rng.uniform(0.0, 0.08, 800), side - np.sign(side) *
                      rng.uniform(0.0, 0.08, 800), rng.uniform(0.05, 1.5, 800)]
                for x0 in np.arange(-2.0, 20.0, 2.7) for side in (-1.2, 1.2)]
    return np.vstack([faces, *uprights])


def aisle_frame(points_world: np.ndarray, x: float, rng: np.random.Generator,
                range_m: float = 5.0, noise_per_m2: float = 0.0005,
                half_fov_rad: float = np.radians(42.0)) -> np.ndarray:
    """(N, 3) base-frame points a forward camera at (x, 0, yaw 0) sees of `points_world`,
    within `range_m` and the field of view, with the simulator's depth noise along each ray
    (σ = noise_per_m2 · d²)."""
    base = points_world - np.array([x, 0.0, 0.0])
    r = np.hypot(base[:, 0], base[:, 1])
    seen = base[(base[:, 0] > 0.3) & (r < range_m)
                & (np.abs(np.arctan2(base[:, 1], base[:, 0])) < half_fov_rad)]
    d = np.linalg.norm(seen, axis=1, keepdims=True)
    return seen + seen / d * noise_per_m2 * d**2 * rng.standard_normal((len(seen), 1))
