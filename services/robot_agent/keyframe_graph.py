"""The agent's back end: a keyframe pose graph with loop closures (GTSAM, robust LM).

Frame-to-map registration (localization.py) bounds the drift rate but not the drift: an error
built while registration is unavailable (frames hidden by teammates, a wall filling the view)
stays in every later frame, and a 5 cm map cannot pull a 0.5-1° yaw error back. Here every
keyframe submap is a node in the `loc` frame; consecutive keyframes are joined by the front
end's relative motion (odometry edges, σ growing with the motion); a keyframe that closes is
registered against earlier keyframes it overlaps (place recognition by geometry: candidates by
distance and box overlap, verified by GICP convergence, inlier share and a drift gate), and
each accepted closure is a robust edge. Robust LM (Huber, Cauchy, χ² gate:
services/common/pose_graph.py) then moves every keyframe, the open one included.

Pure: numpy arrays in, corrected poses out; no bus, no clock.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from services.common.arrays import column_extremes
from services.common.geometry import (
    T_from_xyyaw,
    invert,
    transform_points,
    wrap_angle,
    xyyaw_from_T,
)
from services.common.pose_graph import Between, Prior, info_diag, optimize
from services.common.registration import (
    Prepared,
    RegistrationParams,
    prepare,
    register,
    world_box,
)

log = logging.getLogger(__name__)

# ruff: noqa: N806 (T_a_b names)


@dataclass(frozen=True)
class LoopParams:
    search_radius_m: float = 3.0  # candidate keyframes start within this of the closing one
    min_gap: int = 2  # ... and are at least this many keyframes older
    min_driven_m: float = 3.0  # ... and this much path older (the front end links neighbours)
    max_candidates: int = 1  # older keyframes that make the map it is registered to
    min_overlap_m3: float = 0.3
    min_points: int = 300  # voxels above the floor a keyframe needs to take part
    floor_z_m: float = 0.03
    # drift gate: a closure may move the relative estimate by at most base + per metre driven
    # between the two keyframes (the front end drifts ~1-2 % at worst)
    gate_m: float = 0.10
    gate_m_per_m: float = 0.03
    gate_rad: float = 0.03
    gate_rad_per_m: float = 0.01
    gate_max_m: float = 0.6
    gate_max_rad: float = 0.2
    # odometry edge σ: base + per metre driven and per radian turned
    odom_sigma_m: float = 0.01
    odom_sigma_m_per_m: float = 0.02
    odom_sigma_rad: float = 0.002
    odom_sigma_rad_per_m: float = 0.005
    odom_sigma_rad_per_rad: float = 0.01
    # a closure enters the graph only with a consistent partner among the closures of the
    # last `confirm_window` closing keyframes (one closure alone cannot be judged)
    confirm_window: int = 4
    consistent_m: float = 0.03
    consistent_m_per_m: float = 0.01
    consistent_rad: float = 0.01
    consistent_rad_per_m: float = 0.003
    correction_tol_m: float = 0.003
    correction_tol_rad: float = 0.001
    registration: RegistrationParams = field(default_factory=lambda: RegistrationParams(
        downsample_m=0.15, max_corr_m=0.5, fine_downsample_m=0.05, fine_corr_m=0.08,
        max_iterations=30, min_inlier_frac=0.6, max_shift_m=0.6, max_turn_rad=0.2,
        sigma_m=0.03))


@dataclass
class Keyframe:
    kf_id: int
    T_loc_kf: np.ndarray  # (4, 4) current estimate
    T_front: np.ndarray  # (4, 4) the front end's pose of it (fixed: the odometry measurement)
    distance_m: float  # front-end path length from the first keyframe to this one
    T_reported: np.ndarray  # (4, 4) the pose last given out by `close()` (or the first)
    points: np.ndarray | None = None  # (N, 3) points above the floor, own frame, once closed
    prepared: Prepared | None = None  # registration cloud, once closed
    box: np.ndarray | None = None  # (2, 3) box of its points in its own frame


@dataclass(frozen=True)
class LoopClosure:
    a: int  # older keyframe id
    b: int  # closing keyframe id
    T_a_b: np.ndarray
    info: np.ndarray


def _planar_info(sigma_xy: float, sigma_yaw: float) -> np.ndarray:
    """Pose3 information of a planar motion: z, roll and pitch nearly exact."""
    return info_diag([0.002, 0.002, sigma_yaw], [sigma_xy, sigma_xy, 0.002])


def _planar(T: np.ndarray) -> np.ndarray:
    return T_from_xyyaw(*xyyaw_from_T(T))


def _box_overlap(box_a: np.ndarray, box_b: np.ndarray) -> float:
    side = np.minimum(box_a[1], box_b[1]) - np.maximum(box_a[0], box_b[0])
    return float(np.prod(np.maximum(side, 0.0)))


class KeyframeGraph:
    """Keyframes of one agent in its `loc` frame; `close()` returns the poses that moved."""

    def __init__(self, params: LoopParams | None = None) -> None:
        self.params = params or LoopParams()
        self.keyframes: dict[int, Keyframe] = {}
        self.order: list[int] = []
        self.priors: list[Prior] = []
        self.odometry: list[Between] = []
        self.closures: list[LoopClosure] = []  # confirmed: in the graph
        self.pending: list[LoopClosure] = []  # verified, waiting for a consistent partner
        self.tried = 0
        self.rejected = 0  # by GICP or the drift gate
        self.dropped = 0  # by the robust back end

    def add_keyframe(self, kf_id: int, T_front_kf: np.ndarray) -> None:
        """A new keyframe at the front end's pose, chained to the previous one by the front
        end's relative motion (the front end itself is never re-anchored, so that motion is
        always in one consistent frame)."""
        T = _planar(T_front_kf)
        if not self.order:
            self.priors.append(Prior(kf_id, T, info_diag([1e-4] * 3, [1e-4] * 3)))
            self.keyframes[kf_id] = Keyframe(kf_id, T, T.copy(), 0.0, T.copy())
        else:
            prev = self.keyframes[self.order[-1]]
            T_prev_kf = invert(prev.T_front) @ T
            dx, dy, dyaw = xyyaw_from_T(T_prev_kf)
            d, turn = float(np.hypot(dx, dy)), abs(float(wrap_angle(dyaw)))
            p = self.params
            info = _planar_info(
                p.odom_sigma_m + p.odom_sigma_m_per_m * d,
                p.odom_sigma_rad + p.odom_sigma_rad_per_m * d + p.odom_sigma_rad_per_rad * turn)
            self.odometry.append(Between(prev.kf_id, kf_id, T_prev_kf, info, robust=False))
            T_est = _planar(prev.T_loc_kf @ T_prev_kf)
            self.keyframes[kf_id] = Keyframe(kf_id, T_est, T, prev.distance_m + d, T_est.copy())
        self.order.append(kf_id)

    def close(self, kf_id: int, points_kf: np.ndarray) -> dict[int, np.ndarray]:
        """Keyframe `kf_id` is complete with (N, 3) points in its own frame: register it to
        older keyframes it overlaps; when a closure is accepted, re-solve the graph.
        Returns {keyframe id: corrected T_loc_kf} for poses that moved more than the
        tolerance (the open keyframe included)."""
        kf = self.keyframes[kf_id]
        pts = np.asarray(points_kf, np.float64)
        pts = pts[pts[:, 2] > self.params.floor_z_m]
        if pts.shape[0] < self.params.min_points:
            return {}
        kf.points = pts
        kf.prepared = prepare(pts, self.params.registration)
        kf.box = np.stack(column_extremes(pts))
        candidates = self._candidates(kf)
        if not candidates:
            return {}
        self.tried += 1
        closure = self._verify(candidates, kf)
        if closure is None:
            self.rejected += 1
            return {}
        partners = [c for c in self.closures[-self.params.confirm_window:] + self.pending
                    if c.b != closure.b and self._consistent(c, closure)]
        if not partners:
            self.pending = (self.pending + [closure])[-self.params.confirm_window:]
            return {}
        for c in partners:
            if c in self.pending:
                self.pending.remove(c)
                self.closures.append(c)
        self.closures.append(closure)
        return self.solve()

    def _implied(self, c: LoopClosure) -> np.ndarray:
        """The correction closure c asks of its closing keyframe: T_b_b' at the estimates."""
        return invert(self.keyframes[c.b].T_loc_kf) @ self.keyframes[c.a].T_loc_kf @ c.T_a_b

    def _consistent(self, c1: LoopClosure, c2: LoopClosure) -> bool:
        """Pairwise consistency (PCM's test on two closures): both must move their closing
        keyframes alike, since the front end's motion between those is nearly exact. A false
        closure (a wrong basin) asks for a correction no other closure agrees with."""
        p = self.params
        b1, b2 = self.keyframes[c1.b], self.keyframes[c2.b]
        T_12 = invert(b1.T_loc_kf) @ b2.T_loc_kf
        D = invert(T_12) @ invert(self._implied(c1)) @ T_12 @ self._implied(c2)
        dx, dy, dyaw = xyyaw_from_T(D)
        driven = abs(b2.distance_m - b1.distance_m)
        return bool(np.hypot(dx, dy) <= p.consistent_m + p.consistent_m_per_m * driven
                    and abs(wrap_angle(dyaw)) <= p.consistent_rad
                    + p.consistent_rad_per_m * driven)

    def _candidates(self, kf: Keyframe) -> list[Keyframe]:
        p = self.params
        idx = self.order.index(kf.kf_id)
        box = world_box(kf.box, kf.T_loc_kf)
        scored = []
        for other_id in self.order[: max(idx - p.min_gap + 1, 0)]:
            other = self.keyframes[other_id]
            if other.prepared is None or kf.distance_m - other.distance_m < p.min_driven_m:
                continue
            if np.hypot(*(other.T_loc_kf[:2, 3] - kf.T_loc_kf[:2, 3])) > p.search_radius_m:
                continue
            overlap = _box_overlap(box, world_box(other.box, other.T_loc_kf))
            if overlap >= p.min_overlap_m3:
                scored.append((-overlap, other_id, other))
        return [other for _, _, other in sorted(scored, key=lambda s: s[:2])][: p.max_candidates]

    def _verify(self, olds: list[Keyframe], b: Keyframe) -> LoopClosure | None:
        """GICP of b onto the older keyframes (as one map in the frame of the one it overlaps
        most, `a`) from the current estimate, within the drift gate. One keyframe alone is a
        partial view and registered 0.2-0.4° off in replays; the map of its neighbours is not."""
        p = self.params
        a = olds[0]
        T_a_loc = invert(a.T_loc_kf)
        target = np.concatenate([transform_points(T_a_loc @ o.T_loc_kf, o.points)
                                 for o in olds if o.points is not None])
        assert b.prepared is not None
        T_init = T_a_loc @ b.T_loc_kf
        result = register(prepare(target, p.registration), b.prepared, T_init, p.registration)
        if result is None:
            return None
        T_a_b = _planar(result.T_target_source)
        dx, dy, dyaw = xyyaw_from_T(invert(T_init) @ T_a_b)
        driven = abs(b.distance_m - a.distance_m)
        if (np.hypot(dx, dy) > min(p.gate_max_m, p.gate_m + p.gate_m_per_m * driven)
                or abs(wrap_angle(dyaw)) > min(p.gate_max_rad,
                                               p.gate_rad + p.gate_rad_per_m * driven)):
            return None
        return LoopClosure(a.kf_id, b.kf_id, T_a_b, result.info)

    def solve(self) -> dict[int, np.ndarray]:
        edges = self.odometry + [Between(c.a, c.b, c.T_a_b, c.info, robust=True)
                                 for c in self.closures]
        initial = {k: kf.T_loc_kf for k, kf in self.keyframes.items()}
        result = optimize(initial, self.priors, edges)
        self.dropped = sum(not ok for ok in result.inlier)
        changed = {}
        p = self.params
        for k, T in result.poses.items():
            kf = self.keyframes[k]
            kf.T_loc_kf = _planar(T)
            dx, dy, dyaw = xyyaw_from_T(invert(kf.T_reported) @ kf.T_loc_kf)
            if np.hypot(dx, dy) > p.correction_tol_m or abs(dyaw) > p.correction_tol_rad:
                kf.T_reported = kf.T_loc_kf.copy()
                changed[k] = kf.T_reported
        return changed

    def T_map_front(self) -> np.ndarray:
        """The correction of the front end's frame at the newest keyframe: T_loc_base of the
        robot now = T_map_front · (the front end's T_loc_base)."""
        if not self.order:
            return np.eye(4)
        kf = self.keyframes[self.order[-1]]
        return kf.T_loc_kf @ invert(kf.T_front)

    def stats(self) -> dict[str, int]:
        return {"keyframes": len(self.order), "closures": len(self.closures),
                "pending": len(self.pending),
                "tried": self.tried, "rejected": self.rejected, "dropped": self.dropped}
