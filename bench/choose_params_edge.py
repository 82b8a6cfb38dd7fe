"""Choose r_s, δ_d, δ_v (Alg. 1) and λ, ξ, κ by rerunnable experiments on synthetic surfaces.

Surfaces at ϱ = 0.05 m: a floor with a hole (its rim must be F_u), a wall–floor junction and
a box corner (ordinary structure: must be neither F_u nor F_w), and a noisy patch (points
jittered ±1–2 voxels off the surface: must be F_w). For each r_s the script prints the ρ and σ²
quantiles per class of point and the thresholds that separate them (midpoints between the
classes), then the importance curve I_t(T) for the chosen λ, ξ.

    .venv/bin/python bench/choose_params_edge.py
"""

from __future__ import annotations

import logging

import numpy as np

from services.edge_server.frontiers3d import ball_offsets, density_variance
from services.edge_server.importance import unexplored_importance

log = logging.getLogger("choose_params_edge")


def surfaces(seed: int = 0) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Lattice points and boolean masks of the probe sets."""
    rng = np.random.default_rng(seed)
    g = np.mgrid[0:80, 0:80].reshape(2, -1).T
    floor = np.c_[g, np.zeros(len(g), int)]
    hole = ((floor[:, 0] - 20) ** 2 + (floor[:, 1] - 20) ** 2) < 64
    floor = floor[~hole]
    wall = np.c_[g[:, 0], np.full(len(g), 79), g[:, 1] % 40]
    patch = (floor[:, 0] >= 50) & (floor[:, 0] < 70) & (floor[:, 1] >= 10) & (floor[:, 1] < 30)
    noisy = floor[patch].copy()
    noisy[:, 2] += rng.integers(-2, 3, len(noisy))
    pts = np.concatenate([floor[~patch], noisy, wall])
    pts, inv = np.unique(pts, axis=0, return_inverse=True)
    d_hole = np.hypot(pts[:, 0] - 20, pts[:, 1] - 20)
    in_patch = (pts[:, 0] >= 52) & (pts[:, 0] < 68) & (pts[:, 1] >= 12) & (pts[:, 1] < 28)
    masks = {
        "plane interior": (pts[:, 2] == 0) & (d_hole > 14) & (pts[:, 1] < 70) & ~in_patch
        & (pts[:, 0] > 5) & (pts[:, 0] < 45) & (pts[:, 1] > 5),
        "hole rim": (pts[:, 2] == 0) & (d_hole < 9.5),
        "wall–floor junction": (pts[:, 1] >= 77) & (pts[:, 2] <= 2) & (pts[:, 0] > 5)
        & (pts[:, 0] < 75),
        "noisy patch": in_patch,
    }
    return pts, masks


def quantiles(x: np.ndarray) -> str:
    q = np.quantile(x, [0.05, 0.5, 0.95])
    return f"{q[0]:.4g} / {q[1]:.4g} / {q[2]:.4g}"


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    v = 0.05
    pts, masks = surfaces()
    lines = ["| r_s (m) | K | set | ρ p5/p50/p95 | σ² (m²) p5/p50/p95 |", "|---|---|---|---|---|"]
    for r_s in (0.10, 0.15, 0.20):
        rho, var = density_variance(pts, r_s / v)
        var = var * v * v
        k = len(ball_offsets(r_s / v))
        for name, m in masks.items():
            row = f"| {r_s:.2f} | {k} | {name} | {quantiles(rho[m])} | {quantiles(var[m])} |"
            lines.append(row)
        normal = masks["plane interior"] | masks["wall–floor junction"]
        d_d = 0.5 * (np.quantile(rho[masks["hole rim"]], 0.95) + np.quantile(rho[normal], 0.05))
        d_v = 0.5 * (np.quantile(var[normal], 0.95) + np.quantile(var[masks["noisy patch"]], 0.5))
        fu = [float((rho[m] < d_d).mean()) for m in masks.values()]
        fw = [float((var[m] > d_v).mean()) for m in masks.values()]
        lines.append(f"| {r_s:.2f} | | δ_d = {d_d:.1f}, δ_v = {d_v:.4g} | F_u share "
                     + " / ".join(f"{x:.2f}" for x in fu) + " | F_w share "
                     + " / ".join(f"{x:.2f}" for x in fw) + " |")
    log.info("\n".join(lines))
    log.info("\nI_t(F_u) with D = 1 (λ = 0.01 /s, ξ = 0 s); I_t(F_w) = 1 − that")
    log.info("| T (s) | " + " | ".join(str(t) for t in (0, 30, 60, 120, 240, 400)) + " |")
    log.info("|---|" + "---|" * 6)
    log.info("| I_t(F_u) | " + " | ".join(f"{unexplored_importance(t, 1.0, 0.01, 0.0):.3f}"
                                          for t in (0, 30, 60, 120, 240, 400)) + " |")


if __name__ == "__main__":
    main()
