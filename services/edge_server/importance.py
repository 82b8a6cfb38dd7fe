"""Adaptive frontier assignment: frontier importance I_t and revenue U (the paper's equations).

I_t(f) = e^{−λT}·D / (1 + e^{−λ(T−ξ)}) for F_u and 1 − that for F_w, which simplifies to
D / (e^{λT} + e^{λξ}): strictly decreasing in T, so importance moves from F_u to F_w as time
passes. D = mean‖l_c − f‖ over F_u / mean‖l_c − f‖ over F_w (the text says "average"; with
sums D would just count frontiers), l_c the robots' centroid; D = 1 when a class is empty.
The F_u term is clipped to [0, 1] so the F_w term stays a weight in [0, 1].
U(r_i, f′) = I_t(f)·I_g(f) / (κ·h(p_i, p_f′)), h the path length on the merged grid (m),
floored at `min_path_m` (a robot standing on f′ would otherwise get an infinite revenue).
"""

from __future__ import annotations

import numpy as np


def distance_factor(
    robots_xy: np.ndarray, centroid_xy: np.ndarray, is_weak: np.ndarray
) -> float:
    """D: mean distance from the robots' centroid l_c to F_u over the same for F_w."""
    if len(robots_xy) == 0 or not is_weak.any() or is_weak.all():
        return 1.0
    l_c = np.asarray(robots_xy, np.float64).reshape(-1, 2).mean(axis=0)
    d = np.linalg.norm(np.asarray(centroid_xy)[:, :2] - l_c, axis=1)
    mean_w = float(d[is_weak].mean())
    return float(d[~is_weak].mean() / mean_w) if mean_w > 0 else 1.0


def unexplored_importance(t_s: float, d_factor: float, lam: float, xi: float) -> float:
    """The F_u importance e^{−λT}·D / (1 + e^{−λ(T−ξ)}), clipped to [0, 1]."""
    value = d_factor / (np.exp(lam * t_s) + np.exp(lam * xi))
    return float(np.clip(value, 0.0, 1.0))


def importance(
    t_s: float, robots_xy: np.ndarray, centroid_xy: np.ndarray, is_weak: np.ndarray,
    lam: float, xi: float,
) -> np.ndarray:
    """(F,) I_t(f) for frontier regions of either class at mission time T = t_s."""
    i_u = unexplored_importance(t_s, distance_factor(robots_xy, centroid_xy, is_weak), lam, xi)
    return np.where(is_weak, 1.0 - i_u, i_u)


def revenue(
    imp: np.ndarray, gain: np.ndarray, path_m: np.ndarray, kappa: float, min_path_m: float
) -> np.ndarray:
    """(R, F) U = I_t·I_g / (κ·h); −inf where h is infinite (unreachable)."""
    h = np.maximum(np.asarray(path_m, np.float64), min_path_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (imp * gain)[None, :] / (kappa * h)
    return np.where(np.isfinite(path_m), u, -np.inf)
