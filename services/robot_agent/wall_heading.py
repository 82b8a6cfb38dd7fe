"""Absolute heading from the directions of the walls a frame sees (a Manhattan-frame prior).

Every other heading source the agent has is relative: wheel odometry and scan-to-scan turns
accumulate error, and registration against the robot's own map carries whatever error the map
was built with. The failures that remain (docs/agent.md, "Ten seeds") are a slow yaw creep of
0.5-1° while the robot turns into half-seen ground, each registration agreeing with the last.
Indoors, most wall area runs along a few directions; once the robot has learned them (from its
first frames, where its pose is known), a frame's walls give its heading modulo 90° directly,
with no history to inherit an error from (the drift-free rotation of Manhattan-frame visual
odometry: Kim et al., "Linear RGB-D SLAM for planar environments", ECCV 2018).

Per frame: each downsampled point's covariance (small_gicp's for GICP, 10 neighbours: its
surface normal n with eigenvalues 1e-3, 1, 1, i.e. I − 0.999·n·nᵀ) restricted to the floor plane
is a line along a vertical surface when its smaller eigenvalue is a small share of
the larger; its direction θ (base frame) is folded modulo 90° (e^{4iθ}). The frame's direction
is their circular mean, refined over the points within `select_rad` of it. On recorded frames
of three worlds (bench/bench_wall_heading.py) the error against the truth is 0.02-0.1° median,
0.06-0.38° p90, with rare 1-5° outliers in frames of few wall points, which the filter's χ²
gate and `min_points` keep out.

Pure: numpy in, numpy out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.common.geometry import wrap_angle

QUARTER = np.pi / 2
GICP_SMALL_EIGENVALUE = 1e-3  # small_gicp's covariance along a point's normal (others 1)


@dataclass(frozen=True)
class WallHeadingParams:
    max_linearity: float = 0.15  # smaller / larger eigenvalue of a wall point's xy covariance
    min_vertical: float = 0.3  # its z variance over the larger xy one: a vertical surface
    min_z_m: float = 0.1  # points below are floor and skirting
    select_rad: float = np.radians(3.0)  # points this close to the frame's direction refine it
    min_points: int = 100  # wall points needed for a measurement
    # refinement by straight wall segments: points within `family_rad` of a direction (or its
    # perpendicular), split where their offsets along the normal jump by over `gap_m`, and
    # where the points along the line leave a gap of over `along_gap_m` (0: never): two walls
    # in line, metres apart, are centimetres apart across (depth noise at 5 m is 1.3 cm),
    # and a line through both turns by their offset over their distance (AWS house: two
    # patches 7 m apart made one 7.5 m "segment" 1.6° off; the filter took 1.2° of it)
    family_rad: float = np.radians(4.0)
    gap_m: float = 0.03
    along_gap_m: float = 1.0
    segment_min_points: int = 15
    segment_min_length_m: float = 0.5
    segment_max_rms_m: float = 0.01  # straighter than this, or it is not one wall
    min_segments: int = 1
    # the segments' direction is kept only this close to the points' own: where they differ,
    # one long straight thing that is not a wall (a bed, a rotated cabinet) decides the lines
    agree_with_points_rad: float = np.radians(0.3)
    sigma_rad: float = np.radians(0.2)  # σ of a frame's heading (rotated furniture, 0.1-0.6°
    # in the AWS house, dominates some frames)
    chi2_gate: float = 10.83  # 1 dof, p = 0.999
    # the world's direction is learned from the first `learn_frames` frames, each weighted by
    # 1 / (σ² + the filter's yaw variance): the start pose is known, and the first turn's
    # frames count for less as odometry loses the turn
    learn_frames: int = 20
    learn_max_sigma_rad: float = np.radians(1.0)
    # teammates' learned directions (one world, one direction): a robot whose own lies more
    # than this from the robots' median takes the mean of those within it; None: own only
    team_inlier_rad: float | None = np.radians(0.3)
    # this many measurements in a row rejected by the gate, their offsets from odometry within
    # `reacquire_spread_rad` of each other: the filter's heading is wrong, not the walls
    # (every frame's walls agree); P's yaw variance grows to take them. None: never
    reacquire_frames: int | None = 5
    reacquire_spread_rad: float = np.radians(0.5)


@dataclass(frozen=True)
class WallDirection:
    angle_rad: float  # the walls' direction in the base frame, in [−45°, 45°)
    sigma_rad: float
    n_points: int


def fold(angle: np.ndarray | float) -> np.ndarray | float:
    """An angle modulo 90°, in [−45°, 45°)."""
    return wrap_angle(4.0 * np.asarray(angle)) / 4.0


def gicp_covariance_terms(normals_base: np.ndarray,
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(cxx, cyy, cxy, czz), each (N,), of the covariances small_gicp gives its points for
    GICP, from their unit normals (N, 3) (zero where a point had too few neighbours: then
    the identity, as small_gicp sets it). Taken from the normals, an (N, 3) array, because
    `PointCloud.covs()` builds a list of N 4×4 arrays: 7 % of an agent's CPU."""
    nx, ny, nz = normals_base[:, 0], normals_base[:, 1], normals_base[:, 2]
    flat = 1.0 - GICP_SMALL_EIGENVALUE
    return 1.0 - flat * nx * nx, 1.0 - flat * ny * ny, -flat * nx * ny, 1.0 - flat * nz * nz


def wall_direction(points_base: np.ndarray, normals_base: np.ndarray,
                   params: WallHeadingParams) -> WallDirection | None:
    """The dominant wall direction (mod 90°) of one frame: points (N, 3) and their unit
    normals (N, 3), base frame; None when too few points lie on vertical surfaces."""
    cxx, cyy, cxy, czz = gicp_covariance_terms(normals_base)
    half_tr = 0.5 * (cxx + cyy)
    disc = np.sqrt(np.maximum(half_tr**2 - (cxx * cyy - cxy**2), 0.0))
    large, small = half_tr + disc, half_tr - disc
    wall = ((small < params.max_linearity * large) & (czz > params.min_vertical * large)
            & (points_base[:, 2] > params.min_z_m))
    if np.count_nonzero(wall) < params.min_points:
        return None
    theta = 0.5 * np.arctan2(2.0 * cxy[wall], cxx[wall] - cyy[wall])  # the line's direction
    mean = float(np.angle(np.exp(4j * theta).sum()) / 4.0)
    dev = fold(theta - mean)
    near = np.abs(dev) < params.select_rad
    n = int(np.count_nonzero(near))
    if n < params.min_points:
        return None
    coarse = float(fold(mean + float(np.angle(np.exp(4j * dev[near]).sum()) / 4.0)))
    xy = points_base[wall, :2]
    refined = _segments_direction(xy, theta, coarse, params)
    if refined is None:
        return None
    refined = _segments_direction(xy, theta, refined, params)  # regrouped around the better one
    if refined is None or abs(float(fold(refined - coarse))) > params.agree_with_points_rad:
        return None
    return WallDirection(float(fold(refined)), params.sigma_rad, n)


def _segments_direction(xy: np.ndarray, theta: np.ndarray, direction: float,
                        params: WallHeadingParams) -> float | None:
    """`direction` refined by the straight wall segments along it and its perpendicular: a
    point's covariance gives its line to a few tenths of a degree, a 2 m segment's points to a
    hundredth (house frames: 0.005° median error against 0.05°). The segments' slopes are
    combined by their weighted median."""
    slopes, weights = [], []
    for axis in (direction, direction + QUARTER):
        member = np.abs(wrap_angle(2.0 * (theta - axis)) / 2.0) < params.family_rad
        if np.count_nonzero(member) < params.segment_min_points:
            continue
        c, s = np.cos(axis), np.sin(axis)
        along = c * xy[member, 0] + s * xy[member, 1]
        across = -s * xy[member, 0] + c * xy[member, 1]
        order = np.argsort(across)
        along, across = along[order], across[order]
        for u, v in _contiguous(_long_groups(along, across, params), params.along_gap_m):
            n = len(u)  # sums as u.mean() and np.mean take them, without their overhead
            if n < params.segment_min_points or u.max() - u.min() < params.segment_min_length_m:
                continue
            du, dv = u - np.add.reduce(u) / n, v - np.add.reduce(v) / n
            suu = float(du @ du)
            slope = float(du @ dv) / suu
            r = dv - slope * du
            rms = math.sqrt(float(np.add.reduce(r * r)) / n)
            if rms > params.segment_max_rms_m:
                continue
            slopes.append(slope)
            weights.append(suu / max(rms, 0.003) ** 2)
    if len(slopes) < params.min_segments:
        return None
    slope_arr, w = np.array(slopes), np.array(weights)
    order = np.argsort(slope_arr)
    cum = np.cumsum(w[order])
    return direction + float(slope_arr[order][np.searchsorted(cum, 0.5 * cum[-1])])


def _long_groups(along: np.ndarray, across: np.ndarray, params: WallHeadingParams,
                 ) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """(along, across, extent along) of the runs, in order across the line, between jumps of
    over `gap_m`, keeping only those with enough points and length to hold a segment (a split
    along the line only shortens a run): the rest never reach a fit, and most are a few points."""
    bounds = np.concatenate(([0], np.flatnonzero(np.diff(across) > params.gap_m) + 1,
                             [len(across)]))
    lo, hi = bounds[:-1], bounds[1:]
    big = np.flatnonzero(hi - lo >= params.segment_min_points)
    if not len(big):
        return []
    extent = np.maximum.reduceat(along, lo)[big] - np.minimum.reduceat(along, lo)[big]
    return [(along[lo[i]:hi[i]], across[lo[i]:hi[i]], float(e))
            for i, e in zip(big, extent, strict=True) if e >= params.segment_min_length_m]


def _contiguous(groups: list[tuple[np.ndarray, np.ndarray, float]], max_gap_m: float,
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each (along, across) group split where its points, in order along the line, leave a
    gap over `max_gap_m` (≤ 0: the groups as they are). A group no longer than that has no
    such gap and is not sorted."""
    if max_gap_m <= 0:
        return [(u, v) for u, v, _ in groups]
    out = []
    for u, v, extent in groups:
        if extent <= max_gap_m:
            out.append((u, v))
            continue
        order = np.argsort(u, kind="stable")
        cuts = np.flatnonzero(np.diff(u[order]) > max_gap_m) + 1
        if len(cuts) == 0:  # as it came: the fit's sums in the same order, to the last bit
            out.append((u, v))
            continue
        out.extend(zip(np.split(u[order], cuts), np.split(v[order], cuts), strict=True))
    return out


def team_direction(own_rad: float | None, team_rad: list[float],
                   inlier_rad: float) -> float | None:
    """The world's wall direction (mod 90°) from robots' learned ones: their median (the one
    nearest the others, the robot's own on a tie), then the mean of those within
    `inlier_rad` of it. A robot whose learning frames carried a yaw error learned the world
    that far off and holds its heading to it; among teammates it is the outlier (warehouse,
    24 robots: three learned 0.5-1.3° off, and carried 88 % of the ghost voxels)."""
    values = ([own_rad] if own_rad is not None else []) + list(team_rad)
    if not values:
        return None
    d = np.asarray(values, dtype=float)
    spread = np.abs(fold(d[:, None] - d[None, :])).sum(axis=1)
    median = float(d[int(np.argmin(spread))])  # argmin: the first, own, on a tie
    dev = fold(d - median)
    return float(fold(median + float(np.mean(dev[np.abs(dev) <= inlier_rad]))))


def heading_from(direction: WallDirection, world_rad: float, yaw_pred: float) -> float:
    """The heading the walls give: the world's wall direction minus the frame's, on the
    branch (of four, 90° apart) nearest the predicted heading."""
    return float(yaw_pred + fold(world_rad - direction.angle_rad - yaw_pred))


@dataclass(frozen=True)
class HeadingFusion:
    xyyaw: np.ndarray  # (3,) loc frame
    P: np.ndarray  # (3, 3)
    mahalanobis2: float
    accepted: bool


def fuse_heading(xyyaw: np.ndarray, P: np.ndarray, yaw_meas: float, sigma_rad: float,
                 chi2_gate: float) -> HeadingFusion:
    """Kalman update of (x, y, yaw) with a heading measurement: position moves too, by how
    its error correlates with the heading's (a turn's error swings the path after it)."""
    innovation = float(wrap_angle(yaw_meas - xyyaw[2]))
    s = float(P[2, 2]) + sigma_rad**2
    d2 = innovation**2 / s
    if d2 > chi2_gate:
        return HeadingFusion(np.asarray(xyyaw, float), P, d2, False)
    k = P[:, 2] / s
    out = np.asarray(xyyaw, float) + k * innovation
    out[2] = wrap_angle(out[2])
    I_K = np.eye(3) - np.outer(k, [0.0, 0.0, 1.0])
    P_new = I_K @ P @ I_K.T + np.outer(k, k) * sigma_rad**2  # Joseph form
    return HeadingFusion(out, P_new, d2, True)


class WallHeading:
    """The world's wall direction, learned while the pose is known, then a heading each frame."""

    def __init__(self, params: WallHeadingParams) -> None:
        self.params = params
        self.world_rad: float | None = None
        self._learned = 0j  # Σ e^{4i·direction} / σ² over the frames learned from
        self.team: dict[int, float] = {}  # teammates' learned directions, this robot's frame
        self.n_frames = 0
        self.n_fused = 0
        self.n_rejected = 0
        self.n_reacquired = 0
        self._rejected: list[float] = []  # innovations of the rejections in a row

    @property
    def own_rad(self) -> float | None:
        """This robot's learned direction once learning is over (what teammates get)."""
        if self.n_frames < self.params.learn_frames or self._learned == 0j:
            return None
        return float(np.angle(self._learned) / 4.0)

    def receive(self, robot_id: int, direction_world_rad: float | None,
                yaw_world_loc: float) -> None:
        """A teammate's learned direction (world frame), kept in this robot's frame as it
        first arrives. A learned direction never changes, so a later change of the pair is
        a change of the edge's corrections (`yaw_world_loc`, the sender's or this robot's),
        not of the walls: following it turned a wrong +0.73° correction into this robot's
        own heading (AWS house, view gain, seed 4: a ghost)."""
        if direction_world_rad is not None and robot_id not in self.team:
            self.team[robot_id] = float(fold(direction_world_rad - yaw_world_loc))

    def shared(self, yaw_world_loc: float) -> float | None:
        """This robot's learned direction in the world frame, for its teammates."""
        own = self.own_rad
        return None if own is None else float(fold(own + yaw_world_loc))

    def _world_after_learning(self, P: np.ndarray) -> tuple[float | None, np.ndarray]:
        """The direction to fuse against: its own, unless the team's says it learned off
        (then P grows by the change: a robot that held its heading to a direction δ off has a
        heading δ off). Agreeing robots keep their own, so a team that learned alike (every
        3-robot mission so far: within 0.2°) runs exactly as without teammates."""
        inlier = self.params.team_inlier_rad
        if inlier is None:
            return self.world_rad, P
        own = self.own_rad
        world = team_direction(own, list(self.team.values()), inlier)
        if own is not None and world is not None and abs(float(fold(own - world))) <= inlier:
            world = own
        if world is not None and self.world_rad is not None:
            delta = float(fold(world - self.world_rad))
            if delta != 0.0:
                P = P.copy()
                P[2, 2] += delta**2
        self.world_rad = world
        return world, P

    def update(self, xyyaw: np.ndarray, P: np.ndarray, points_base: np.ndarray,
               normals_base: np.ndarray, yaw_odom: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """(x, y, yaw) and P after this frame's walls (unchanged when they say nothing).
        `yaw_odom`: the frame's odometry heading, against which rejected headings are
        compared for re-acquisition (the estimate itself may jump meanwhile)."""
        self.n_frames += 1
        direction = wall_direction(points_base, normals_base, self.params)
        if direction is None:
            return xyyaw, P
        if self.n_frames <= self.params.learn_frames:
            var = max(float(P[2, 2]), 0.0)
            if var <= self.params.learn_max_sigma_rad**2:
                self._learned += np.exp(4j * (xyyaw[2] + direction.angle_rad)) / (
                    direction.sigma_rad**2 + var)
                self.world_rad = float(np.angle(self._learned) / 4.0)
            return xyyaw, P
        world, P = self._world_after_learning(P)
        if world is None:
            return xyyaw, P
        yaw = heading_from(direction, world, float(xyyaw[2]))
        fusion = fuse_heading(xyyaw, P, yaw, direction.sigma_rad, self.params.chi2_gate)
        if fusion.accepted:
            self.n_fused += 1
            self._rejected = []
            return fusion.xyyaw, fusion.P
        self.n_rejected += 1
        P = self._reacquire(P, float(wrap_angle(yaw - xyyaw[2])),
                            float(wrap_angle(yaw - yaw_odom)))
        if P is None:
            return xyyaw, fusion.P
        self.n_reacquired += 1
        fusion = fuse_heading(xyyaw, P, yaw, direction.sigma_rad, np.inf)
        return fusion.xyyaw, fusion.P

    def _reacquire(self, P: np.ndarray, innovation: float, offset: float) -> np.ndarray | None:
        """P with the yaw variance the walls' persistent disagreement calls for, or None
        while they have not disagreed alike often enough: `reacquire_frames` rejected
        headings in a row whose offsets from odometry's heading (`offset`) agree (a robot
        that turned into new ground registers its frames to the map it built meanwhile, and
        the gate, trusting that, rejects every wall heading that would bring it back)."""
        k = self.params.reacquire_frames
        if k is None:
            return None
        self._rejected = (self._rejected[-(k - 1):] if k > 1 else []) + [offset]
        recent = np.array(self._rejected)
        if len(recent) < k or np.ptp(recent) > self.params.reacquire_spread_rad:
            return None
        self._rejected = []
        P = P.copy()
        P[2, 2] += innovation**2
        return P
