"""Identification from the IMU and the motor commands alone (no pose, no rotor speeds).

Most flight controllers log the accelerometer, the gyro and the commands they send. In the
body frame (x forward, y left, z up) these fix, with no position or attitude:

* the **thrust map per command**: ``m f_z = sum_i T(u_i)`` with ``T(u) = c1 u + c2 u^2`` N
  per rotor (``f_z`` the accelerometer's body-z specific force, m/s^2; ``m`` the skeleton's
  mass, kg) and, where the battery voltage v is logged and varies (by 1 % of its mean at
  least, :data:`quadsim.effects.battery_sag.VOLTAGE_TESTED`: a steady one does not fix the
  term), ``T = c1 u + c2 u^2 + c3 u^2 (v - v_ref)`` (``voltage_gain = c3 / c2``, 1/V; v_ref
  the median voltage);
* the **motor's first-order time constant** T_m (s): the thrust follows the command through
  ``T_m du_f/dt = u - u_f`` (exact zero-order-hold discretisation, ``u_f`` starting at the
  stretch's first command); every balance below uses ``u_f``;
* the **roll/pitch torque per command** and the **roll/pitch inertia**: ``I_xx dw_x/dt =
  sum_i y_i T(u_f,i) + M_x0`` and ``I_yy dw_y/dt = -sum_i x_i T(u_f,i) + M_y0`` (rotor i at
  (x_i, y_i) from the CoM; ``M_0`` a constant torque: trim, CoM offset). The gyroscopic term
  ``(I_zz - I_yy) w_y w_z`` is left out (I_zz is not identified; it is under 1 % of the
  torque for the Crazyflie's manoeuvres).

Each balance is written over windows of ``WINDOW_S`` (integrals, so no differentiated
gyro): the window means of ``m f_z`` and of ``T(u_f)``; the change of the body rate ``Delta w``
across the window against the torque's integral. The inertia is the least-squares slope of
the torque integral on ``Delta w`` (the model's error -- thrust map, unmodelled aerodynamics --
lies in the torque, the dependent side; the gyro's noise on ``Delta w`` is small against
the manoeuvres, so the slope is not attenuated).

**T_m** maximises the joint profile likelihood of the three balances (each with its own
residual variance, in the measured quantity: the specific force, and the change of body
rate ``torque residual / I``): ``l(T_m) = -1/2 sum_b n_b log(RSS_b(T_m) / n_b)`` over
``LAG_GRID_S``;
its 95 % interval is where ``2 (l_max - l) / tau_corr <= 3.84`` with ``tau_corr`` the
residuals' integrated correlation time (windows), for autocorrelated residuals.

**Intervals** (95 %): the thrust coefficients and the inertia by least squares with the
residual variance widened by its correlation time; the inertia's interval also spans its
values at the ends of T_m's interval (the two are correlated: a longer lag shrinks the
torque's swing and the inertia with it) and the thrust map's relative uncertainty at the
hover command (the torque's scale is the thrust map's). An inertia is identified where that
interval is narrower than the value and the torque explains at least
:data:`quadsim.identify.from_logs.INERTIA_R2` (0.5) of the change of body rate, as with
rotor speeds; else :func:`identification_for_set` keeps the skeleton's (or the default)
with the reason.

**Robust**: windows whose residual in any balance exceeds ``TRIM`` robust standard
deviations (1.4826 x median absolute deviation) at a first fit are left out (impacts,
ground contact, a crash at the end of a stretch); the count is in the notes.

Example::

    >>> segs = segments_from_logs(logs)               # FlightLogs, airborne stretches
    >>> ident = identify_imu(segs, mass=0.027, arms=arms)
    >>> ident.time_constant.value, [e.value for e in ident.inertia]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from ..core.errors import InputError
from ..effects.battery_sag import VOLTAGE_TESTED, voltage_spread
from .from_logs import INERTIA_R2, kept_inertia
from .logseries import Estimate, correlation_time

__all__ = ["LAG_GRID_S", "TRIM", "WINDOW_S", "ImuIdentification", "ImuSegment", "ThrustMap",
           "identification_for_set",
           "identify_imu", "lagged", "segments_from_logs"]

#: window of the balances (s): short against the motor lag and the manoeuvres' rise times
#: (the roll/pitch flips of the published logs change rate within ~50 ms), long against the
#: 1 kHz logging step.
WINDOW_S = 0.02
#: motor time-constant grid (s): 0 (no lag) to 200 ms, above any multirotor motor.
LAG_GRID_S = np.arange(0.0, 0.2001, 0.0025)
#: windows with a residual beyond TRIM robust standard deviations are left out (a 4-sigma
#: outlier has probability 6e-5 under Gaussian noise: impacts, not noise).
TRIM = 4.0
#: rounds of (best lag, trim): the first fit with every window sees the impacts too.
ROUNDS = 2
#: another rotor order must beat the skeleton's by this much roll + pitch R^2 (of 2) to be
#: named: a wrong order turns at least one axis' torque the wrong way (R^2 near 0), so the
#: right order wins by far more; smaller gaps are the noise of two close fits.
ORDER_MARGIN = 0.2
#: fewer windows than this in a balance: refused (no interval can be stated).
MIN_WINDOWS = 50
_CHI2_95 = 3.841


@dataclass(frozen=True)
class ImuSegment:
    """One airborne stretch on a uniform grid (SI, body frame FLU). t (N,) s; specific_force
    (N, 3) m/s^2; body_rate (N, 3) rad/s; command (N, R) normalised 0-1; vbat (N,) V or None;
    name: the file (and stretch) it came from."""

    name: str
    t: np.ndarray
    specific_force: np.ndarray
    body_rate: np.ndarray
    command: np.ndarray
    vbat: np.ndarray | None = None


@dataclass(frozen=True)
class ThrustMap:
    """``T(u, v) = c1 u + c2 u^2 + c3 u^2 (v - v_ref)`` N per rotor (u normalised command,
    lagged). ``cov``: covariance (k, k) of (c1, c2[, c3]); r2: the fit's R^2 over ``windows``;
    reference_voltage V or None (no voltage logged)."""

    c1: float
    c2: float
    c3: float
    reference_voltage: float | None
    cov: np.ndarray
    r2: float
    windows: int

    def thrust(self, u, v=None) -> np.ndarray:
        """Thrust (N) per rotor at commands ``u`` (and voltages ``v``, broadcast)."""
        u = np.asarray(u, dtype=float)
        out = self.c1 * u + self.c2 * u * u
        if self.reference_voltage is not None and v is not None:
            out = out + self.c3 * u * u * (np.asarray(v, float) - self.reference_voltage)
        return out

    @property
    def voltage_gain(self) -> float:
        """c3 / c2 (1/V): the relative change of thrust per volt at a given command."""
        return self.c3 / self.c2 if self.c2 else 0.0

    def full_thrust_se(self) -> float:
        """Standard error (N) of T(1) = c1 + c2 at v_ref."""
        return math.sqrt(max(float(self.cov[0, 0] + self.cov[1, 1] + 2 * self.cov[0, 1]), 0.0))


@dataclass(frozen=True)
class ImuIdentification:
    """What :func:`identify_imu` found. time_constant (s); thrust; inertia (Ixx, Iyy) kg m^2;
    torque_per_command (roll, pitch): N m per unit command difference between the two sides
    at the hover command (``2 sum_{i left} y_i dT/du``: the control effectiveness); hover
    command (normalised); r2 of the (z, roll, pitch) balances; notes: one line each."""

    time_constant: Estimate
    thrust: ThrustMap
    inertia: tuple[Estimate, Estimate]
    torque_per_command: tuple[Estimate, Estimate]
    hover_command: float
    r2: tuple[float, float, float]
    notes: tuple[str, ...]


def lagged(u: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """First-order lag of ``u`` (N, ...) with time constant ``tau`` (s), step ``dt`` (s):
    exact for a command held over each step, ``y[k+1] = e y[k] + (1 - e) u[k]``,
    ``e = exp(-dt / tau)``, ``y[0] = u[0]``; ``tau <= 0`` returns ``u``."""
    u = np.asarray(u, dtype=float)
    if tau <= 0:
        return u
    e = math.exp(-dt / tau)
    out, _ = lfilter([0.0, 1.0 - e], [1.0, -e], u, axis=0, zi=u[:1])   # y[0] = u[0]
    return out


def segments_from_logs(logs, *, dt: float | None = None) -> list[ImuSegment]:
    """:class:`ImuSegment` per FlightLog (airborne stretches, NaN cut), resampled onto a
    uniform grid of step ``dt`` (default: the largest median step) by linear interpolation.
    Raises :class:`InputError` naming the file and the column it lacks."""
    out = []
    step = dt or max(float(np.median(np.diff(log.t))) for log in logs)
    for log in logs:
        where = log.path if log.path is not None else "log"
        if log.accel is None:
            raise InputError(f"{where}: ax, ay, az: no accelerometer; identification from "
                             "the IMU needs the specific force")
        if log.body_rate is None:
            raise InputError(f"{where}: wx, wy, wz: no gyro; identification from the IMU "
                             "needs the body rates")
        if log.rotor_command is None:
            raise InputError(f"{where}: cmd_*: no motor commands")
        t = np.asarray(log.t, float)
        grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step + 1e-9)) + 1)

        def on_grid(x, t=t, grid=grid):
            x = np.asarray(x, float)
            if x.ndim == 1:
                return np.interp(grid, t, x)
            return np.stack([np.interp(grid, t, x[:, i]) for i in range(x.shape[1])], 1)

        out.append(ImuSegment(str(where), grid, on_grid(log.accel), on_grid(log.body_rate),
                              on_grid(log.rotor_command),
                              None if log.vbat is None else on_grid(log.vbat)))
    return out


@dataclass(frozen=True)
class _Windows:
    """The balances' window sums at one T_m, pooled over segments. z: (W, k) regressors of
    ``m f_z`` (window means of sum u, sum u^2[, sum u^2 (v - v_ref)]) and its target (W,);
    rot: (W, 2) Delta w (roll, pitch); lin, quad: (W, R) window integrals of u_f and u_f^2
    (and quad_v of u_f^2 (v - v_ref)); span: (W,) window lengths (s)."""

    z: np.ndarray
    target: np.ndarray
    rot: np.ndarray
    lin: np.ndarray
    quad: np.ndarray
    quad_v: np.ndarray | None
    span: np.ndarray
    segment: np.ndarray          # (W,) index of the stretch each window lies in


def _windows(segments: list[ImuSegment], tau: float, mass: float,
             v_ref: float | None) -> _Windows:
    parts: dict[str, list] = {k: [] for k in ("z", "target", "rot", "lin", "quad", "quad_v",
                                              "span", "segment")}
    for index, seg in enumerate(segments):
        dt = float(seg.t[1] - seg.t[0])
        n = max(1, round(WINDOW_S / dt))
        u = lagged(seg.command, dt, tau)
        start = np.arange(0, len(seg.t) - n, n)
        if len(start) == 0:
            continue

        def integral(x, start=start, n=n, dt=dt):
            c = np.concatenate([np.zeros((1, *x.shape[1:])), np.cumsum(x, axis=0)]) * dt
            return c[start + n] - c[start]

        span = n * dt
        lin, quad = integral(u), integral(u * u)
        quad_v = integral(u * u * (seg.vbat - v_ref)[:, None]) if v_ref is not None else None
        cols = [lin.sum(1), quad.sum(1)] + ([quad_v.sum(1)] if quad_v is not None else [])
        parts["z"].append(np.stack(cols, 1) / span)
        parts["target"].append(mass * integral(seg.specific_force[:, 2]) / span)
        parts["rot"].append(seg.body_rate[start + n, :2] - seg.body_rate[start, :2])
        parts["lin"].append(lin)
        parts["quad"].append(quad)
        parts["quad_v"].append(quad_v)
        parts["span"].append(np.full(len(start), span))
        parts["segment"].append(np.full(len(start), index))
    if not parts["z"]:
        raise InputError(f"{segments[0].name}: t: no stretch longer than a {WINDOW_S} s window")
    joined = {k: (np.concatenate(v) if v and v[0] is not None else None) for k, v in parts.items()}
    return _Windows(**joined)


@dataclass(frozen=True)
class _Fit:
    """The three balances fitted at one T_m: coefficients, residuals (W,) each."""

    thrust: np.ndarray           # (k,) c1, c2[, c3]
    thrust_res: np.ndarray
    inertia: np.ndarray          # (2,) Ixx, Iyy
    offset: np.ndarray           # (2,) constant torques, N m
    rot_res: np.ndarray          # (W, 2) torque-integral residuals, N m s
    torque: np.ndarray           # (W, 2) torque integrals, N m s
    rate_res: np.ndarray         # (W, 2) Delta w not explained by the torque, rad/s


def _lstsq(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.linalg.lstsq(x, y, rcond=None)[0]


def _fit(w: _Windows, keep: np.ndarray, arms: np.ndarray, *, per_stretch: bool) -> _Fit:
    """The balances at one T_m; ``per_stretch``: one thrust map per stretch (no voltage
    logged: the battery's sag changes the thrust per command from take-off to take-off)."""
    groups = np.unique(w.segment) if per_stretch else [None]
    coefs = np.zeros((len(w.target), w.z.shape[1]))
    for g in groups:
        rows = np.ones(len(w.target), bool) if g is None else w.segment == g
        use = rows & keep
        coefs[rows] = _lstsq(w.z[use], w.target[use]) if use.sum() > w.z.shape[1] else np.nan
    coef = np.nanmedian(coefs, axis=0)
    coefs = np.where(np.isfinite(coefs), coefs, coef)
    res = w.target - np.sum(w.z * coefs, axis=1)
    torque_rows = np.stack([arms[:, 1], -arms[:, 0]])          # (2, R): roll, pitch per unit T
    per_rotor = coefs[:, :1] * w.lin + coefs[:, 1:2] * w.quad
    if w.quad_v is not None:
        per_rotor = per_rotor + coefs[:, 2:3] * w.quad_v
    torque = per_rotor @ torque_rows.T                          # (W, 2) N m s
    inertia, offset = np.zeros(2), np.zeros(2)
    rot_res, rate_res = np.zeros_like(torque), np.zeros_like(torque)
    for a in range(2):
        x = np.stack([w.rot[:, a], w.span], 1)
        beta = _lstsq(x[keep], torque[keep, a])
        inertia[a], offset[a] = beta
        rot_res[:, a] = torque[:, a] - x @ beta
        x = np.stack([torque[:, a], w.span], 1)              # the same balance, output error
        rate_res[:, a] = w.rot[:, a] - x @ _lstsq(x[keep], w.rot[keep, a])
    return _Fit(coef, res, inertia, -offset, rot_res, torque, rate_res)


def _loglik(fit: _Fit, keep: np.ndarray) -> float:
    """The profile log-likelihood of the three balances, each in what was measured (the
    specific force; the change of body rate: torque residual / I), not in what the model
    computes (a torque residual shrinks with any lag that smooths the torque)."""
    total = 0.0
    for r in (fit.thrust_res, fit.rate_res[:, 0], fit.rate_res[:, 1]):
        r = r[keep]
        total -= 0.5 * len(r) * math.log(max(float(r @ r) / len(r), 1e-300))
    return total


def _outliers(fit: _Fit) -> np.ndarray:
    """Windows whose residual in every balance is within TRIM robust standard deviations."""
    keep = np.ones(len(fit.thrust_res), bool)
    for r in (fit.thrust_res, fit.rate_res[:, 0], fit.rate_res[:, 1]):
        scale = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        if scale > 0:
            keep &= np.abs(r - np.median(r)) <= TRIM * scale
    return keep


def _r2(res: np.ndarray, y: np.ndarray) -> float:
    y = y - y.mean()
    return 1.0 - float(res @ res) / max(float(y @ y), 1e-300)


def identify_imu(segments: list[ImuSegment], *, mass: float, arms: np.ndarray) -> ImuIdentification:
    """T_m, the thrust map, roll/pitch torque per command and Ixx, Iyy (see the module).
    ``mass`` kg; ``arms`` (R, 3) m: rotor positions from the CoM, body FLU, in the command
    columns' order. Raises :class:`InputError` when the stretches are too short or the data
    fix no positive thrust or inertia."""
    if not segments:
        raise InputError("--logs: no airborne stretch to identify from")
    arms = np.asarray(arms, dtype=float)
    count = {s.command.shape[1] for s in segments}
    if count != {len(arms)}:
        raise InputError(f"{segments[0].name}: cmd_*: {sorted(count)} command column(s), "
                         f"{len(arms)} rotors in the skeleton")
    # the voltage term only where the logs' voltage varies (a steady one leaves its column of
    # the thrust fit constant: battery_sag.VOLTAGE_TESTED); else the map in u alone
    has_v = all(s.vbat is not None for s in segments) and \
        voltage_spread([s.vbat for s in segments])[1] >= VOLTAGE_TESTED
    v_ref = float(np.median(np.concatenate([s.vbat for s in segments]))) if has_v else None
    per_stretch = not has_v and len(segments) > 1

    def scan(keep):
        return np.array([_loglik(_fit(_windows(segments, tau, mass, v_ref), keep, arms,
                                      per_stretch=per_stretch), keep)
                         for tau in LAG_GRID_S])

    keep = np.ones(len(_windows(segments, 0.0, mass, v_ref).target), bool)
    for _ in range(ROUNDS):         # trim at the best lag of the windows kept so far
        tau0 = float(LAG_GRID_S[int(np.argmax(scan(keep)))])
        keep = _outliers(_fit(_windows(segments, tau0, mass, v_ref), keep, arms,
                              per_stretch=per_stretch))
    if keep.sum() < MIN_WINDOWS:
        raise InputError(f"{segments[0].name}: t: {int(keep.sum())} usable windows of "
                         f"{WINDOW_S} s, fewer than {MIN_WINDOWS}: too short to identify")
    lik = scan(keep)
    best = int(np.argmax(lik))
    tau = _refine(lik, best)
    w = _windows(segments, tau, mass, v_ref)
    fit = _fit(w, keep, arms, per_stretch=per_stretch)
    corr = max(correlation_time(r[keep]) for r in (fit.thrust_res, fit.rot_res[:, 0],
                                                   fit.rot_res[:, 1]))
    inside = LAG_GRID_S[2.0 * (lik.max() - lik) / corr <= _CHI2_95]
    tau_ci = (float(inside.min()), float(inside.max()))
    notes = [(f"{int((~keep).sum())} of {len(keep)} windows of {1000 * WINDOW_S:.0f} ms left "
              f"out as outliers (residual beyond {TRIM:g} robust standard deviations: impacts, "
              "ground contact)")] if (~keep).any() else []
    if best in (0, len(LAG_GRID_S) - 1):
        notes.append(f"motor time constant at the grid's end ({1000 * tau:.1f} ms): not "
                     "determined by these logs")
    _check_order(segments[0].name, w, keep, arms, per_stretch=per_stretch)
    thrust = _thrust_map(w, _fit(w, keep, arms, per_stretch=False), keep, v_ref)
    if per_stretch:
        scales = _stretch_scales(w, keep, thrust)
        notes.append(f"no battery voltage logged: one thrust map per airborne stretch (the "
                     f"battery's sag changes the thrust per command); thrust at the median "
                     f"command spans {100 * (min(scales) - 1):+.1f} .. "
                     f"{100 * (max(scales) - 1):+.1f} % of the pooled map over the "
                     f"{len(segments)} stretches; the pooled map is written")
    if not thrust.c1 + thrust.c2 > 0:
        raise InputError(f"{segments[0].name}: cmd_*: the command -> thrust fit gives no "
                         f"thrust at full command (c1 {thrust.c1:.3g}, c2 {thrust.c2:.3g} N): "
                         "commands not normalised 0-1, or too little range flown")
    ends = [_fit(_windows(segments, t_end, mass, v_ref), keep, arms,
                 per_stretch=per_stretch).inertia
            for t_end in tau_ci]
    hover = float(np.median(np.concatenate([s.command for s in segments])))
    slope = thrust.c1 + 2 * thrust.c2 * hover                   # dT/du at hover, N
    se_slope = math.sqrt(max(float(np.array([1, 2 * hover]) @ thrust.cov[:2, :2]
                                   @ np.array([1, 2 * hover])), 0.0))
    inertia = []
    for a, name in enumerate(("Ixx", "Iyy")):
        x = np.stack([w.rot[keep, a], w.span[keep]], 1)
        r = fit.rot_res[keep, a]
        cov = np.linalg.inv(x.T @ x) * float(r @ r) / max(1, len(r) - 2) * correlation_time(r)
        value = float(fit.inertia[a])
        half = math.sqrt((1.96 * math.sqrt(max(cov[0, 0], 0.0))) ** 2
                         + max(abs(e[a] - value) for e in ends) ** 2
                         + (1.96 * value * se_slope / slope) ** 2)
        r2 = _r2(r, fit.torque[keep, a])
        quality = (f"torque of the lagged commands on the change of body rate over "
                   f"{1000 * WINDOW_S:.0f} ms windows; R^2 {r2:.3f} over {int(keep.sum())} "
                   f"windows; interval includes T_m's and the thrust map's")
        # as the fit with rotor speeds (quadsim.identify.from_logs.INERTIA_R2): a slope the
        # torque does not explain is no inertia (measured: CHANGELOG.md, branch imuinertia)
        ok = value > 0 and half < value and r2 >= INERTIA_R2
        reason = (f"R^2 {r2:.3f} below {INERTIA_R2}: the lagged commands' torque explains too "
                  "little of the change of body rate" if r2 < INERTIA_R2 else
                  "too little roll/pitch excitation")
        inertia.append(Estimate(value, (value - half, value + half), quality, ok,
                                "" if ok else f"{name} fit {value:.3g} kg m^2 +- {half:.2g}: "
                                f"{reason}"))
    hover = float(np.median(np.concatenate([s.command for s in segments])))
    slope = thrust.c1 + 2 * thrust.c2 * hover                   # dT/du at hover, N
    se_slope = math.sqrt(max(float(np.array([1, 2 * hover]) @ thrust.cov[:2, :2]
                                   @ np.array([1, 2 * hover])), 0.0))
    effect = []
    for col in (1, 0):
        lever = float(np.sum(np.abs(arms[:, col]))) / 2          # N m per N per side
        value = lever * slope
        effect.append(Estimate(value, (value - 1.96 * lever * se_slope,
                                       value + 1.96 * lever * se_slope),
                               f"dT/du {slope:.4g} N at the median command {hover:.3f} x "
                               f"lever {lever:.4g} m"))
    r2 = (_r2(fit.thrust_res[keep], w.target[keep]), _r2(fit.rot_res[keep, 0],
                                                        fit.torque[keep, 0]),
          _r2(fit.rot_res[keep, 1], fit.torque[keep, 1]))
    time_constant = Estimate(tau, tau_ci, f"joint profile likelihood of the thrust and "
                             f"roll/pitch balances over {int(keep.sum())} windows of "
                             f"{len(segments)} airborne stretch(es); residual correlation "
                             f"{corr:.1f} windows")
    return ImuIdentification(time_constant, thrust, tuple(inertia), tuple(effect), hover, r2,
                             tuple(notes))


def _order_score(w: _Windows, keep: np.ndarray, arms: np.ndarray, *, per_stretch: bool
                 ) -> float:
    """Roll + pitch R^2 of the change of body rate explained by the torque of ``arms``
    (rotor positions in the command columns' order); an axis whose inertia comes out
    negative scores 0 (the torque turns the vehicle the wrong way)."""
    fit = _fit(w, keep, arms, per_stretch=per_stretch)
    total = 0.0
    for a in range(2):
        if fit.inertia[a] > 0:
            total += max(_r2(fit.rate_res[keep, a], w.rot[keep, a]), 0.0)
    return total


def _check_order(name: str, w: _Windows, keep: np.ndarray, arms: np.ndarray, *,
                 per_stretch: bool) -> None:
    """Refuse commands whose columns fit another rotor order than the skeleton's by more
    than ``ORDER_MARGIN`` of roll + pitch R^2 (every permutation of up to 8 columns)."""
    import itertools

    count = len(arms)
    if count > 8:
        return
    own = _order_score(w, keep, arms, per_stretch=per_stretch)
    best, best_order = own, tuple(range(count))
    for order in itertools.permutations(range(count)):
        if order != tuple(range(count)):
            score = _order_score(w, keep, arms[list(order)], per_stretch=per_stretch)
            if score > best:
                best, best_order = score, order
    if best - own > ORDER_MARGIN:
        inverse = [0] * count
        for column, rotor in enumerate(best_order):
            inverse[rotor] = column
        mapping = ",".join(str(c + 1) for c in inverse)
        raise InputError(f"{name}: cmd_*: the commands fit another rotor order: roll + pitch "
                         f"R^2 {own:.2f} in the skeleton's order, {best:.2f} with our rotor i "
                         f"taken from command column m_i = {mapping}; convert the logs with "
                         f"--rotor-map {mapping} (or reorder the skeleton's [[rotor]] entries)")


def _stretch_scales(w: _Windows, keep: np.ndarray, pooled: ThrustMap) -> list[float]:
    """Each stretch's thrust at the median command over the pooled map's (ratios)."""
    out = []
    for g in np.unique(w.segment):
        use = keep & (w.segment == g)
        if use.sum() <= w.z.shape[1]:
            continue
        c = _lstsq(w.z[use], w.target[use])
        u = float(np.median(w.z[use, 0])) / w.lin.shape[1]        # median command
        out.append(float((c[0] * u + c[1] * u * u) / pooled.thrust(u)))
    return out or [1.0]


def _refine(lik: np.ndarray, best: int) -> float:
    """The grid's maximum refined by a parabola through it and its neighbours (s)."""
    if 0 < best < len(lik) - 1:
        a, b, c = lik[best - 1], lik[best], lik[best + 1]
        denom = a - 2 * b + c
        if denom < 0:
            step = float(LAG_GRID_S[1] - LAG_GRID_S[0])
            return float(LAG_GRID_S[best] + 0.5 * step * (a - c) / denom)
    return float(LAG_GRID_S[best])


def _thrust_map(w: _Windows, fit: _Fit, keep: np.ndarray, v_ref: float | None) -> ThrustMap:
    x, r = w.z[keep], fit.thrust_res[keep]
    cov = np.linalg.inv(x.T @ x) * float(r @ r) / max(1, len(r) - x.shape[1]) * \
        correlation_time(r)
    c = fit.thrust
    return ThrustMap(float(c[0]), float(c[1]), float(c[2]) if len(c) > 2 else 0.0, v_ref, cov,
                     _r2(r, w.target[keep]), int(keep.sum()))


def identification_for_set(ident: ImuIdentification, skeleton, *, stretches: int):
    """The :class:`~quadsim.identify.logseries.LogIdentification` that
    :func:`quadsim.identify.vehicle_set.build_set` writes, from an IMU + commands
    identification: b = T(1) / max_speed^2 (the skeleton's ``rotors.max_speed``: commands
    fix only the thrust, not the rotor speed), the motor map ``Omega(u) = sqrt(T(u) / b)``
    with T_m, Ixx and Iyy with their intervals. Raises :class:`InputError` naming the
    skeleton's field when max_speed is missing."""
    from .logseries import LogIdentification

    if skeleton.max_speed is None:
        raise InputError(f"{skeleton.path}: rotors.max_speed: missing; logs without rotor "
                         "speeds fix only the thrust per command, and the speed scale comes "
                         "from max_speed (the rotor speed at full command: motor kV x battery "
                         "voltage, or a tachometer)")
    tm = ident.thrust
    full = tm.c1 + tm.c2
    b = full / skeleton.max_speed ** 2
    half = 1.96 * tm.full_thrust_se() / full * b
    grid = np.linspace(0.0, 1.0, 11)
    speed = np.sqrt(np.clip(tm.thrust(grid), 0.0, None) / b)
    summary = (f"command -> thrust per rotor T(u) = {tm.c2:.4g} u^2 + {tm.c1:.4g} u N"
               + (f" (x (1 + {tm.voltage_gain:.3g} (v - {tm.reference_voltage:.3g} V)) on the "
                  "u^2 term)" if tm.reference_voltage is not None else "")
               + f", u the command lagged by T_m = {1000 * ident.time_constant.value:.1f} ms; "
               f"R^2 {tm.r2:.3f} over {tm.windows} windows of {stretches} airborne stretch(es); "
               f"T(1) = {full:.4g} +- {1.96 * tm.full_thrust_se():.2g} N")
    thrust = Estimate(b, (b - half, b + half), f"IMU + commands: b = T(1) / max_speed^2 with "
                      f"the skeleton's max_speed {skeleton.max_speed:.5g} rad/s; {summary}")
    count = len(skeleton.positions)
    table = {"command": grid.tolist(), "speed": [speed.tolist()] * count,
             "reference_voltage": tm.reference_voltage,
             "voltage_gain": tm.voltage_gain if tm.reference_voltage is not None else 0.0,
             "time_constant": round(float(ident.time_constant.value), 5),
             "time_constant_ci": tuple(float(v) for v in ident.time_constant.ci95)}
    roll, pitch = ident.torque_per_command
    tau, (tau_lo, tau_hi) = ident.time_constant.value, ident.time_constant.ci95
    notes = [(f"motor time constant T_m = {1000 * tau:.1f} ms, 95 % {1000 * tau_lo:.1f}-"
              f"{1000 * tau_hi:.1f} ms ({ident.time_constant.quality})"),
             (f"roll torque per unit command difference {roll.value:.4g} N m (95 % "
              f"{roll.ci95[0]:.4g}-{roll.ci95[1]:.4g}), pitch {pitch.value:.4g} N m "
              f"({roll.quality})"),
             (f"balances' R^2: thrust {ident.r2[0]:.3f}, roll {ident.r2[1]:.3f}, pitch "
              f"{ident.r2[2]:.3f}"), *ident.notes]
    # an inertia not identified is the skeleton's (or the default), as with rotor speeds
    inertia = []
    for k, e in enumerate(ident.inertia):
        if e.identified:
            inertia.append(e)
            continue
        value, own = kept_inertia(skeleton, k)
        inertia.append(Estimate(value, (float("nan"),) * 2, e.quality, False,
                                f"{e.why}; {'the skeleton' if own else 'the default'}'s "
                                f"{value:.4g} kg m^2 kept"))
    out = LogIdentification(thrust, [], inertia, table, summary, True, notes)
    out.warnings.append("no rotor speeds in any log: b and the motor map are identified "
                        "only as the product b Omega^2 (speed scale from max_speed); the "
                        "spins, Izz and d are not identified (the rotor order is checked by "
                        "the roll/pitch balance of the commands)")
    out.warnings += [e.why for e in inertia if not e.identified]
    return out
