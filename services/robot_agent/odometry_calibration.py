"""Online calibration of wheel odometry's systematic errors against registrations.

Wheel odometry errs two ways: at random (slip, a random walk) and systematically (a wheel
radius off by a few per cent scales every distance; unequal radii bend a straight drive into
an arc and scale every turn). Over a mission the systematic part dominates (2 % of a 10 m
aisle is 20 cm; 0.005 rad/m over 5 m is 1.4°), and it is the same on every metre, so it can
be learned: between two frames that registered well against the map, the registered motion is
the truth within millimetres, and the odometry's is the truth through the error model

    measured translation = (1 + scale) · true translation
    measured turn        = (1 + turn_scale) · true turn + heading_bias · signed distance

Least squares over such segments, with a prior at "no error" worth `prior_segments` segments,
gives the three parameters (Censi et al., "Simultaneous calibration of odometry and sensor
parameters for mobile robots", T-RO 2013, without the sensor part); the agent integrates
corrected increments. Segments the current model explains badly (a registration that slid)
are left out.

Robots of one model share much of their wheels' error: with `fleet_weight` > 0 an agent adds
its teammates' own segments (their normal equations, `own_stats`, sent with their poses)
weighed by it, so a robot that has not yet closed a segment of its own (along an aisle,
registrations are too weak to end one) drives on the fleet's estimate instead of raw
odometry. 1 pools them fully (the same wheels); each agent's sums hold its own segments only,
so no evidence is counted twice.

Where robots' wheels differ, pooling fully hands every robot the fleet's mean. With
`fleet_prior_segments` > 0 the teammates' pooled fit is instead the centre of the prior, which
then weighs that many unit segments more than the "no error" one did: a robot with no segment
of its own drives on the fleet's estimate, and its own segments take over as they outnumber
the prior (a hierarchical model: the fleet's wheels as the prior of each robot's). With
`fleet_prior_from_spread` the prior's weight is learned from how much the teammates' own fits
differ beyond their sampling noise (the between-robot variance τ², DerSimonian-Laird, per
parameter): wheels alike give a prior worth up to `fleet_prior_max_segments`, wheels that
differ one no heavier than `fleet_prior_segments` (empirical Bayes).

Pure: numpy in, numpy out; the state is a small accumulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from services.common.geometry import wrap_angle


@dataclass(frozen=True)
class CalibrationParams:
    segment_m: float = 1.0  # a segment closes at the first good frame this far driven ...
    segment_rad: float = 1.0  # ... or this much turned since the segment's first
    max_segment_m: float = 5.0  # longer ones (no good frame for long) are dropped
    prior_segments: float = 2.0  # the "no error" prior weighs this many unit segments
    # per-segment noise: registration at both ends plus odometry's random walk
    reg_sigma_m: float = 0.01
    reg_sigma_rad: float = 0.004
    walk_m2_per_m: float = 0.01**2
    walk_rad2_per_rad: float = 0.01**2
    outlier_sigmas: float = 4.0  # residuals beyond this many σ of the model are left out
    min_segments_for_outliers: int = 5
    max_abs_scale: float = 0.1  # estimates are clamped to plausible wheels
    max_abs_bias_rad_per_m: float = 0.05
    # a good registration (a segment's end): matched this share of its points, and its
    # weakest translation direction at most this many times weaker than its strongest
    min_inlier_frac: float = 0.7
    max_weak_ratio: float = 10.0
    fleet_weight: float = 0.0  # teammates' segments count this much each (0: own only)
    # the teammates' pooled fit is a prior worth this many unit segments (0: none)
    fleet_prior_segments: float = 0.0
    # ... or, with this, 1 / τ² unit segments (at least the above, at most the cap) once at
    # least `fleet_spread_min_teammates` teammates have fits to compare
    fleet_prior_from_spread: bool = False
    fleet_prior_max_segments: float = 10_000.0
    fleet_spread_min_teammates: int = 5
    # a segment's registered motion from its two end frames aligned to each other, not from
    # their poses against the map: the map the end frame meets was built during the segment,
    # on the uncorrected wheels, and pulls the end back toward them (localization.py)
    frame_pairs: bool = False
    pair_max_corr_m: float = 0.3
    pair_max_iterations: int = 30
    # ... kept only this close (m, rad) to the motion the map gives: shelves repeat, and a
    # pair can lock on the next one (35 cm off in a replay)
    pair_gate_m: float = 0.05
    pair_gate_rad: float = 0.02
    # a segment's odometry chord from its increments with the turn errors taken out (the
    # current estimate), not from the two raw poses: the wheels over-turn by the turn scale
    # on every turn, which bends the raw path and shortens its chord to first order in the
    # turn (a 90° corner between two 2.5 m legs: 0.8 % short at a 1 % turn scale), so the
    # scale fitted from raw chords falls short of the wheels' (warehouse recording: 1.86 %
    # of 2 % from the truth's chords, 1.56 % over 30 s windows; docs/agent.md)
    turn_corrected_chords: bool = True


@dataclass(frozen=True)
class OdometryErrors:
    scale: float = 0.0  # relative error of distance travelled
    turn_scale: float = 0.0  # relative error of angle turned
    heading_bias_rad_per_m: float = 0.0  # yaw added per metre driven forward


NO_ERRORS = OdometryErrors()
STATS = 7  # the numbers of `Calibration.own_stats`


def is_good_registration(inlier_frac: float, R: np.ndarray, params: CalibrationParams) -> bool:
    """Whether a fused registration (loc-frame covariance R) can end a segment: frames of new
    ground or of one wall slide along what they cannot see."""
    w = np.linalg.eigvalsh(0.5 * (R[:2, :2] + R[:2, :2].T))
    return inlier_frac >= params.min_inlier_frac and w[1] <= params.max_weak_ratio * w[0]


def signed_distance(increment: np.ndarray) -> float:
    """Distance of one (dx, dy, dyaw) increment, negative when driven backwards."""
    return math.copysign(math.hypot(increment[0], increment[1]), increment[0])


def corrected_increment(increment: np.ndarray, errors: OdometryErrors) -> np.ndarray:
    """The true (dx, dy, dyaw) an odometry increment stands for, under the error model."""
    k = 1.0 + errors.scale
    dx, dy = increment[0] / k, increment[1] / k
    dyaw = (increment[2] - errors.heading_bias_rad_per_m * signed_distance(
        np.array([dx, dy]))) / (1.0 + errors.turn_scale)
    return np.array([dx, dy, dyaw])


def turn_corrected_increment(increment: np.ndarray, errors: OdometryErrors) -> np.ndarray:
    """An odometry increment with only its turn corrected (turn scale, heading bias): its
    translation keeps the wheels' scale, which the segments measure."""
    return corrected_increment(increment, replace(errors, scale=0.0))


@dataclass(frozen=True)
class Segment:
    """Odometry and registration between two well-registered frames."""

    odom_chord_m: float  # straight-line odometry displacement
    reg_chord_m: float  # the registered one
    odom_turn_rad: float  # signed sum of odometry's turn increments (unwrapped)
    reg_turn_rad: float  # registered turn, unwrapped next to the odometry's
    signed_distance_m: float  # odometry's distance driven, backwards negative
    driven_m: float  # odometry's |distance| summed
    turned_rad: float  # odometry's |turn| summed


@dataclass
class Calibration:
    """Normal equations of the two fits (scale; turn scale and heading bias)."""

    params: CalibrationParams
    errors: OdometryErrors = NO_ERRORS
    n_used: int = 0
    n_rejected: int = 0
    _scale_num: float = 0.0
    _scale_den: float = 0.0
    _turn_normal: np.ndarray = field(default_factory=lambda: np.zeros((2, 2)))
    _turn_rhs: np.ndarray = field(default_factory=lambda: np.zeros(2))
    _fleet: np.ndarray = field(default_factory=lambda: np.zeros(STATS))  # teammates' sums
    _teammates: dict[int, np.ndarray] = field(default_factory=dict)  # their latest sums
    # the fleet prior's weight in unit segments (scale, turn scale, bias) of the last fit
    fleet_prior_weight: np.ndarray | None = None

    def own_stats(self) -> np.ndarray:
        """(7,) this robot's own normal equations: scale numerator and denominator, turn
        normal matrix (xx, xy, yy) and right-hand side; what teammates pool."""
        n, r = self._turn_normal, self._turn_rhs
        return np.array([self._scale_num, self._scale_den, n[0, 0], n[0, 1], n[1, 1],
                         r[0], r[1]])

    def pooled_segments(self) -> float:
        """This robot's and its teammates' segments so far, in unit (1 m) segments of the
        scale's evidence: how well the fleet knows its wheels' scale yet."""
        var_t, _ = unit_variances(self.params)
        return float((self._scale_den + self._fleet[1]) * var_t)

    def set_fleet(self, teammates_stats: np.ndarray) -> None:
        """The sum of the teammates' `own_stats`; weighed by `fleet_weight` in the fit."""
        self._fleet = np.asarray(teammates_stats, float).reshape(STATS).copy()
        self.errors = self._solve()

    def receive(self, robot_id: int, stats: list[float] | None) -> None:
        """A teammate's latest `own_stats` (from its pose); the fit is redone when they
        changed. Kept per teammate: each sends its running sums, not increments."""
        if stats is None:
            return
        new = np.asarray(stats, float)
        last = self._teammates.get(robot_id)
        if last is not None and np.array_equal(last, new):
            return
        self._teammates[robot_id] = new
        # summed in robot order, not arrival order: the same seed gives the same fit
        self.set_fleet(np.sum([self._teammates[r] for r in sorted(self._teammates)], axis=0))

    def shared(self) -> list[float] | None:
        """`own_stats` for this robot's pose when the fleet pools them, else None."""
        p = self.params
        pooled = p.fleet_weight > 0 or p.fleet_prior_segments > 0
        return [float(v) for v in self.own_stats()] if pooled else None

    def add(self, seg: Segment) -> bool:
        """Fit the segment in, unless the current model says it is an outlier."""
        p = self.params
        if seg.driven_m > p.max_segment_m:
            return False
        var_t = 2 * p.reg_sigma_m**2 + p.walk_m2_per_m * seg.driven_m
        var_r = 2 * p.reg_sigma_rad**2 + p.walk_rad2_per_rad * seg.turned_rad
        e = self.errors
        r_t = seg.odom_chord_m - (1 + e.scale) * seg.reg_chord_m
        r_r = seg.odom_turn_rad - (1 + e.turn_scale) * seg.reg_turn_rad \
            - e.heading_bias_rad_per_m * seg.signed_distance_m
        if self.n_used >= p.min_segments_for_outliers and (
                r_t**2 > p.outlier_sigmas**2 * var_t or r_r**2 > p.outlier_sigmas**2 * var_r):
            self.n_rejected += 1
            return False
        self._scale_num += seg.reg_chord_m * (seg.odom_chord_m - seg.reg_chord_m) / var_t
        self._scale_den += seg.reg_chord_m**2 / var_t
        x = np.array([seg.reg_turn_rad, seg.signed_distance_m])
        self._turn_normal += np.outer(x, x) / var_r
        self._turn_rhs += x * (seg.odom_turn_rad - seg.reg_turn_rad) / var_r
        self.n_used += 1
        self.errors = self._solve()
        return True

    def _solve(self) -> OdometryErrors:
        p = self.params
        own = self.own_stats() + p.fleet_weight * self._fleet
        if p.fleet_prior_segments <= 0 or not self._fleet.any():
            return self._fit(own)
        fleet = self._fit(self._fleet)
        centre = np.array([fleet.scale, fleet.turn_scale, fleet.heading_bias_rad_per_m])
        weight = np.full(3, p.fleet_prior_segments)
        if p.fleet_prior_from_spread and len(self._teammates) >= p.fleet_spread_min_teammates:
            weight = fleet_prior_weights(
                np.array([self._teammates[r] for r in sorted(self._teammates)]), p)
        self.fleet_prior_weight = weight
        return self._fit(own, centre, weight)

    def _fit(self, stats: np.ndarray, centre: np.ndarray | None = None,
             centre_segments: float | np.ndarray = 0.0) -> OdometryErrors:
        """Errors from summed `own_stats`-shaped normal equations and a prior of
        `prior_segments` + `centre_segments` unit segments (1 m, 1 rad) at the nominal noise
        (one weight, or one per parameter), centred on "no error" or on `centre` (scale, turn
        scale, heading bias)."""
        p = self.params
        var_t, var_r = unit_variances(p)
        n = p.prior_segments + np.broadcast_to(np.asarray(centre_segments, float), (3,))
        c = np.zeros(3) if centre is None else n * centre
        scale = (stats[0] + c[0] / var_t) / (stats[1] + n[0] / var_t)
        normal = np.array([[stats[2], stats[3]], [stats[3], stats[4]]]) + np.diag(n[1:] / var_r)
        rhs = stats[5:7] + c[1:3] / var_r
        try:
            turn_scale, bias = np.linalg.solve(normal, rhs)
        except np.linalg.LinAlgError:  # no prior, and no turn yet to tell the two apart
            turn_scale, bias = np.linalg.lstsq(normal, rhs, rcond=None)[0]
        return OdometryErrors(
            scale=float(np.clip(scale, -p.max_abs_scale, p.max_abs_scale)),
            turn_scale=float(np.clip(turn_scale, -p.max_abs_scale, p.max_abs_scale)),
            heading_bias_rad_per_m=float(np.clip(bias, -p.max_abs_bias_rad_per_m,
                                                 p.max_abs_bias_rad_per_m)),
        )


def unit_variances(params: CalibrationParams) -> tuple[float, float]:
    """Variances of one unit segment's (1 m, 1 rad) translation and turn residuals."""
    return (2 * params.reg_sigma_m**2 + params.walk_m2_per_m,
            2 * params.reg_sigma_rad**2 + params.walk_rad2_per_rad)


def between_variance(estimates: np.ndarray, weights: np.ndarray) -> float:
    """DerSimonian-Laird: the variance of the true values behind `estimates` (k,), each known
    to its `weights` (inverse sampling variances), beyond what their sampling noise explains."""
    k = len(estimates)
    if k < 2:
        return math.inf
    total = float(weights.sum())
    pooled = float(weights @ estimates) / total
    q = float(weights @ (estimates - pooled) ** 2)
    return max(0.0, (q - (k - 1)) / (total - float(weights @ weights) / total))


def fleet_prior_weights(teammate_stats: np.ndarray, params: CalibrationParams) -> np.ndarray:
    """(3,) the fleet prior's weight in unit segments for the scale, turn scale and heading
    bias: the unit segment's variance over the teammates' between-robot variance, within
    [`fleet_prior_segments`, `fleet_prior_max_segments`]. `teammate_stats` (k, STATS) holds
    each teammate's `own_stats`; one with no segment (or, for the turn, no turn) is left out."""
    var_t, var_r = unit_variances(params)
    tau2 = np.full(3, math.inf)
    has_scale = teammate_stats[:, 1] > 0
    if has_scale.any():
        st = teammate_stats[has_scale]
        tau2[0] = between_variance(st[:, 0] / st[:, 1], st[:, 1])
    fits, precisions = [], []
    for row in teammate_stats:
        normal = np.array([[row[2], row[3]], [row[3], row[4]]])
        if np.linalg.cond(normal) > 1e8:  # no turn yet, or no drive: the two not apart
            continue
        cov = np.linalg.inv(normal)
        fits.append(cov @ row[5:7])
        precisions.append(1.0 / np.diag(cov))
    if fits:
        est, w = np.array(fits), np.array(precisions)
        tau2[1:] = [between_variance(est[:, j], w[:, j]) for j in (0, 1)]
    unit = np.array([var_t, var_r, var_r])
    with np.errstate(divide="ignore"):
        weight = unit / tau2
    return np.clip(weight, params.fleet_prior_segments, params.fleet_prior_max_segments)


def segment_between(odom_from: np.ndarray, odom_to: np.ndarray, reg_from: np.ndarray,
                    reg_to: np.ndarray, odom_turn_rad: float, signed_distance_m: float,
                    driven_m: float, turned_rad: float) -> Segment:
    """A segment from planar poses (x, y, yaw) at its two ends and odometry's sums between."""
    reg_turn = odom_turn_rad + float(wrap_angle(
        (reg_to[2] - reg_from[2]) - odom_turn_rad))
    return Segment(
        odom_chord_m=float(np.hypot(*(np.asarray(odom_to[:2]) - odom_from[:2]))),
        reg_chord_m=float(np.hypot(*(np.asarray(reg_to[:2]) - reg_from[:2]))),
        odom_turn_rad=odom_turn_rad, reg_turn_rad=reg_turn,
        signed_distance_m=signed_distance_m, driven_m=driven_m, turned_rad=turned_rad,
    )


def _relative(xyyaw_from: np.ndarray, xyyaw_to: np.ndarray) -> np.ndarray:
    c, s = math.cos(xyyaw_from[2]), math.sin(xyyaw_from[2])
    wx, wy = xyyaw_to[0] - xyyaw_from[0], xyyaw_to[1] - xyyaw_from[1]
    return np.array([c * wx + s * wy, -s * wx + c * wy,
                     float(wrap_angle(xyyaw_to[2] - xyyaw_from[2]))])


def _compose(xyyaw: np.ndarray, increment: np.ndarray) -> np.ndarray:
    c, s = math.cos(xyyaw[2]), math.sin(xyyaw[2])
    return np.array([xyyaw[0] + c * increment[0] - s * increment[1],
                     xyyaw[1] + s * increment[0] + c * increment[1],
                     float(wrap_angle(xyyaw[2] + increment[2]))])


class CalibratedOdometry:
    """Raw odometry poses in, corrected ones out; segments closed at good registrations.

    The corrected chain starts at the first raw pose and integrates each raw increment
    through the current error estimate, so a better estimate corrects what follows, never
    what was integrated already (no jumps in the pose)."""

    def __init__(self, params: CalibrationParams) -> None:
        self.calibration = Calibration(params)
        self._raw: np.ndarray | None = None  # last raw pose seen (x, y, yaw)
        self._corrected: np.ndarray | None = None  # its corrected counterpart
        self._anchor: tuple[np.ndarray, np.ndarray] | None = None  # (raw, registered) poses
        # odometry's sums since the anchor: turn, signed distance, |distance|, |turn|
        self._turn = self._distance = self._driven = self._turned = 0.0
        # the path since the anchor in the anchor's frame, turn errors out, scale kept
        self._path = np.zeros(3)

    def corrected(self, xyyaw_raw: np.ndarray) -> np.ndarray:
        """The corrected pose of a raw one at or after the last seen (the state is kept)."""
        if self._raw is None:
            return np.asarray(xyyaw_raw, float)
        inc = corrected_increment(_relative(self._raw, xyyaw_raw), self.calibration.errors)
        return _compose(self._corrected, inc)

    def observe(self, xyyaw_raw: np.ndarray) -> np.ndarray:
        """Advance to a new raw pose (seeing the same one again changes nothing)."""
        xyyaw_raw = np.asarray(xyyaw_raw, float)
        if self._raw is not None and np.array_equal(xyyaw_raw, self._raw):
            return self._corrected
        if self._raw is not None:
            inc = _relative(self._raw, xyyaw_raw)
            self._turn += inc[2]
            self._turned += abs(inc[2])
            self._distance += signed_distance(inc)
            self._driven += abs(signed_distance(inc))
            self._path = _compose(self._path, turn_corrected_increment(
                inc, self.calibration.errors))
        self._corrected = self.corrected(xyyaw_raw)
        self._raw = xyyaw_raw
        return self._corrected

    @property
    def anchor_xyyaw(self) -> np.ndarray | None:
        """The registered pose the open segment started at (None: no segment open)."""
        return None if self._anchor is None else self._anchor[1]

    def due(self) -> bool:
        """Whether a good registration now would close the segment (or open the first)."""
        p = self.calibration.params
        return self._raw is not None and (self._anchor is None or self._driven >= p.segment_m
                                          or self._turned >= p.segment_rad)

    def drop_segment(self) -> None:
        """Give up the open segment (its end cannot be measured): the next good
        registration opens a new one."""
        self._anchor = None
        self._restart_sums()

    def _restart_sums(self) -> None:
        self._turn = self._distance = self._driven = self._turned = 0.0
        self._path = np.zeros(3)

    def registered(self, xyyaw_reg: np.ndarray) -> None:
        """A frame at the last seen raw pose registered well, at `xyyaw_reg` (loc frame)."""
        if not self.due():
            return
        if self._anchor is not None:
            seg = segment_between(
                self._anchor[0], self._raw, self._anchor[1], np.asarray(xyyaw_reg, float),
                self._turn, self._distance, self._driven, self._turned)
            if self.calibration.params.turn_corrected_chords:
                seg = replace(seg, odom_chord_m=float(np.hypot(self._path[0], self._path[1])))
            self.calibration.add(seg)
        self._anchor = (self._raw.copy(), np.asarray(xyyaw_reg, float).copy())
        self._restart_sums()
