"""The merger's back end: a GTSAM Pose3 pose graph solved with Levenberg-Marquardt.

Nodes are submaps; priors fix the known initial poses; between-edges carry odometry (Gaussian)
or registration (robust). All information matrices are 6×6 in GTSAM's tangent convention:
rotation first, right perturbation (T·Exp(ξ)) of the measured T_a_b. A false registration edge
is removed in three stages (field notes): LM with Huber (convex, so it converges from the
agents' drifted poses), LM with Cauchy warm-started from it (redescending: an outlier's pull
fades), then every robust edge whose whitened residual χ² exceeds `gate_chi2` is dropped and
LM runs once more without it, so outliers exert no pull at all on the final poses.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import gtsam
import numpy as np

# ruff: noqa: N806 (T_a_b names)


@dataclass(frozen=True)
class Prior:
    key: Hashable
    T_world_node: np.ndarray
    info: np.ndarray  # (6, 6)


@dataclass(frozen=True)
class Between:
    a: Hashable
    b: Hashable
    T_a_b: np.ndarray  # measured pose of b in a's frame
    info: np.ndarray  # (6, 6), GTSAM convention
    robust: bool  # registration edges are robust; odometry is Gaussian


@dataclass(frozen=True)
class GraphResult:
    poses: dict[Hashable, np.ndarray]  # T_world_node
    inlier: list[bool]  # per edge in input order (odometry edges are always True)


def info_diag(sigma_rot: Sequence[float], sigma_trans: Sequence[float]) -> np.ndarray:
    """Diagonal information from standard deviations (rad for roll/pitch/yaw, then m)."""
    return np.diag(1.0 / np.square(np.concatenate([sigma_rot, sigma_trans])))


def left_to_right_info(info_left: np.ndarray, T_a_b: np.ndarray) -> np.ndarray:
    """Information of a left perturbation (Exp(ξ)·T, open3d's convention in the target frame)
    re-expressed for GTSAM's right perturbation (T·Exp(ξ)): Ad(T)ᵀ Λ Ad(T)."""
    ad = gtsam.Pose3(T_a_b).AdjointMap()
    return ad.T @ info_left @ ad


def edge_chi2(edge: Between, T_world_a: np.ndarray, T_world_b: np.ndarray) -> float:
    """Whitened squared residual of a between-edge at the given poses."""
    predicted = gtsam.Pose3(T_world_a).between(gtsam.Pose3(T_world_b))
    e = gtsam.Pose3.Logmap(gtsam.Pose3(edge.T_a_b).between(predicted))
    return float(e @ edge.info @ e)


def _noise(info: np.ndarray, kernel: gtsam.noiseModel.mEstimator.Base | None):
    gauss = gtsam.noiseModel.Gaussian.Information(np.asarray(info, np.float64))
    return gauss if kernel is None else gtsam.noiseModel.Robust.Create(kernel, gauss)


def _solve(
    ids: dict[Hashable, int], initial: dict[Hashable, np.ndarray], priors: Sequence[Prior],
    edges: Sequence[Between], kernel: gtsam.noiseModel.mEstimator.Base | None,
    max_iterations: int,
) -> dict[Hashable, np.ndarray]:
    graph = gtsam.NonlinearFactorGraph()
    for p in priors:
        graph.add(gtsam.PriorFactorPose3(ids[p.key], gtsam.Pose3(p.T_world_node),
                                         _noise(p.info, None)))
    for e in edges:
        graph.add(gtsam.BetweenFactorPose3(ids[e.a], ids[e.b], gtsam.Pose3(e.T_a_b),
                                           _noise(e.info, kernel if e.robust else None)))
    values = gtsam.Values()
    for key, i in ids.items():
        values.insert(i, gtsam.Pose3(initial[key]))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    return {key: result.atPose3(i).matrix() for key, i in ids.items()}


def optimize(
    initial: dict[Hashable, np.ndarray], priors: Sequence[Prior], edges: Sequence[Between],
    huber_k: float = 1.345, cauchy_c: float = 1.0, gate_chi2: float = 16.81,
    max_iterations: int = 50,
) -> GraphResult:
    """Robust LM over the graph; `gate_chi2` defaults to χ²(6) at 99 %."""
    ids = {key: i for i, key in enumerate(sorted(initial))}  # sorted: deterministic ordering
    M = gtsam.noiseModel.mEstimator
    poses = _solve(ids, initial, priors, edges, M.Huber.Create(huber_k), max_iterations)
    if any(e.robust for e in edges):
        poses = _solve(ids, poses, priors, edges, M.Cauchy.Create(cauchy_c), max_iterations)
    inlier = [not e.robust or edge_chi2(e, poses[e.a], poses[e.b]) <= gate_chi2 for e in edges]
    if not all(inlier):
        kept = [e for e, ok in zip(edges, inlier, strict=True) if ok]
        poses = _solve(ids, poses, priors, kept, None, max_iterations)
    return GraphResult(poses, inlier)
