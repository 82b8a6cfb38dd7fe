"""Fusing frame-to-map registration with wheel odometry: a planar Kalman filter on the pose.

A registration that converges is not yet a measurement to trust: facing one wall, or with a
corner cut away by the sensor's edge dropouts, GICP settles 5 cm off while the robot turns in
place, and a gate on each frame's jump alone lets such slides add up frame after frame
(house replays: 10-28 cm, bench/bench_localization.py). Here the pose estimate carries a
covariance `P` (loc frame: x, y, yaw) that grows only as the wheels can drift (per metre
driven, per radian turned: the odometry error model) and shrinks with each fused
registration. A registration is a measurement with covariance `R` (σ per axis, inflated
along the direction a degenerate scene leaves weak); it is rejected when its innovation is
implausible (Mahalanobis² above a χ² bound) and otherwise moves the pose by the Kalman gain,
so a stationary robot cannot be walked away by a run of biased alignments.

Pure: numpy in, numpy out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.geometry import T_from_xyyaw, wrap_angle, xyyaw_from_T


@dataclass(frozen=True)
class FilterParams:
    # process noise: variance added per frame, per metre driven, per radian turned
    q_m2: float = 0.001**2  # wheel slip even when stationary
    q_m2_per_m: float = 0.02**2  # 1 % random walk and 2 % scale error, generously
    q_rad2: float = 0.0005**2
    q_rad2_per_rad: float = 0.02**2  # 1 % random walk and 1 % turn-scale error
    q_rad2_per_m: float = 0.01**2  # heading bias (0.005 rad/m)
    # measurement noise of one registration (the strong directions)
    r_m: float = 0.005
    r_rad: float = 0.002
    max_weak_inflation: float = 1e4  # σ² along a degenerate direction grows by at most this
    # σ² along a weaker direction grows by (strongest / its information) to this power: above
    # 1 a registration's weak direction (along an aisle) counts for less against the wheels
    weak_inflation_power: float = 1.0
    weak_inflation_knee: float = 1.0  # ... only for the part of the ratio above this
    # ... but this power (0 = the same) until the wheels' scale is known from this many unit
    # segments pooled over the fleet: wheels not yet calibrated read as long as they are made
    weak_inflation_power_uncalibrated: float = 0.0
    calibrated_segments: float = 0.0
    chi2_gate: float = 16.27  # 3 dof, p = 0.999
    coupled_length_m: float = 0.0  # > 0: R from the whole planar information (see below)
    # re-acquisition: this many gate-rejected registrations in a row (0 = never) that agree
    # with each other on the odometry drift within these bounds are taken as the truth
    reacquire_frames: int = 3
    reacquire_tol_m: float = 0.03
    reacquire_tol_rad: float = 0.005
    # ... plus this much per radian turned and per metre driven between two of them: odometry
    # loses a turn at its own rate (1 % scale, random walk), so during a turn the drift the
    # registrations imply grows frame by frame (docs/agent.md, "A reproducible turn lost")
    reacquire_rad_per_rad: float = 0.0
    # a frame that matched fewer than this share of its points (new ground) is a weaker
    # measurement: R grows by full_overlap_frac / inlier fraction (0 = never)
    full_overlap_frac: float = 0.0
    # ... and by full_inliers / inlier count (0 = never): its information is its points'
    full_inliers: int = 0
    reacquire_m_per_m: float = 0.0
    # a registration whose position lies further from the prediction than this many σ of
    # P's position (floored at jump_floor_m) is rejected whatever its own R says: a GICP
    # local minimum 38 cm off with a large R along it passed the χ² gate, and its confident
    # yaw (3.7° wrong) went in (warehouse, 24 robots). 0 = no such test
    max_jump_sigmas: float = 0.0
    jump_floor_m: float = 0.03


def predict(P: np.ndarray, xyyaw_from: np.ndarray, xyyaw_to: np.ndarray,
            params: FilterParams) -> np.ndarray:
    """Covariance after the odometry motion `from → to` (loc frame x, y, yaw)."""
    dx, dy = xyyaw_to[0] - xyyaw_from[0], xyyaw_to[1] - xyyaw_from[1]
    d = float(np.hypot(dx, dy))
    turn = abs(float(wrap_angle(xyyaw_to[2] - xyyaw_from[2])))
    # a yaw error swings the whole motion sideways: first-order unicycle Jacobian
    F = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
    q_t = params.q_m2 + params.q_m2_per_m * d
    q_r = params.q_rad2 + params.q_rad2_per_rad * turn + params.q_rad2_per_m * d
    return F @ P @ F.T + np.diag([q_t, q_t, q_r])


def measurement_cov(H6: np.ndarray | None, yaw: float, params: FilterParams) -> np.ndarray:
    """R (loc frame) of a registration at heading `yaw` whose GICP Hessian is H6.

    small_gicp's H orders rx, ry, rz, tx, ty, tz in the body frame; its scale is not a
    covariance (the point covariances are regularised), so only its shape is used. With
    `coupled_length_m` > 0 the planar block (tx, ty, rz; z, roll, pitch marginalised) is
    compared in (x, y, L·yaw): σ² along each weaker direction, yaw-translation mixtures
    included (one far wall: turning ≈ sliding), grows by its ratio to the strongest. With 0
    only the translation block is (yaw marginalised) and yaw keeps `r_rad`."""
    if H6 is not None and params.coupled_length_m > 0:
        return _coupled_cov(np.asarray(H6), yaw, params)
    R_t = np.eye(2) * params.r_m**2
    if H6 is not None:
        H = np.asarray(H6)[np.ix_([3, 4, 2], [3, 4, 2])]
        if H[2, 2] > 0:
            Ht = H[:2, :2] - np.outer(H[:2, 2], H[2, :2]) / H[2, 2]
            R_t = _inflated(Ht, params.r_m**2, params.max_weak_inflation,
                            params.weak_inflation_power, params.weak_inflation_knee)
    rot = _rot(yaw)
    out = np.zeros((3, 3))
    out[:2, :2] = rot @ R_t @ rot.T
    out[2, 2] = params.r_rad**2
    return out


def count_inflation(inlier_frac: float, n_points: int, params: FilterParams) -> float:
    """How much weaker than R a registration is that matched fewer points than
    `full_inliers` (1: that many or more, or no count asked): R's scale is set for a room's
    frame (about a thousand inliers after downsampling), and a few hundred far points at the
    view's edges carry far less (warehouse: 210 inliers, all beyond 4 m, pulled a robot 11 cm
    back along a corridor)."""
    if params.full_inliers <= 0 or n_points <= 0:
        return 1.0
    return max(1.0, params.full_inliers / max(inlier_frac * n_points, 1.0))


def overlap_inflation(inlier_frac: float, params: FilterParams) -> float:
    """How much weaker than R a registration is that matched `inlier_frac` of its points:
    the fewer old points a frame sees, the more one mis-weighted patch moves it (AWS house: a
    robot turning into a new room accepted seven such frames, each 0.2-0.4° the same wrong
    way)."""
    if params.full_overlap_frac <= 0:
        return 1.0
    return max(1.0, params.full_overlap_frac / max(inlier_frac, 1e-3))


def _coupled_cov(H6: np.ndarray, yaw: float, params: FilterParams) -> np.ndarray:
    planar, rest = [3, 4, 2], [5, 0, 1]  # tx, ty, rz | tz, rx, ry
    A, B, C = H6[np.ix_(planar, planar)], H6[np.ix_(planar, rest)], H6[np.ix_(rest, rest)]
    try:
        Hp = A - B @ np.linalg.solve(C, B.T)
    except np.linalg.LinAlgError:
        Hp = A
    L = params.coupled_length_m
    S = np.diag([1.0, 1.0, 1.0 / L])  # (x, y, yaw) = S · (x, y, L·yaw)
    Hn = np.linalg.inv(S) @ Hp @ np.linalg.inv(S)  # information in (x, y, L·yaw)
    Rn = _inflated(Hn, params.r_m**2, params.max_weak_inflation, params.weak_inflation_power,
                   params.weak_inflation_knee)
    R_body = S @ Rn @ S
    T = np.eye(3)
    T[:2, :2] = _rot(yaw)
    return T @ R_body @ T.T


def _inflated(H: np.ndarray, sigma2: float, max_inflation: float,
              power: float = 1.0, knee: float = 1.0) -> np.ndarray:
    """σ² in every direction, times (strongest / this) information along each eigenvector,
    to `power` beyond `knee` (r ≤ knee: r; above: knee·(r / knee)^power), at most
    `max_inflation`."""
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    if w[-1] <= 0:
        return np.eye(len(w)) * sigma2 * max_inflation
    ratio = np.clip(w[-1] / np.maximum(w, w[-1] / max_inflation), 1.0, max_inflation)
    ratio = np.where(ratio > knee, knee * (ratio / knee) ** power, ratio)
    ratio = np.minimum(ratio, max_inflation)
    return V @ np.diag(sigma2 * ratio) @ V.T


def _rot(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class Fusion:
    xyyaw: np.ndarray  # (3,) fused pose, loc frame
    P: np.ndarray  # (3, 3) its covariance
    mahalanobis2: float
    accepted: bool


def fuse(xyyaw_guess: np.ndarray, P: np.ndarray, xyyaw_meas: np.ndarray, R: np.ndarray,
         params: FilterParams, R_gate: np.ndarray | None = None) -> Fusion:
    """Kalman update of the odometry guess with a registered pose (both loc frame).

    `R_gate` (default R) judges the measurement: a registration weighed down for its few
    points is still gated at its own precision, so the weighing never lets through a jump
    the gate would have stopped (a 4° turn, warehouse)."""
    innovation = np.asarray(xyyaw_meas, float) - np.asarray(xyyaw_guess, float)
    innovation[2] = wrap_angle(innovation[2])
    S = P + R
    S_gate = S if R_gate is None else P + R_gate
    d2 = float(innovation @ np.linalg.solve(S_gate, innovation))
    if d2 > params.chi2_gate or _jumped(innovation, P, params):
        return Fusion(np.asarray(xyyaw_guess, float), P, d2, False)
    K = P @ np.linalg.inv(S)
    xyyaw = np.asarray(xyyaw_guess, float) + K @ innovation
    xyyaw[2] = wrap_angle(xyyaw[2])
    I_K = np.eye(3) - K
    P_new = I_K @ P @ I_K.T + K @ R @ K.T  # Joseph form: stays symmetric positive
    return Fusion(xyyaw, P_new, d2, True)


def _jumped(innovation: np.ndarray, P: np.ndarray, params: FilterParams) -> bool:
    if params.max_jump_sigmas <= 0.0:
        return False
    sigma_m = float(np.sqrt(P[0, 0] + P[1, 1] + params.jump_floor_m**2))
    return float(np.hypot(innovation[0], innovation[1])) > params.max_jump_sigmas * sigma_m


def agree(xyyaw_reg: list[np.ndarray], xyyaw_odom: list[np.ndarray],
          params: FilterParams) -> bool:
    """Whether rejected registrations (T_loc_base, x, y, yaw) tell one story with odometry.

    The gate rejects a registration far from the estimate; when the estimate is what went
    wrong (a slide accepted earlier, odometry that turned more than modelled), every later
    registration is rejected too, and the map is built at a wrong pose. Registrations whose
    relative motions match the odometry's between them, frame after frame, while the estimate
    does not, are the evidence that the estimate is off (house and AWS replays: 2.6-5.3° of
    yaw error held by the gate while each registration asked for it back, within 0.15° of
    each other). A slide in progress moves the registrations while the wheels do not."""
    n = params.reacquire_frames
    if n <= 0 or len(xyyaw_reg) < n:
        return False
    regs = [T_from_xyyaw(*r) for r in xyyaw_reg[-n:]]
    odoms = np.asarray(xyyaw_odom[-n:], float)
    turned = np.concatenate([[0.0], np.cumsum(np.abs(wrap_angle(np.diff(odoms[:, 2]))))])
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(odoms[:, :2], axis=0).T))])
    for i in range(n):
        for j in range(i + 1, n):
            odom_ij = T_from_xyyaw(*(_relative(odoms[i], odoms[j])))
            ex, ey, eyaw = xyyaw_from_T(np.linalg.inv(odom_ij) @ np.linalg.inv(regs[i]) @ regs[j])
            tol_m = params.reacquire_tol_m + params.reacquire_m_per_m * (driven[j] - driven[i])
            tol_rad = params.reacquire_tol_rad + params.reacquire_rad_per_rad * (
                turned[j] - turned[i])
            if np.hypot(ex, ey) > tol_m or abs(wrap_angle(eyaw)) > tol_rad:
                return False
    return True


def _relative(xyyaw_from: np.ndarray, xyyaw_to: np.ndarray) -> tuple[float, float, float]:
    """(dx, dy, dyaw) from one planar pose to another, in the first's frame."""
    c, s = np.cos(xyyaw_from[2]), np.sin(xyyaw_from[2])
    wx, wy = xyyaw_to[0] - xyyaw_from[0], xyyaw_to[1] - xyyaw_from[1]
    return c * wx + s * wy, -s * wx + c * wy, float(wrap_angle(xyyaw_to[2] - xyyaw_from[2]))


def _translation_information(H6: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Eigenvalues (ascending) and eigenvectors of GICP's planar translation information once
    yaw is marginalised out (Schur complement; small_gicp orders rx, ry, rz, tx, ty, tz,
    body-frame perturbation), or None without yaw information."""
    H = np.asarray(H6)[np.ix_([3, 4, 2], [3, 4, 2])]
    if H[2, 2] <= 0:
        return None
    Ht = H[:2, :2] - np.outer(H[:2, 2], H[2, :2]) / H[2, 2]
    return np.linalg.eigh(0.5 * (Ht + Ht.T))


def translation_information_ratio(H6: np.ndarray) -> float:
    """Weakest / strongest planar translation information of a registration (1: as strong
    along every direction; along an aisle or one wall, ~0.01)."""
    info = _translation_information(H6)
    if info is None or info[0][1] <= 0:
        return 0.0
    return float(max(info[0][0], 0.0) / info[0][1])


def drop_weak_translation(step: np.ndarray, H6: np.ndarray, ratio: float) -> np.ndarray:
    """The (dx, dy, dyaw) body-frame step without its part along a degenerate direction.

    Between shelf rows or along one wall the translation information
    (`_translation_information`) is a hundred times weaker along the aisle than across it,
    and GICP then walks the pose along the aisle by ~2 cm a frame; odometry is the better
    guess there (solution remapping, Zhang et al. ICRA 2016)."""
    info = _translation_information(H6)
    if info is None:
        return step
    w, V = info
    if w[1] <= 0 or w[0] >= ratio * w[1]:
        return step
    weak = V[:, 0]
    out = step.copy()
    out[:2] -= weak * float(weak @ step[:2])
    return out
