"""The reference flights' envelope, and the reference model at a flight flown elsewhere in it
or outside it.

The reference model (:mod:`.calibrate`) is fitted on flights of one envelope, and what its
shared values absorb of the physics it lacks depends on how the flights were flown. A
flight flown elsewhere meets the model's *extrapolation error*; read against the
references' own residual statistics it looks like an effect. Two parts of it are physics
the reference model now shares (:func:`.calibrate.per_flight_candidate`: the motor map's
gain and the vertical drag, both drifting with the flight's envelope); the rest is measured
here, over the references themselves, and widens the
reference model for a flight beyond them. Every judged flight's answer states whether it
lies outside its references' envelope, along which coordinate and by how much.

Coordinates (:func:`coordinates`, per flight, natural log so that "1.6x faster" is a
distance of log 1.6 = 0.47): RMS speed |v| (m/s), RMS body rate |omega| (rad/s), RMS
variation of the specific force's size |f| about its mean (m/s^2: how hard the thrust is
worked), each floored at :data:`FLOORS` (a hover's sensor noise level, so that hovering
flights do not sit at log 0 = -inf). The *envelope* is the references' range per coordinate;
a flight's distance outside it is the largest excess over the coordinates (:class:`Position`).

Trend (:func:`fit_trend`). The references' main axis of variation in these coordinates
(first principal direction, ``axis``; sign: speed increasing) gives each flight a scalar
place u. Over the references, each shared parameter's own value theta_j (one Gauss-Newton
step from the pooled value on flight j alone, standard error se_j: stage 3 of
:mod:`.calibrate`)
is regressed on u_j by weighted least squares (weights 1/se_j^2): slope b, variance var(b)
scaled by the fit's reduced chi^2 when above 1 (the between-flight scatter); each channel's
log mean-square residual (the lack-of-fit statistic) is regressed on u_j by ordinary least
squares: slope g_c, one residual spread s_g pooled over channels (C (n - 2) degrees of
freedom).

The reference model at a flight's place (:func:`local_reference`). Every shared value is the
trend's prediction at the flight's place, ``theta_ref + b (u - u_w)`` (u_w the references'
weighted mean place; clipped to the parameter's bounds), its variance ``var(b) (u - u_w)^2``
added to the between-flight scatter. Why: what a shared value absorbs of the physics the
model lacks depends on how the flight was flown, and the references show how (a quadratic
rate drag fitted as linear damping reads higher on faster-turning flights; a closed-loop
motor lag reads longer on slower ones). Inside the references' range
of places [u_min, u_max] their other statistics hold (the calibrated scatter and lack-of-fit
spread already contain how the references differ among themselves). A flight at
e = u - u_max > 0 (or u_min - u) beyond the outermost reference meets the model's
extrapolation, measured by the trend:

* the between-flight scatter grows further, by ``(b^2 + var(b)) e^2``: the trend itself may
  bend out there;
* the noise scale sigma_c grows by ``exp(max(0, g_c e) / 2)``: the residual the references'
  trend expects there is carried as noise (never narrowed: the sensor noise does not shrink
  on a slower flight), and the lack-of-fit mean moves by ``g_c e`` less that widening;
* the lack-of-fit spread, per channel, grows to
  ``sqrt(s^2 + s_g^2 e^2 / (S_uu (1 + 1/n)) + g_c^2 e^2)``: the regression's prediction term
  (S_uu the references' sum of squared places about their mean) and the trend's own move
  there, as for the shared values (a form error that grows with the motion may grow faster
  beyond the references than along them).

A second line per noise-biased parameter (:data:`quadsim.gap.calibrate.NOISE_BIASED`): its
inverse information per sample q_j = se_j^2 N_j (:func:`quadsim.gap.calibrate.inverse_information`).
Least squares biases a value scaling a noisy regressor by the noise over the regressor's
signal (errors in variables), a straight line in q, not in u: over the references the same
weighted regression on q (where their q spread over at least :data:`MIN_INFO_SPREAD`, an
e-fold) gives slope b_q, var(b_q), and the two lines, with as many parameters, are compared
by their chi^2 (scaled by the better one's reduced chi^2 s): the q line's weight
``w = 1 / (1 + exp((chi2_q - chi2_u) / 2 s))``. At a flight with its own q (``info`` of
:func:`position`) the shared value moves by ``(1 - w) m_u + w m_q``, its variance
``(1 - w) v_u + w v_q + w (1 - w) (m_u - m_q)^2`` (each line's v with its extrapolation
beyond the outermost reference, e_q = q - clip(q, q_min, q_max) for the q line).

No threshold decides "inside" or "outside" beyond the references' own extreme: the answer
states the distance whenever it is above zero. Below :data:`MIN_FLIGHTS` references (3: a
slope needs a residual degree of freedom) or when the references' places spread less than
:data:`MIN_SPREAD` (0.05, 5 %: no trend can be measured) the reference model is used as
calibrated, and the answer says that the references do not show how their model
extrapolates.

Example::

    >>> pos = position(flight.fit, ref.envelope)
    >>> pos.distance, pos.text          # 0.35, "speed 1.42x the fastest reference's ..."
    >>> local = local_reference(ref, pos)      # the Reference this flight is judged by
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .fitting import parameter_bounds

__all__ = [
    "COORDINATES",
    "FLOORS",
    "MIN_FLIGHTS",
    "MIN_SPREAD",
    "Envelope",
    "Position",
    "Trend",
    "coordinates",
    "envelope_of",
    "envelope_summary",
    "fit_trend",
    "local_reference",
    "position",
]

#: the envelope's coordinates (name, unit, what it measures)
COORDINATES = (("speed", "m/s", "RMS speed"), ("rate", "rad/s", "RMS body rate"),
               ("thrust", "m/s^2", "RMS variation of the specific force's size"))
#: floors of the coordinates (m/s, rad/s, m/s^2): a hover's level (5 cm/s drift, 3 deg/s
#: gyro noise and wobble, 0.05 m/s^2 accelerometer noise)
FLOORS = np.array([0.05, 0.05, 0.05])
#: fewest references with which a trend is measured
MIN_FLIGHTS = 3
#: least spread (natural log units) of the references' places along their axis
MIN_SPREAD = 0.05
#: least spread (natural log units) of the references' inverse information per sample of a
#: parameter for its inverse-information form: an e-fold. Below it the line's slope comes
#: from a range of information narrower than that of the differences it would explain and
#: extrapolates a noise slope (a parameter whose information does not depend on how a
#: flight is flown spreads far less than an e-fold)
MIN_INFO_SPREAD = 1.0


def coordinates(states) -> np.ndarray:
    """Envelope coordinates (3,) of a flight's states: natural logs (module doc)."""
    speed = np.sqrt(np.mean(np.sum(states.velocity ** 2, axis=1)))
    rate = np.sqrt(np.mean(np.sum(states.body_rate ** 2, axis=1)))
    size = np.linalg.norm(states.specific_force, axis=1)
    thrust = np.sqrt(np.mean((size - size.mean()) ** 2))
    return np.log(np.maximum([speed, rate, thrust], FLOORS))


@dataclass
class Trend:
    """How the references' shared values and residuals move along their axis (module doc).

    ``axis`` (3,): unit direction in the coordinates; ``u_mean``: the references' mean place;
    ``u_w`` (P,): per parameter the weighted mean place; ``slope``/``slope_var`` (P,): dtheta/du
    and its variance; ``lof_slope`` (C,): d(log ms_c)/du; ``lof_mean`` (C,): at u_mean;
    ``lof_sd``, ``lof_dof``: pooled residual spread; ``s_uu``: sum of squared places about
    u_mean; ``n``: references; ``u_low``/``u_high``: the outermost references' places.
    The inverse-information form (module doc, per parameter; weight 0 where not measured):
    ``q_weight`` its posterior weight against the place's line, ``q_w``, ``q_slope``,
    ``q_slope_var``, ``q_low``/``q_high`` as their place counterparts."""

    axis: np.ndarray
    u_mean: float
    u_w: np.ndarray
    slope: np.ndarray
    slope_var: np.ndarray
    lof_slope: np.ndarray
    lof_mean: np.ndarray
    lof_sd: float
    lof_dof: int
    s_uu: float
    n: int
    u_low: float
    u_high: float
    q_weight: np.ndarray | None = None
    q_w: np.ndarray | None = None
    q_slope: np.ndarray | None = None
    q_slope_var: np.ndarray | None = None
    q_low: np.ndarray | None = None
    q_high: np.ndarray | None = None


@dataclass
class Envelope:
    """The references' coordinates (n, 3) and their trend (None: not measurable)."""

    coords: np.ndarray
    trend: Trend | None

    @property
    def low(self) -> np.ndarray:
        return self.coords.min(axis=0)

    @property
    def high(self) -> np.ndarray:
        return self.coords.max(axis=0)


@dataclass
class Position:
    """A flight's place: coordinates, distance outside the envelope (log units, 0 inside),
    the coordinate furthest outside, place u along the references' axis, and in words."""

    coords: np.ndarray
    distance: float
    worst: str
    u: float | None
    text: str
    #: the flight's own inverse information per sample of each shared parameter (P,)
    #: (:func:`quadsim.gap.calibrate.inverse_information`); None: not measured
    info: np.ndarray | None = None

    def to_json(self) -> dict:
        names = [c[0] for c in COORDINATES]
        return {"outside": self.distance > 0, "distance": float(self.distance),
                "furthest": self.worst if self.distance > 0 else None,
                "rms": {n: float(np.exp(v)) for n, v in zip(names, self.coords)},
                "place": None if self.u is None else float(self.u), "text": self.text}


def envelope_of(coords: np.ndarray, values: np.ndarray, se: np.ndarray,
                identified: np.ndarray, log_ms: np.ndarray,
                info: np.ndarray | None = None) -> Envelope:
    """The envelope of reference flights (coordinates (n, 3)), with the trend of their own
    parameter values ``values`` (n, P) (standard errors ``se``; parameters not
    ``identified`` get no slope), their log mean squares ``log_ms`` (n, C) and their
    inverse information per sample ``info`` (n, P; None: no inverse-information form)."""
    return Envelope(np.asarray(coords, float),
                    fit_trend(np.asarray(coords, float), values, se, identified, log_ms,
                              info))


def envelope_summary(envelope: Envelope | None, names=()) -> dict | None:
    """The references' envelope as JSON: per coordinate the smallest and largest RMS value
    (SI), whether a trend was measured, and per shared parameter (``names``) the weight of
    its inverse-information line where it has one."""
    if envelope is None:
        return None
    coords = [c[0] for c in COORDINATES]
    trend = envelope.trend
    weights = {} if trend is None or trend.q_weight is None else {
        n: float(w) for n, w in zip(names, trend.q_weight) if w > 0}
    return {"rms": {n: [float(np.exp(lo)), float(np.exp(hi))]
                    for n, lo, hi in zip(coords, envelope.low, envelope.high)},
            "trend": trend is not None, "information_line": weights}


def _line(x: np.ndarray, v: np.ndarray, se: np.ndarray) -> tuple[float, float, float, float]:
    """Weighted (1/se^2) line of v on x: weighted mean place x_w, slope b, var(b) scaled by
    the reduced chi^2 when above 1, and the fit's chi^2."""
    w = 1.0 / np.maximum(se, 1e-300) ** 2
    x_w = float(np.sum(w * x) / np.sum(w))
    dx = x - x_w
    sxx = float(np.sum(w * dx ** 2))
    mean = float(np.sum(w * v) / np.sum(w))
    b = float(np.sum(w * dx * (v - mean)) / sxx)
    chi2 = float(np.sum(w * (v - mean - b * dx) ** 2))
    return x_w, b, max(1.0, chi2 / (len(x) - 2)) / sxx, chi2


def fit_trend(coords, values, se, identified, log_ms, info=None) -> Trend | None:
    """The :class:`Trend` of n reference flights (module doc): ``coords`` (n, 3) their
    envelope coordinates (:func:`coordinates`), ``values``/``se`` (n, P) each flight's own
    shared values and standard errors (each parameter's unit), ``identified`` (P,) which
    parameters get a slope, ``log_ms`` (n, C) their log mean squares over sigma_c^2,
    ``info`` (n, P) their inverse information per sample (None: no inverse-information
    line). None below :data:`MIN_FLIGHTS` references or a spread of places below
    :data:`MIN_SPREAD`."""
    n = len(coords)
    if n < MIN_FLIGHTS:
        return None
    centred = coords - coords.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    if axis[0] < 0 or (axis[0] == 0 and axis.sum() < 0):
        axis = -axis
    u = coords @ axis
    if np.ptp(u) < MIN_SPREAD:
        return None
    p = values.shape[1]
    u_w, slope, slope_var = np.zeros(p), np.zeros(p), np.zeros(p)
    q = [np.zeros(p) for _ in range(6)]     # weight, q_w, slope, slope_var, low, high
    for k in range(p):
        # a standard error of 0 (or so small that its weight overflows) is a value the
        # flight's step did not move, not one known exactly: no line
        with np.errstate(divide="ignore", over="ignore"):
            weighable = np.all(np.isfinite(1.0 / se[:, k] ** 2))
        if not identified[k] or not weighable:
            u_w[k] = u.mean()
            continue
        u_w[k], slope[k], slope_var[k], chi2_u = _line(u, values[:, k], se[:, k])
        x = None if info is None else info[:, k]
        if x is None or not np.all(np.isfinite(x)) or np.any(x <= 0) \
                or np.ptp(np.log(x)) < MIN_INFO_SPREAD:
            continue
        q_w, b, var_b, chi2_q = _line(x, values[:, k], se[:, k])
        # the two lines have as many parameters: their likelihoods compare directly, the
        # chi^2 scaled by the better line's reduced chi^2 (the between-flight scatter
        # neither line explains, which must not turn a small difference into certainty)
        scale = max(1.0, min(chi2_u, chi2_q) / (n - 2))
        weight = 1.0 / (1.0 + np.exp((chi2_q - chi2_u) / (2.0 * scale)))
        for arr, val in zip(q, (weight, q_w, b, var_b, x.min(), x.max())):
            arr[k] = val
    du = u - u.mean()
    s_uu = float(du @ du)
    g = (du @ (log_ms - log_ms.mean(axis=0))) / s_uu
    lof_mean = log_ms.mean(axis=0)
    rest = log_ms - lof_mean - np.outer(du, g)
    dof = max(1, rest.size - 2 * rest.shape[1])
    return Trend(axis, float(u.mean()), u_w, slope, slope_var, g, lof_mean,
                 float(np.sqrt(np.sum(rest ** 2) / dof)), dof, s_uu, n,
                 float(u.min()), float(u.max()), *q)


def position(states, envelope: Envelope | None, info: np.ndarray | None = None
             ) -> Position | None:
    """A flight's :class:`Position` against the references' envelope (None without one);
    ``info``: its inverse information per sample of each shared parameter."""
    if envelope is None:
        return None
    x = coordinates(states)
    above, below = x - envelope.high, envelope.low - x
    excess = np.maximum(np.maximum(above, below), 0.0)
    worst = int(np.argmax(excess))
    distance = float(excess[worst])
    u = None if envelope.trend is None else float(x @ envelope.trend.axis)
    name, unit, what = COORDINATES[worst]
    if distance <= 0:
        text = "inside the reference flights' envelope (speed, body rate, thrust variation)"
    else:
        fast = above[worst] > 0
        ratio = np.exp(x[worst] - (envelope.high if fast else envelope.low)[worst])
        size = (f"{ratio:.2f}x" if abs(np.log(ratio)) >= 0.1
                else f"{100 * abs(ratio - 1):.1f} % {'above' if fast else 'below'}")
        text = (f"outside the reference flights' envelope: {what} {np.exp(x[worst]):.3g} "
                f"{unit}, {size} the {'largest' if fast else 'smallest'} reference's")
        text += ("; the reference model follows the references' own trend there, its "
                 "uncertainty and noise widened" if envelope.trend is not None else
                 "; the references do not spread enough to show how their model "
                 "extrapolates: judged by the reference model as calibrated")
    return Position(x, distance, name, u, text,
                    None if info is None else np.asarray(info, float))


def local_reference(reference, pos: Position | None):
    """The reference model at a flight's place (module doc): a copy of ``reference`` with its
    shared values at the trend's prediction, and widened scatter, noise scale and lack-of-fit
    statistics beyond the outermost reference; ``reference`` itself where no trend is
    measured."""
    trend = getattr(getattr(reference, "envelope", None), "trend", None)
    pooled = getattr(reference, "lof_pooled", None)
    if pos is not None and pos.distance > 0 and pooled is not None:
        # a channel's own spread holds within the references' envelope; beyond it, at least
        # the pooled one (quadsim.gap.moderated)
        reference = dataclasses.replace(
            reference, lof_sd=np.maximum(reference.lof_sd, pooled[0]), lof_dof=pooled[1])
    if pos is None or trend is None or pos.u is None:
        return reference
    # beyond the references' outermost places only: inside, their own statistics hold
    edge = pos.u - np.clip(pos.u, trend.u_low, trend.u_high)
    scatter = reference.scatter
    shift = trend.lof_slope * edge
    widen = np.maximum(shift, 0.0)
    n = len(reference.names) or trend.n
    # per channel: the regression's prediction term, and the trend's own move there (it
    # may bend beyond its references, as for the shared values)
    spread = np.sqrt(reference.lof_sd ** 2
                     + trend.lof_sd ** 2 * edge ** 2 / (trend.s_uu * (1 + 1 / n))
                     + (trend.lof_slope * edge) ** 2)
    lower, upper = getattr(reference, "bounds", None) or parameter_bounds(reference.candidate,
                                                                 reference.params)
    move, var = _predicted_move(trend, pos, edge)
    predicted = np.clip(reference.theta + move, lower, upper)
    theta = _physical_towards(reference, predicted, np.sqrt(scatter ** 2 + var))
    # the part of the trend's move that no rigid body can make is the model's error there
    scatter = np.sqrt(scatter ** 2 + var + (predicted - theta) ** 2)
    return dataclasses.replace(
        reference, theta=theta, scatter=scatter, sigma=reference.sigma * np.exp(widen / 2),
        lof_mean=reference.lof_mean + shift - widen, lof_sd=spread)


def _predicted_move(trend: Trend, pos: Position, edge: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The trend's move of each shared value from the pooled one at the flight's place, and
    its variance (module doc): the place's line, mixed with the inverse-information line by
    the latter's weight where it is measured and the flight's information is known."""
    lead = pos.u - trend.u_w
    move_u = trend.slope * lead
    var_u = trend.slope_var * lead ** 2 + (trend.slope ** 2 + trend.slope_var) * edge ** 2
    if trend.q_weight is None or pos.info is None or len(pos.info) != len(trend.slope):
        return move_u, var_u
    w = np.where(np.isfinite(pos.info), trend.q_weight, 0.0)
    info = np.where(w > 0, pos.info, trend.q_w)
    lead_q = info - trend.q_w
    edge_q = info - np.clip(info, trend.q_low, trend.q_high)
    move_q = trend.q_slope * lead_q
    var_q = (trend.q_slope_var * lead_q ** 2
             + (trend.q_slope ** 2 + trend.q_slope_var) * edge_q ** 2)
    move = (1.0 - w) * move_u + w * move_q
    return move, (1.0 - w) * var_u + w * var_q + w * (1.0 - w) * (move_u - move_q) ** 2


#: bisection steps of :func:`_physical_towards` (the move kept to 2^-30 of its length)
_PHYSICAL_STEPS = 30


def _physical_towards(reference, theta: np.ndarray, sd: np.ndarray | None = None
                      ) -> np.ndarray:
    """``theta`` where the reference model's vehicle there is physical, else the nearest
    physical point found by taking back the trend's least certain moves first: each moved
    value in turn, in order of its move over its spread ``sd`` (smallest first), goes back
    towards the pooled value ``reference.theta`` (physical: the references were fitted
    there), the last one only as far as the wall (bisection). The trend is a straight line
    fitted on the references, and a rigid body's inertia must keep the triangle inequality
    wherever the line leads (a flat frame's Izz is nearly Ixx + Iyy). The part of the move
    left out widens the shared value's spread (:func:`local_reference`), so the trend's
    artefact is not read as the flight's own difference. The least certain move goes back
    first: it is the one the wall speaks against."""
    if _physical(reference, theta):
        return theta
    base = np.asarray(reference.theta, float)
    theta = np.array(theta, dtype=float)
    moved = np.flatnonzero(theta != base)
    sd = np.ones_like(theta) if sd is None else np.maximum(np.asarray(sd, float), 1e-300)
    for k in moved[np.argsort(np.abs(theta - base)[moved] / sd[moved], kind="stable")]:
        start = theta[k]
        theta[k] = base[k]
        if not _physical(reference, theta):
            continue
        inside, outside = 0.0, 1.0
        for _ in range(_PHYSICAL_STEPS):
            mid = 0.5 * (inside + outside)
            theta[k] = base[k] + mid * (start - base[k])
            if _physical(reference, theta):
                inside = mid
            else:
                outside = mid
        theta[k] = base[k] + inside * (start - base[k])
        return theta
    return theta


def _physical(reference, theta: np.ndarray) -> bool:
    """Whether the shared effects at ``theta`` leave the vehicle physical."""
    from ..core.errors import ModelError
    from ..effects.base import EffectSet

    try:
        EffectSet(tuple(reference.effects(theta))).apply_to_params(reference.params)
    except ModelError:
        return False
    return True

