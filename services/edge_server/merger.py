"""Coherent spatial map merger: the incremental pose graph over every robot's submaps.

Nodes are submaps. A robot's first submap gets a tight prior at its reported pose (robots start
from known initial poses); the first submap of a later epoch (a restarted agent) a loose one.
Consecutive submaps of one robot and epoch are joined by an odometry edge, frozen when the
newer submap first arrives: T_a_b = T_world_a⁻¹·T_reported_b, with T_world_a the corrected
pose when the edge corrected a (the agent re-anchors its odometry frame on the newest
corrected submap, which is a). Pairs of submaps of different robots whose world boxes overlap
are registered once both are closed (their robot has started a newer one), at most
`max_registrations` per update, so the cost is amortised across ticks. With a precheck set,
a pair is first asked cheaply whether enough of the source's points lie near the target's
at the current estimate (three in four box-overlapping pairs share too little surface to
pass the registration's inlier test); one that does not is set aside untried and costs
none of the update's registrations. LM runs only when the
graph changed and holds at least one registration edge; until then placements follow reports.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import small_gicp
from gtsam import Pose3

from services.common.arrays import column_extremes
from services.common.geometry import invert
from services.common.pose_graph import Between, Prior, info_diag, optimize
from services.common.registration import (
    Prepared,
    RegistrationParams,
    overlapping_pairs,
    prepare,
    register,
    world_boxes,
)
from services.edge_server.config import EdgeConfig
from services.edge_server.consistency import ConsistencyMemo, ConsistencyParams, select
from services.edge_server.submap_store import StoredSubmap, SubmapKey, SubmapStore

log = logging.getLogger(__name__)

# ruff: noqa: N806 (T_a_b names)


@dataclass(frozen=True)
class MergerParams:
    prior_info: np.ndarray = field(default_factory=lambda: info_diag([1e-3] * 3, [1e-3] * 3))
    restart_prior_info: np.ndarray = field(
        default_factory=lambda: info_diag([0.02, 0.02, 0.2], [0.5, 0.5, 0.02]))
    # planar odometry: roll, pitch and z are nearly exact; x, y and yaw drift, by
    # σ = base + per metre (x, y) and base + per radian turned (yaw) between the submaps
    odometry_sigma_m: float = 0.01
    odometry_sigma_per_m: float = 0.01
    odometry_sigma_rad: float = 0.003
    odometry_sigma_rad_per_rad: float = 0.01
    # every later submap's report as a loose absolute prior (0: none): the agents register
    # against their own maps from a known start, so their error is bounded, not a random walk
    report_sigma_m: float = 0.0
    report_sigma_per_m: float = 0.0  # ... plus this per metre of the robot's chain so far
    report_sigma_rad: float = 0.02
    min_overlap_m3: float = 0.5
    min_points: int = 200
    max_registrations: int = 2
    registrations_per_robot: float = 0.0  # ... or this many per robot with submaps, if more
    registrations_per_pair: float = 0.0  # ... or this many per pair of robots, if more
    precheck_m: float = 0.0  # > 0: a source point within this of a target point counts ...
    precheck_frac: float = 0.4  # ... and a pair whose share is below this is not registered
    max_prechecks: int = 64  # pairs asked per update at most
    # prepared clouds (covariances, KD-trees) kept for this many submaps, least recently used
    # dropped: a 24-robot warehouse mission at 300 s holds thousands of submaps, and an edge
    # that kept them all was killed for memory
    max_prepared: int = 256
    correction_tol_m: float = 0.01
    correction_tol_rad: float = 0.004
    registration: RegistrationParams = field(
        default_factory=lambda: RegistrationParams(sigma_m=0.05))
    # inter-robot edges enter the graph only inside a consistent set (None: every edge)
    consistency: ConsistencyParams | None = field(
        default_factory=lambda: ConsistencyParams(tol_m_per_m=0.005))
    # odometry edges and PCM's chains from the agents' own-frame poses (T_odom) where sent,
    # instead of the reported world poses, which step wherever a correction reached the agent
    agent_frame: bool = False
    # > 0: a robot's own submaps at least this many apart (same epoch) are candidates too
    own_loop_gap: int = 0


def merger_params(config: EdgeConfig) -> MergerParams:
    """The merger's parameters from the edge's config section."""
    return MergerParams(
        odometry_sigma_m=config.merge_odometry_sigma_m,
        odometry_sigma_per_m=config.merge_odometry_sigma_per_m,
        odometry_sigma_rad=config.merge_odometry_sigma_rad,
        odometry_sigma_rad_per_rad=config.merge_odometry_sigma_rad_per_rad,
        report_sigma_m=config.merge_report_sigma_m,
        report_sigma_per_m=config.merge_report_sigma_per_m,
        report_sigma_rad=config.merge_report_sigma_rad,
        max_registrations=config.max_registrations,
        registrations_per_robot=config.merge_registrations_per_robot,
        registrations_per_pair=config.merge_registrations_per_robot_pair,
        precheck_m=config.merge_precheck_m,
        precheck_frac=config.merge_precheck_frac,
        registration=RegistrationParams(
            sigma_m=config.merge_registration_sigma_m, max_shift_m=config.merge_max_shift_m,
            max_mean_error=config.merge_max_mean_error or float("inf"),
            max_planar_condition=config.merge_max_condition or float("inf"),
            max_opposed_frac=config.merge_max_opposed_frac,
            viewpoint_m=(0.0, 0.0, config.camera_height_m)),
        consistency=ConsistencyParams(
            tol_m=config.merge_pcm_tol_m, tol_m_per_m=config.merge_pcm_tol_m_per_m,
            tol_rad=config.merge_pcm_tol_rad, tol_rad_per_m=config.merge_pcm_tol_rad_per_m,
            min_clique=config.merge_pcm_min_clique),
        agent_frame=config.merge_agent_frame, own_loop_gap=config.merge_own_loop_gap)


def pose_change(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """(translation m, rotation rad) between two poses."""
    xi = Pose3.Logmap(Pose3(T_a).between(Pose3(T_b)))
    return float(np.linalg.norm(xi[3:])), float(np.linalg.norm(xi[:3]))


PRECHECK_CHUNK = 512  # points per k-d tree query of the precheck


def _share_near(tree: small_gicp.KdTree, points: np.ndarray, n_all: int, near_m: float,
                frac: float) -> bool:
    """Whether (points within `near_m` of the tree) / `n_all` ≥ `frac`, queried in chunks
    and decided as soon as the rest cannot change the answer (the same answer as one query
    of them all: the share only grows with the count)."""
    near = 0
    for start in range(0, len(points), PRECHECK_CHUNK):
        if near / n_all >= frac:
            return True
        if (near + len(points) - start) / n_all < frac:
            return False
        chunk = points[start:start + PRECHECK_CHUNK]
        _, d2 = tree.batch_nearest_neighbor_search(chunk, num_threads=1)
        near += int(np.count_nonzero(np.asarray(d2) < near_m**2))
    return near / n_all >= frac


class MapMerger:
    """Pose graph state; `update(store)` returns the submap poses that changed."""

    def __init__(self, voxel_m: float, params: MergerParams | None = None) -> None:
        self.voxel_m = voxel_m  # the store's voxel keys are at this size
        self.params = params or MergerParams()
        self.priors: dict[SubmapKey, Prior] = {}
        self.odometry: list[Between] = []
        self.reports: list[Prior] = []
        self._path_m: dict[tuple[int, int], float] = {}  # (robot, epoch) → chain length so far
        self.registrations: dict[tuple[SubmapKey, SubmapKey], Between | None] = {}
        self.estimates: dict[SubmapKey, np.ndarray] = {}
        self.inliers: dict[tuple[SubmapKey, SubmapKey], bool] = {}
        self._boxes: dict[SubmapKey, tuple[int, np.ndarray]] = {}  # n, submap-frame box
        self._fine_boxes: dict[SubmapKey, tuple[int, np.ndarray]] = {}  # ... of fine points
        self._pcm_memo = ConsistencyMemo()
        self._prepared: OrderedDict[SubmapKey, tuple[int, Prepared]] = OrderedDict()
        self._epochs: dict[int, set[int]] = {}
        self._dirty = False
        # per odometry edge with both agent-frame poses: (m, rad) between the edge from the
        # reports and the exact one
        self.report_steps: list[tuple[float, float]] = []

    # -- graph building --------------------------------------------------------------------
    def _add_node(self, sm: StoredSubmap, previous: StoredSubmap | None) -> None:
        key = sm.key
        self.estimates[key] = sm.T_reported.copy()
        epochs = self._epochs.setdefault(sm.robot_id, set())
        if not epochs:
            self.priors[key] = Prior(key, sm.T_reported.copy(), self.params.prior_info)
        elif sm.epoch not in epochs or previous is None or previous.epoch != sm.epoch:
            self.priors[key] = Prior(key, sm.T_reported.copy(), self.params.restart_prior_info)
        else:
            T_a_b = self._odometry_of(previous, sm)
            if self.params.agent_frame and sm.T_odom is not None:
                self.estimates[key] = self.estimates[previous.key] @ T_a_b  # not a stale frame
            self.odometry.append(Between(previous.key, key, T_a_b, self._odometry_info(T_a_b),
                                         robust=False))
            path = self._path_m.get((sm.robot_id, sm.epoch), 0.0) + float(
                np.linalg.norm(T_a_b[:2, 3]))
            self._path_m[(sm.robot_id, sm.epoch)] = path
            if self.params.report_sigma_m > 0:
                sigma = self.params.report_sigma_m + self.params.report_sigma_per_m * path
                self.reports.append(Prior(key, sm.T_reported.copy(), info_diag(
                    [0.01, 0.01, self.params.report_sigma_rad], [sigma, sigma, 0.01])))
        epochs.add(sm.epoch)
        self._dirty = True

    def _odometry_of(self, a: StoredSubmap, b: StoredSubmap) -> np.ndarray:
        """T_a_b of consecutive submaps of one agent: exact from its own frame where it sent
        it; else from the reports, with a's corrected pose (the agent re-anchored on it)."""
        T_world_a = a.T_world_submap if a.corrected else a.T_reported
        from_reports = invert(T_world_a) @ b.T_reported
        if a.T_odom is None or b.T_odom is None:
            return from_reports
        exact = invert(a.T_odom) @ b.T_odom
        dt, dr = pose_change(from_reports, exact)
        self.report_steps.append((dt, dr))  # what the reports' edge would have got wrong
        return exact if self.params.agent_frame else from_reports

    def _chain_pose(self, sm: StoredSubmap) -> np.ndarray:
        """A submap's pose along its robot's chain, for PCM's loops."""
        if self.params.agent_frame and sm.T_odom is not None:
            return sm.T_odom
        return sm.T_reported

    def report_step_summary(self) -> str:
        """How far the odometry edges from the reports would be (or were) from the agents'
        own relative poses: corrections that reached an agent between two reports."""
        if not self.report_steps:
            return "no odometry edge with the agents' own-frame poses"
        dt, dr = np.array(self.report_steps).T
        return (f"{dt.size} odometry edges; the reports' were off by > 1 cm in "
                f"{int(np.count_nonzero(dt > 0.01))}, > 0.2 deg in "
                f"{int(np.count_nonzero(dr > np.radians(0.2)))}; max {100 * dt.max():.1f} cm, "
                f"{np.degrees(dr.max()):.2f} deg ({'not ' if not self.params.agent_frame else ''}"
                "used: edge.merge_agent_frame)")

    def _odometry_info(self, T_a_b: np.ndarray) -> np.ndarray:
        """Planar odometry information, looser the further and the more the robot turned."""
        p = self.params
        turned = abs(float(np.arctan2(T_a_b[1, 0], T_a_b[0, 0])))
        sigma_xy = p.odometry_sigma_m + p.odometry_sigma_per_m * float(np.linalg.norm(T_a_b[:2, 3]))
        sigma_yaw = p.odometry_sigma_rad + p.odometry_sigma_rad_per_rad * turned
        return info_diag([0.01, 0.01, sigma_yaw], [sigma_xy, sigma_xy, 0.01])

    def _box_of(self, sm: StoredSubmap) -> np.ndarray:
        """(2, 3) submap-frame bounding box of the agents' voxel means, kept per submap size."""
        cached = self._boxes.get(sm.key)
        if cached is None or cached[0] != sm.keys.size:
            cached = (sm.keys.size, np.stack(column_extremes(sm.points.astype(np.float64))))
            self._boxes[sm.key] = cached
        return cached[1]

    def _candidates(self, closed: list[StoredSubmap], limit: int
                    ) -> list[tuple[StoredSubmap, StoredSubmap]]:
        """The first `limit` untried pairs of closed submaps of different robots (or of one
        robot's chain, `own_loop_gap` or more apart), largest box overlap first."""
        if len(closed) < 2 or limit <= 0:
            return []
        boxes = world_boxes(np.stack([self._box_of(sm) for sm in closed]),
                            np.stack([self.estimates[sm.key] for sm in closed]))
        rows, cols, overlap = overlapping_pairs(boxes, self.params.min_overlap_m3)
        robots = np.array([sm.robot_id for sm in closed])
        other = robots[rows] != robots[cols]
        if self.params.own_loop_gap > 0:
            ids = np.array([sm.submap_id for sm in closed])
            epochs = np.array([sm.epoch for sm in closed])
            other |= ((robots[rows] == robots[cols]) & (epochs[rows] == epochs[cols])
                      & (np.abs(ids[rows] - ids[cols]) >= self.params.own_loop_gap))
        rows, cols, overlap = rows[other], cols[other], overlap[other]
        pairs = []
        for k in np.lexsort((cols, rows, -overlap)):  # largest first, then by index
            a, b = closed[rows[k]], closed[cols[k]]
            if (a.key, b.key) not in self.registrations:
                pairs.append((a, b))
                if len(pairs) == limit:
                    break
        return pairs

    def _prepared_of(self, sm: StoredSubmap) -> Prepared:
        """Downsampled cloud + covariances + KD-tree, built once per submap size."""
        cached = self._prepared.get(sm.key)
        if cached is None or cached[0] != sm.keys.size:
            points = sm.points.astype(np.float64)  # the agents' voxel means
            cached = (sm.keys.size, prepare(points, self.params.registration))
            self._prepared[sm.key] = cached
            while len(self._prepared) > self.params.max_prepared:
                self._prepared.popitem(last=False)
        self._prepared.move_to_end(sm.key)
        return cached[1]

    def _near_enough(self, target: StoredSubmap, source: StoredSubmap) -> bool:
        """Whether at least `precheck_frac` of the source's fine points lie within
        `precheck_m` of a target point, at the current estimates. Only the points inside the
        target's fine box grown by that much are searched: the others cannot be near, and
        most box-overlapping pairs are decided by that count alone."""
        tgt, src = self._prepared_of(target), self._prepared_of(source)
        T = invert(self.estimates[target.key]) @ self.estimates[source.key]
        points = np.asarray(src.fine[0].points())[:, :3] @ T[:3, :3].T + T[:3, 3]
        if not len(points):
            return self.params.precheck_frac <= 0.0
        margin = self.params.precheck_m + 1e-6  # beyond it no rounding makes a point near
        lo, hi = self._fine_box(target)
        inside = np.all((points >= lo - margin) & (points <= hi + margin), axis=1)
        if int(np.count_nonzero(inside)) / len(points) < self.params.precheck_frac:
            return False  # the same test as below, on a count at least as large
        return _share_near(tgt.fine[1], points[inside], len(points), self.params.precheck_m,
                           self.params.precheck_frac)

    def _fine_box(self, sm: StoredSubmap) -> np.ndarray:
        """(2, 3) box of the submap's fine registration points (its own frame)."""
        cached = self._fine_boxes.get(sm.key)
        if cached is None or cached[0] != sm.keys.size:
            fine = np.asarray(self._prepared_of(sm).fine[0].points())[:, :3]
            cached = (sm.keys.size, np.stack(column_extremes(fine)))
            self._fine_boxes[sm.key] = cached
        return cached[1]

    def registration_budget(self, robots: int) -> int:
        """Registrations per update for a team of this many robots with submaps: a large
        team's chains drift further and meet more teammates, and the pairs of submaps that
        overlap grow with the pairs of robots (at 24 robots and 8 per update, 837 of 1377
        submaps were never registered, and they held the warehouse's ghosts)."""
        per_robot = round(self.params.registrations_per_robot * robots)
        per_pair = round(self.params.registrations_per_pair * robots * (robots - 1) / 2)
        return max(self.params.max_registrations, per_robot, per_pair)

    def _worth_registering(self, pairs: list[tuple[StoredSubmap, StoredSubmap]], budget: int
                           ) -> list[tuple[StoredSubmap, StoredSubmap]]:
        """The first `budget` pairs that pass the precheck; the ones that fail are recorded
        as tried (None)."""
        if self.params.precheck_m <= 0:
            return pairs[:budget]
        chosen = []
        for target, source in pairs:
            if len(chosen) == budget:
                break
            if self._near_enough(target, source):
                chosen.append((target, source))
            else:
                self.registrations[(target.key, source.key)] = None
        return chosen

    def _register(self, target: StoredSubmap, source: StoredSubmap) -> None:
        T_init = invert(self.estimates[target.key]) @ self.estimates[source.key]
        result = register(self._prepared_of(target), self._prepared_of(source), T_init,
                          self.params.registration)
        edge = None
        if result is not None:
            edge = Between(target.key, source.key, result.T_target_source, result.info, True)
            self._dirty = True
        self.registrations[(target.key, source.key)] = edge
        log.debug("registration %s ← %s: %s", target.key, source.key,
                  "kept" if edge else "rejected")

    def _consistent(self, edges: list[Between], store: SubmapStore) -> list[bool]:
        """PCM over the registrations (consistency.py); each robot's chain is its reports."""
        if self.params.consistency is None:
            return [True] * len(edges)
        keys = {k for e in edges for k in (e.a, e.b)}
        subs = {k: store.submaps[k] for k in keys}
        return select(edges, {k: self._chain_pose(sm) for k, sm in subs.items()},
                      {k: (sm.robot_id, sm.epoch) for k, sm in subs.items()},
                      self.params.consistency, self._pcm_memo)

    # -- update ----------------------------------------------------------------------------
    def update(self, store: SubmapStore) -> dict[SubmapKey, np.ndarray]:
        by_robot: dict[int, list[StoredSubmap]] = {}
        for sm in store.ordered():
            by_robot.setdefault(sm.robot_id, []).append(sm)
        closed = []
        for sms in by_robot.values():
            for i, sm in enumerate(sms):
                if sm.key not in self.estimates:
                    self._add_node(sm, sms[i - 1] if i else None)
            closed += [sm for sm in sms[:-1] if sm.keys.size >= self.params.min_points]
        budget = self.registration_budget(len(by_robot))
        asked = budget if self.params.precheck_m <= 0 else self.params.max_prechecks
        for target, source in self._worth_registering(self._candidates(closed, asked), budget):
            self._register(target, source)
        edges = [e for e in self.registrations.values() if e is not None]
        if not self._dirty or not edges:
            return {}
        self._dirty = False
        kept = self._consistent(edges, store)
        self.inliers = {(e.a, e.b): False for e in edges}
        edges = [e for e, ok in zip(edges, kept, strict=True) if ok]
        if not edges:
            return {}
        result = optimize(self.estimates, [*self.priors.values(), *self.reports],
                          self.odometry + edges)
        self.inliers.update({(e.a, e.b): ok for e, ok in
                             zip(edges, result.inlier[len(self.odometry):], strict=True)})
        self.estimates = result.poses
        changed = {}
        for key, T in result.poses.items():
            dt, dr = pose_change(store.submaps[key].T_world_submap, T)
            if dt > self.params.correction_tol_m or dr > self.params.correction_tol_rad:
                changed[key] = T
        return changed
