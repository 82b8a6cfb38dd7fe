"""Pairwise consistency maximisation (PCM, Mangelson et al. ICRA 2018) of inter-robot edges.

One registration between two robots cannot be judged on its own: a confident wrong basin
looks exactly like a correction, and the robust kernels only catch it once enough other
edges disagree. Two registrations between the same pair of robots, a_i → b_k and a_j → b_l,
are consistent when the loop they close with each robot's own chain
(T_ai_bk · T_bk_bl · T_bl_aj · T_aj_ai) is near the identity, within what the robots' drift
between the submaps can explain. The edges kept are the largest mutually consistent set
(a maximum clique) per robot pair, and only when it holds at least `min_clique` edges.

Pure: poses and edges in, the kept edges out.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from gtsam import Pose3

from services.common.geometry import invert
from services.common.pose_graph import Between

# ruff: noqa: N806 (T_a_b names)


@dataclass(frozen=True)
class ConsistencyParams:
    tol_m: float = 0.05  # loop error allowed ... plus per metre between the submaps
    tol_m_per_m: float = 0.02
    tol_rad: float = 0.02
    tol_rad_per_m: float = 0.005
    min_clique: int = 2  # a lone edge waits for a second that agrees with it


def loop_error(e1: Between, e2: Between, chain: Mapping[Hashable, np.ndarray]
               ) -> tuple[float, float, float]:
    """(m, rad, metres spanned) of the loop e1 · chain(b) · e2⁻¹ · chain(a).

    Both edges go from robot a's submap (target) to robot b's (source); `chain` holds each
    submap's pose in its own robot's frame (the reported poses)."""
    T_bk_bl = invert(chain[e1.b]) @ chain[e2.b]
    T_aj_ai = invert(chain[e2.a]) @ chain[e1.a]
    loop = e1.T_a_b @ T_bk_bl @ invert(e2.T_a_b) @ T_aj_ai
    xi = Pose3.Logmap(Pose3(loop))
    span = float(np.linalg.norm(T_bk_bl[:3, 3]) + np.linalg.norm(T_aj_ai[:3, 3]))
    return float(np.linalg.norm(xi[3:])), float(np.linalg.norm(xi[:3])), span


def consistent(e1: Between, e2: Between, chain: Mapping[Hashable, np.ndarray],
               params: ConsistencyParams) -> bool:
    dt, dr, span = loop_error(e1, e2, chain)
    return (dt <= params.tol_m + params.tol_m_per_m * span
            and dr <= params.tol_rad + params.tol_rad_per_m * span)


def max_clique(adjacent: np.ndarray) -> list[int]:
    """Largest clique of a small undirected graph (Bron-Kerbosch with pivoting), sorted."""
    n = adjacent.shape[0]
    neighbours = [set(np.flatnonzero(adjacent[i]).tolist()) - {i} for i in range(n)]
    best: list[int] = []

    def expand(r: set[int], p: set[int], x: set[int]) -> None:
        nonlocal best
        if not p and not x:
            if len(r) > len(best) or (len(r) == len(best) and sorted(r) < best):
                best = sorted(r)
            return
        if len(r) + len(p) < len(best):
            return
        pivot = max(p | x, key=lambda u: len(neighbours[u] & p))
        for v in sorted(p - neighbours[pivot]):
            expand(r | {v}, p & neighbours[v], x & neighbours[v])
            p = p - {v}
            x = x | {v}

    expand(set(), set(range(n)), set())
    return best


def oriented(edge: Between, robot_of: Mapping[Hashable, tuple[int, int]]) -> Between:
    """The edge with its target in the lower (robot, epoch) (so a pair's edges compare
    directly). Only its transform is meant for the loop test: the information is not moved."""
    if robot_of[edge.a] <= robot_of[edge.b]:
        return edge
    return Between(edge.b, edge.a, invert(edge.T_a_b), edge.info, edge.robust)


@dataclass
class ConsistencyMemo:
    """Pair tests already made, reused while the four chain poses each one read are
    unchanged: the merger asks PCM again at every update with one or two new edges, and the
    old pairs' tests were most of its cost (66 000 in an AWS house mission)."""

    poses: dict[Hashable, tuple[np.ndarray, int]] = field(default_factory=dict)  # T, stamp
    tests: dict[tuple, tuple[tuple[int, ...], bool]] = field(default_factory=dict)

    def stamps(self, chain: Mapping[Hashable, np.ndarray]) -> dict[Hashable, int]:
        """Per submap, a number that changes whenever its chain pose does."""
        out = {}
        for key, T in chain.items():
            held = self.poses.get(key)
            if held is None or not np.array_equal(held[0], T):
                held = (np.array(T, copy=True), held[1] + 1 if held else 0)
                self.poses[key] = held
            out[key] = held[1]
        return out


def _test(e1: Between, e2: Between, chain: Mapping[Hashable, np.ndarray],
          params: ConsistencyParams, memo: ConsistencyMemo | None,
          stamps: Mapping[Hashable, int]) -> bool:
    if memo is None:
        return consistent(e1, e2, chain, params)
    pair = ((e1.a, e1.b), (e2.a, e2.b))
    now = (stamps[e1.a], stamps[e1.b], stamps[e2.a], stamps[e2.b])
    held = memo.tests.get(pair)
    if held is None or held[0] != now:
        held = (now, consistent(e1, e2, chain, params))
        memo.tests[pair] = held
    return held[1]


def select(edges: Sequence[Between], chain: Mapping[Hashable, np.ndarray],
           robot_of: Mapping[Hashable, tuple[int, int]], params: ConsistencyParams,
           memo: ConsistencyMemo | None = None) -> list[bool]:
    """Per edge (input order): kept by PCM. With a memo, pair tests made before with the
    same chain poses are not made again (the same answers)."""
    stamps = memo.stamps(chain) if memo is not None else {}
    groups: dict[tuple, list[int]] = {}
    for i, e in enumerate(edges):
        pair = tuple(sorted((robot_of[e.a], robot_of[e.b])))
        groups.setdefault(pair, []).append(i)
    keep = [False] * len(edges)
    for members in groups.values():
        es = [oriented(edges[i], robot_of) for i in members]
        n = len(es)
        adjacent = np.zeros((n, n), bool)
        for i in range(n):
            for j in range(i + 1, n):
                adjacent[i, j] = adjacent[j, i] = _test(es[i], es[j], chain, params, memo,
                                                        stamps)
        clique = max_clique(adjacent)
        if len(clique) >= params.min_clique:
            for c in clique:
                keep[members[c]] = True
    return keep
