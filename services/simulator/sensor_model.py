"""Sensor presets and the Kinect-v2-like depth model (pure numpy, no MuJoCo).

A time-of-flight camera returns nothing where too little light comes back: at grazing angles
(Lambertian return ∝ cos θ) and at depth edges, where a pixel's footprint straddles two
surfaces and its mixed phase gives a "flying pixel" that drivers filter out. Both are decided
from the rendered depth alone (normals by finite differences), so GL and ray casting agree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from services.simulator.config import SensorPreset, SimConfig


@dataclass(frozen=True)
class SensorModel:
    """Effective sensor settings after the preset and explicit overrides."""

    depth_noise_per_m2: float  # σ = this × depth², metres
    max_incidence_deg: float  # no return beyond this angle between ray and normal; 90 = off
    edge_rel_jump: float  # invalidate the far pixel of a jump > this × depth; 0 = off
    odom_noise_m_per_sqrt_m: float
    odom_noise_rad_per_sqrt_rad: float


PRESETS: dict[SensorPreset, SensorModel] = {
    "realistic": SensorModel(0.0005, 80.0, 0.1, 0.01, 0.01),
    # Every random or dropout term off; odometry's deterministic scale and bias errors stay.
    "ideal": SensorModel(0.0, 90.0, 0.0, 0.0, 0.0),
}


def sensor_model(cfg: SimConfig) -> SensorModel:
    """The preset `cfg.sensors`, with each field the config sets explicitly (not None) winning."""
    base = PRESETS[cfg.sensors]

    def pick(explicit: float | None, preset: float) -> float:
        return preset if explicit is None else float(explicit)

    return SensorModel(
        depth_noise_per_m2=pick(cfg.depth_noise_per_m2, base.depth_noise_per_m2),
        max_incidence_deg=pick(cfg.depth_max_incidence_deg, base.max_incidence_deg),
        edge_rel_jump=pick(cfg.depth_edge_rel_jump, base.edge_rel_jump),
        odom_noise_m_per_sqrt_m=pick(cfg.odom_noise_m_per_sqrt_m, base.odom_noise_m_per_sqrt_m),
        odom_noise_rad_per_sqrt_rad=pick(
            cfg.odom_noise_rad_per_sqrt_rad, base.odom_noise_rad_per_sqrt_rad
        ),
    )


def _one_sided(dw: np.ndarray, axis: int) -> np.ndarray:
    """Per pixel, the smaller of its backward and forward differences along `axis` (0 or 1).

    `dw` holds the n−1 differences; borders take the one they have. Picking the smaller side
    keeps a pixel next to a depth edge on its own surface instead of reading the jump as a
    slope (which would also erase a pixel on each side of every edge).
    """
    if axis == 0:
        return _one_sided(dw.T, 1).T
    h, n = dw.shape
    out = np.empty((h, n + 1), dw.dtype)
    back, fwd = dw[:, :-1], dw[:, 1:]
    np.copyto(out[:, 1:-1], fwd)
    np.copyto(out[:, 1:-1], back, where=np.abs(back) <= np.abs(fwd))
    out[:, 0], out[:, -1] = dw[:, 0], dw[:, -1]
    return out


@lru_cache(maxsize=8)
def _ray_terms(
    shape: tuple[int, int], K: tuple[float, float, float, float], max_incidence_deg: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rx (1, W), ry (H, 1) and the per-pixel bound on |n|² of the grazing test."""
    fx, fy, cx, cy = K
    rx = ((np.arange(shape[1]) - cx) / fx)[None, :].astype(np.float32)
    ry = ((np.arange(shape[0]) - cy) / fy)[:, None].astype(np.float32)
    bound = (1 / math.cos(math.radians(max_incidence_deg)) ** 2 / (1 + rx * rx + ry * ry))
    return rx, ry, bound.astype(np.float32)


def invalid_return_mask(
    depth: np.ndarray, K: np.ndarray, max_incidence_deg: float, edge_rel_jump: float
) -> np.ndarray:
    """True where a ToF camera would give no return: grazing incidence or the far side of a
    depth edge. `depth` is z-depth in metres, ≤ 0 = no return (never flagged again).

    Works on inverse depth w = 1/z, which is affine in (u, v) on a plane, so one-sided
    differences give planes' normals exactly. With g = fx·∂z/∂u / z = −fx·w_u / w (h for v) and
    the ray r = ((u−cx)/fx, (v−cy)/fy, 1), the normal is ∝ (−g, −h, 1 + g·rx + h·ry) and
    cos θ = 1 / (|r|·|n|): θ > θmax ⇔ |n|² > 1 / (cos²θmax·|r|²), no arccos, no square root.
    """
    z = np.asarray(depth, np.float32)
    valid = z > 0
    w = np.divide(np.float32(1), z, out=np.zeros_like(z), where=valid)
    dwu, dwv = np.diff(w, axis=1), np.diff(w, axis=0)
    mask = np.zeros(z.shape, bool)
    if 0 < max_incidence_deg < 90:
        fx, fy = np.float32(K[0, 0]), np.float32(K[1, 1])
        rx, ry, bound = _ray_terms(
            z.shape, (float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])),
            float(max_incidence_deg),
        )
        g = _one_sided(dwu, 1)
        g *= z  # z = 1/w where valid, 0 elsewhere (never flagged)
        g *= -fx
        h = _one_sided(dwv, 0)
        h *= z
        h *= -fy
        t = g * rx
        t += h * ry
        t += 1
        t *= t
        t += g * g
        t += h * h
        mask |= t > bound
    if edge_rel_jump > 0:
        # |z_a − z_b| > k·min(z_a, z_b) is |w_a − w_b| > k·min(w_a, w_b) in inverse depth.
        # Only the far pixel of a pair goes: the foreground keeps its silhouette and thin
        # objects (table legs are 1-2 px at 160×120) are not erased; no return (w = 0) is the
        # far side of any jump, so borders with the sky or beyond range cost nothing.
        k = np.float32(edge_rel_jump)
        jump = np.abs(dwu) > k * np.minimum(w[:, :-1], w[:, 1:])
        mask[:, :-1] |= jump & (dwu > 0)  # left pixel farther (smaller w)
        mask[:, 1:] |= jump & (dwu < 0)
        jump = np.abs(dwv) > k * np.minimum(w[:-1], w[1:])
        mask[:-1] |= jump & (dwv > 0)  # upper pixel farther
        mask[1:] |= jump & (dwv < 0)
    mask &= valid
    return mask


def apply_depth_model(
    raw_depth: np.ndarray, K: np.ndarray, model: SensorModel, range_m: float,
    rng: np.random.Generator | None,
) -> np.ndarray:
    """Published depth from a rendered one: invalid returns, then noise σ = k·d², then range.

    Invalid returns are judged on the noise-free geometry (the physics decides them, not the
    noise: noisy finite differences would read a far head-on wall as grazing). Noise is drawn
    for every pixel, returns or not, so the generator's stream does not depend on the scene.
    """
    depth = np.where((raw_depth > 0) & (raw_depth <= range_m), raw_depth, 0).astype(np.float32)
    if model.max_incidence_deg < 90 or model.edge_rel_jump > 0:
        depth[invalid_return_mask(raw_depth, K, model.max_incidence_deg, model.edge_rel_jump)] = 0
    if model.depth_noise_per_m2 > 0 and rng is not None:
        # Only returns get noise: the far plane's ~1 km "depth" would land 3 % of the sky
        # within range.
        noise = rng.standard_normal(depth.shape, dtype=np.float32)
        depth = depth + noise * np.float32(model.depth_noise_per_m2) * depth * depth
        depth = np.where((depth > 0) & (depth <= range_m), depth, 0).astype(np.float32)
    return depth
