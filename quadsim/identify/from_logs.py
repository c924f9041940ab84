"""A vehicle's rotor factors, motor map and inertia from its own flight logs (pure math).

What a user measures by hand (mass on a scale, rotor positions and spins with a ruler, the
propeller radius) is a *skeleton* (:mod:`.skeleton`); this module adds what the logs
determine, each with a 95 % interval and the fit quality. Input: one :class:`LogSeries` per
log (smoothed on a uniform grid, SI, body frame x forward / y left / z up; ground and idle
spans already cut). ``python -m quadsim.identify --logs`` loads and smooths the logs, runs
:func:`identify_from_logs`, adds the drag factor d (the gap's instrumental-variables refit)
and writes the parameter set (:mod:`.vehicle_set`). The data types are in :mod:`.logseries`,
the motor map and the commands-only thrust map in :mod:`.motor_fits`.

Fits (N samples pooled over the logs; rotor i at (x_i, y_i) from the CoM, spin s_i = +1 ccw)

* **thrust factor b** (N s^2/rad^2): least squares through the origin of the body-z force
  balance ``m f_z = b sum_i Omega_i^2`` (f_z the accelerometer's specific force, m the
  skeleton's mass). Standard error ``s sqrt(tau / sum x^2)`` with tau the residual's
  integrated autocorrelation time (samples). Per log as well: two logs whose b differ by
  more than :data:`MIX_TOLERANCE` *and* beyond their combined 95 % interval are refused as
  logs of different vehicles. A thrust curve ``b Omega^2 + c0`` per rotor is scored on
  held-out logs (leave one log out) and reported where it lowers the held-out error.
* **rotor order and spins**: the angular accelerations are regressed on the torque patterns
  ``sum y_i Omega_i^2`` (roll), ``-sum x_i Omega_i^2`` (pitch) and ``-sum s_i Omega_i^2``
  (yaw) of every assignment of log columns to skeleton rotors (R! of them); the skeleton's
  order must explain roll and pitch (R^2) within :data:`ORDER_MARGIN` of the best, and the
  yaw slope (d / Izz) must be positive, else the spins are reversed. With roll and pitch
  R^2 below :data:`WEAK_R2` the order cannot be told and is not checked (a named warning).
* **inertia** Ixx, Iyy (kg m^2): ``I_xx wdot_x + (I_zz - I_yy) w_y w_z = b sum y_i Omega_i^2``
  (and pitch) by least squares of the torque on the angular acceleration (noise on the
  speeds enters the dependent side and does not bias it; noise on the differentiated gyro
  biases it low). The commanded speeds are no instrument here: in closed loop the attitude
  controller computes them from the same gyro. Identified when the 95 % half-width is below
  :data:`INERTIA_CI` of the value and R^2 >= :data:`INERTIA_R2`, else the skeleton's value
  (or the default) is kept and named. Izz and d enter the yaw balance only as d/Izz: Izz
  stays the skeleton's (or the default) and d is identified given it. Where the whole-band
  fit is too weak (translating flight: the rotor torque below ~2 Hz balances aerodynamic
  moments), Ixx and Iyy come from the 4-16 Hz band where the rotors drive the body, with each
  log's rotor-data delay (:mod:`quadsim.identify.rotation`), when that fit passes the same
  acceptance.
* **motor map** per rotor: ``Omega = L_tau[a_i + k_i cmd_i (1 + gamma (v - v_ref))]`` with
  L_tau a first-order lag (time constant tau, s, one for all rotors, from a grid), v the
  battery voltage (V) and v_ref its median; saturated commands (>= :data:`SATURATED`) are
  left out. Stored as the map at cmd 0 and 1 at v_ref, ``voltage_gain`` gamma (1/V) and
  ``time_constant`` tau.
* **blade flapping** per axis (``roll``, ``pitch``, kg m/rad; the library's
  ``blade_flapping``): below 2 Hz the rotor torque less the body's moment (with the inertia
  above) on the flapping regressor ``sum_i Omega_i (v_y, -v_x)``, the logs together, each its
  own constant, 95 % by a delete-one-log jackknife (:mod:`quadsim.identify.flapping`);
  identified when 3 or more logs give the interval and it excludes 0. Logs without a body
  velocity (:class:`LogSeries` ``velocity`` None) are left out of it.
* **commands only** (no rotor speeds in any log): ``m f_z = sum_i T(u_i)``, with u = cmd
  (1 + gamma (v - v_ref)) and ``T(u) = c2 u^2 + c1 u`` per rotor alike; the rotor-speed scale
  is then the skeleton's ``max_speed`` at u = 1 (b = T(1) / max_speed^2, and the motor map
  follows ``Omega(u) = sqrt(T(u) / b)``): only the product b Omega^2 is identified.

Example::

    >>> ident = identify_from_logs(series, skeleton)
    >>> ident.thrust.value, ident.thrust.ci95
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from ..core.errors import InputError
from .flapping import identify_flapping
from .logseries import (
    MIX_TOLERANCE,
    Estimate,
    LogIdentification,
    LogSeries,
    Skeleton,
    confidence_interval,
    correlation_time,
    origin_fit,
    refuse_mixed,
)
from .motor_fits import LAG_GRID_S, SATURATED, commanded_speed, fit_command_thrust, fit_motor_map
from .rotation import with_band_inertia
from .sanity import r2_text

#: the skeleton's rotor order must reach the best order's roll/pitch R^2 within this; below
#: WEAK_R2 per axis the order (and, for yaw, the spins) cannot be checked.
ORDER_MARGIN = 0.05
WEAK_R2 = 0.05
#: inertia is identified when its 95 % half-width is below this fraction of the value and
#: the torque explains at least INERTIA_R2 of the angular acceleration's variance.
INERTIA_CI = 0.15
INERTIA_R2 = 0.5

#: default inertia without a skeleton value: Ixx = Iyy = 0.2 m r^2, Izz = 0.35 m r^2 (r the
#: mean rotor distance; the Crazyflie 2.x 0.21/0.29 and the testbed 0.21/0.41).
DEFAULT_INERTIA = (0.2, 0.2, 0.35)




# ----------------------------------------------------------------------------- thrust


def fit_thrust(logs: list[LogSeries],
               mass: float) -> tuple[Estimate, list[tuple[str, float, float]]]:
    """b from ``m f_z = b sum Omega^2`` pooled and per log; refuses mixed vehicles."""
    xs = [np.sum(np.square(s.rotor_speed), axis=1) for s in logs]
    ys = [mass * s.specific_force[:, 2] for s in logs]
    per_log = []
    for s, x, y in zip(logs, xs, ys):
        beta, se, _ = origin_fit(x, y)
        per_log.append((s.name, beta, se))
    refuse_mixed(per_log, "rotor_*: b (N s^2/rad^2)")
    beta, se, r2 = origin_fit(np.concatenate(xs), np.concatenate(ys))
    spread = np.std([b for _, b, _ in per_log], ddof=1) if len(per_log) > 1 else 0.0
    quality = (f"{r2_text(r2)} over {sum(len(x) for x in xs)} samples of {len(logs)} log(s); "
               f"per-log std {spread:.3g}")
    return Estimate(beta, confidence_interval(beta, se), quality), per_log


def thrust_curve_score(logs: list[LogSeries], mass: float) -> str:
    """Leave-one-log-out (one log: its halves): does ``b Omega^2 + c0`` per rotor beat
    ``b Omega^2``? (one line)"""
    rows = [(np.sum(np.square(s.rotor_speed), 1), s.rotor_speed.shape[1],
             mass * s.specific_force[:, 2]) for s in logs]
    unit = "log"
    if len(rows) == 1:           # one log: its two halves
        x, count, y = rows[0]
        half = len(x) // 2
        rows, unit = [(x[:half], count, y[:half]), (x[half:], count, y[half:])], "half"
    err_quad = err_curve = 0.0
    offsets = []
    for k in range(len(rows)):
        train = [r for i, r in enumerate(rows) if i != k]
        x = np.concatenate([r[0] for r in train])
        y = np.concatenate([r[2] for r in train])
        count = train[0][1]
        b = float(x @ y) / float(x @ x)
        design = np.stack([x, np.full_like(x, count)], 1)
        (b2, c0), *_ = np.linalg.lstsq(design, y, rcond=None)
        offsets.append(c0)
        xk, _, yk = rows[k]
        err_quad += float(np.sum((yk - b * xk) ** 2))
        err_curve += float(np.sum((yk - b2 * xk - c0 * count) ** 2))
    gain = 1.0 - err_curve / err_quad
    verdict = ("supported: the engines' b Omega^2 is kept; the thrust_curve effect models it"
               if gain > 0.05 else "not supported: b Omega^2 is enough")
    return (f"thrust curve b Omega^2 + c0 per rotor (c0 = {np.mean(offsets):.3g} N): held-out "
            f"squared error {-100 * gain:+.1f} % against b Omega^2 alone, leave one {unit} "
            f"out over {len(rows)} {'halves' if unit == 'half' else 'logs'}: {verdict}")


# ----------------------------------------------------------------------------- geometry


def _patterns(omega2: np.ndarray, arms: np.ndarray, spins: np.ndarray) -> np.ndarray:
    """(N, 3) roll, pitch, yaw torque patterns per unit b (roll, pitch) and d (yaw)."""
    return np.stack([omega2 @ arms[:, 1], -(omega2 @ arms[:, 0]), -(omega2 @ spins)], 1)


def _r2(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    x = x - x.mean()
    y = y - y.mean()
    denom = float(x @ x)
    if denom <= 0:
        return 0.0, 0.0
    slope = float(x @ y) / denom
    u = y - slope * x
    return slope, 1.0 - float(u @ u) / max(float(y @ y), 1e-300)


def check_rotor_order(logs: list[LogSeries], skeleton: Skeleton) -> list[str]:
    """Refuse a skeleton whose rotor order or spins the logs contradict; notes otherwise.

    Not :func:`quadsim.logs.checks.check_rotor_order` (``gap``, ``view``, ``convert
    --model``), which judges one log's columns against a complete parameter set (inertia,
    b, d) by Delta chi^2: here no parameter set exists yet (the skeleton has positions and
    spins, b and the inertia are what is being identified), the logs are pooled, the fix is
    the skeleton's ``[[rotor]]`` order, and the spins are checked too (the yaw slope's
    sign), which no column order can repair."""
    omega2 = np.concatenate([np.square(s.rotor_speed) for s in logs])
    accel = np.concatenate([s.body_accel for s in logs])
    arms = skeleton.positions - skeleton.com
    count = len(arms)

    def score(order):
        p = _patterns(omega2[:, list(order)], arms, skeleton.spins)
        fits = [_r2(p[:, k], accel[:, k]) for k in range(3)]
        return fits, fits[0][1] + fits[1][1]

    own_fits, own = score(range(count))
    best_order, best = tuple(range(count)), own
    if count <= 8:
        for order in itertools.permutations(range(count)):
            fits, total = score(order)
            if fits[0][0] > 0 and fits[1][0] > 0 and total > best + 1e-9:
                best_order, best = order, total
    inverse = [0] * count
    for k, col in enumerate(best_order):
        inverse[col] = k
    weak = max(best, own) < 2 * WEAK_R2
    if not weak and (best - own > 2 * ORDER_MARGIN or own_fits[0][0] <= 0
                     or own_fits[1][0] <= 0):
        mapping = ",".join(str(inverse[i] + 1) for i in range(count))
        raise InputError(
            f"{skeleton.path}: rotor: the logs show the rotors in another order: roll+pitch "
            f"R^2 {own:.2f} with the skeleton's order, {best:.2f} when log columns rotor_1.."
            f"{count} are the skeleton's rotors {mapping}; reorder the [[rotor]] entries (or "
            "convert the logs with --rotor-map)")
    slope_yaw, r2_yaw = own_fits[2]
    if slope_yaw < 0 and r2_yaw > WEAK_R2:
        raise InputError(
            f"{skeleton.path}: rotor.spin: the yaw torque has the wrong sign for these spins "
            f"(yaw acceleration against -sum s_i Omega_i^2: slope {slope_yaw:.3g}, R^2 "
            f"{r2_yaw:.2f}): the rotors spin the other way; swap every 'ccw' and 'cw'")
    fits = (f"roll R^2 {own_fits[0][1]:.2f}, pitch R^2 {own_fits[1][1]:.2f}, yaw R^2 "
            f"{r2_yaw:.2f}")
    if weak:
        return [f"rotor order and spins not checked: {fits} (too little roll and pitch in the "
                "logs to tell one rotor order from another); the skeleton's are kept"]
    return [f"rotor order and spins: {fits} with positive yaw slope: the skeleton's order "
            "and spins match the logs"
            + ("" if r2_yaw > WEAK_R2 else " (yaw too weakly excited to confirm the spins)")]


# ----------------------------------------------------------------------------- inertia


def fit_inertia(logs: list[LogSeries], skeleton: Skeleton, b: float,
                defaults: np.ndarray) -> list[Estimate]:
    """Ixx, Iyy by least squares of the rotor torque on the angular acceleration (see
    module); the skeleton's value (or the default) is kept where the fit is too weak."""
    arms = skeleton.positions - skeleton.com
    accel = np.concatenate([s.body_accel for s in logs])
    rate = np.concatenate([s.body_rate for s in logs])
    torque = b * _patterns(np.concatenate([np.square(s.rotor_speed) for s in logs]), arms,
                           skeleton.spins)
    out = []
    gyro = (rate[:, 1] * rate[:, 2], rate[:, 0] * rate[:, 2])
    for axis, name in ((0, "Ixx"), (1, "Iyy")):
        y = torque[:, axis]
        x = np.stack([accel[:, axis], gyro[axis]], 1)
        coef, *_ = np.linalg.lstsq(x, y, rcond=None)
        u = y - x @ coef
        cov = np.linalg.inv(x.T @ x) * float(u @ u) / max(1, len(u) - 2) * correlation_time(u)
        value, se = float(coef[0]), float(math.sqrt(max(cov[0, 0], 0.0)))
        keep = float(skeleton.inertia[axis]) if skeleton.inertia is not None else float(
            defaults[axis])
        kept_from = "the skeleton's value" if skeleton.inertia is not None else "the default"
        r2 = 1.0 - float(u @ u) / float(np.sum((y - y.mean()) ** 2))
        quality = (f"least squares of the rotor torque on the angular acceleration; R^2 "
                   f"{r2:.3f}; 95 % half-width {100 * 1.96 * se / abs(value):.1f} %")
        if value > 0 and 1.96 * se < INERTIA_CI * value and r2 >= INERTIA_R2:
            out.append(Estimate(value, confidence_interval(value, se), quality))
        else:
            reason = (f"R^2 {r2:.2f} below {INERTIA_R2}: the torque of the logged rotor speeds "
                      f"explains too little of the angular acceleration" if r2 < INERTIA_R2
                      else f"95 % half-width {1.96 * se:.2g} kg m^2 wider than "
                           f"{100 * INERTIA_CI:.0f} %")
            why = (f"too little excitation for inertia: {name} fit {value:.3g} kg m^2, "
                   f"{reason}; {kept_from} {keep:.4g} kg m^2 kept")
            out.append(Estimate(keep, (float("nan"), float("nan")), quality, False, why))
    return out


# ----------------------------------------------------------------------------- all of it


def default_inertia(skeleton: Skeleton) -> np.ndarray:
    """The documented default inertia (kg m^2) from mass and rotor distance (see module)."""
    r = float(np.mean(np.linalg.norm((skeleton.positions - skeleton.com)[:, :2], axis=1)))
    return skeleton.mass * r * r * np.asarray(DEFAULT_INERTIA)


def kept_inertia(skeleton: Skeleton, axis: int) -> tuple[float, bool]:
    """(the principal moment kg m^2 of body ``axis`` (0 x, 1 y, 2 z) that a set keeps where
    the logs do not identify it, whether it is the skeleton's): the skeleton's, else
    :func:`default_inertia`'s."""
    if skeleton.inertia is not None:
        return float(skeleton.inertia[axis]), True
    return float(default_inertia(skeleton)[axis]), False


def identify_from_logs(logs: list[LogSeries], skeleton: Skeleton) -> LogIdentification:
    """Thrust factor, rotor order and spins, inertia (x, y) and motor map (see module). The
    drag factor d is added by the caller (it needs the gap's model of the yaw torque)."""
    if not logs:
        raise InputError("--logs: no log given")
    counts = {s.rotor_speed.shape[1] if s.rotor_speed is not None else s.command.shape[1]
              for s in logs}
    if counts != {len(skeleton.positions)}:
        raise InputError(f"{logs[0].name}: rotor_*: {sorted(counts)} rotor column(s) in the "
                         f"logs, {len(skeleton.positions)} rotors in {skeleton.path}")
    defaults = default_inertia(skeleton)
    with_speed = [s for s in logs if s.rotor_speed is not None]
    if not with_speed:
        if any(s.command is None for s in logs):
            raise InputError(f"{logs[0].name}: cmd_*: neither rotor speeds nor commands")
        thrust, table, summary = fit_command_thrust(logs, skeleton)
        inertia = [Estimate(kept_inertia(skeleton, k)[0], (float("nan"),) * 2, "", False,
                            "not identified: without rotor speeds the body torques are "
                            "unknown; " + ("the skeleton's" if kept_inertia(skeleton, k)[1]
                                           else "the default") + " value kept")
                   for k in range(2)]
        ident = LogIdentification(thrust, [], inertia, table, summary, True)
        ident.warnings.append("no rotor speeds in any log: b and the motor map are "
                              "identified only as the product b Omega^2 (speed scale from "
                              "max_speed); rotor order, spins, inertia and d are not "
                              "identified")
        return ident
    if len(with_speed) < len(logs):
        ident_warn = [f"{len(logs) - len(with_speed)} log(s) without rotor speeds left out "
                      "of the rotor fits"]
    else:
        ident_warn = []
    thrust, per_log = fit_thrust(with_speed, skeleton.mass)
    notes = check_rotor_order(with_speed, skeleton)
    ident_warn += [n for n in notes if "not checked" in n]
    curve = thrust_curve_score(with_speed, skeleton.mass)
    with_cmd = [s for s in with_speed if s.command is not None]
    motor = fit_motor_map(with_cmd) if with_cmd else None
    inertia = with_band_inertia(fit_inertia(with_speed, skeleton, thrust.value, defaults),
                                with_speed, skeleton, thrust.value)
    izz = kept_inertia(skeleton, 2)[0]
    flapping = identify_flapping(with_speed, skeleton, thrust.value,
                                 (inertia[0].value, inertia[1].value, izz))
    ident = LogIdentification(thrust, per_log, inertia, motor, curve, False, notes,
                              ident_warn, [e for e in flapping if e is not None])
    ident.warnings += [e.why for e in inertia if not e.identified]
    return ident


__all__ = ["MIX_TOLERANCE", "Estimate", "LogIdentification", "LogSeries", "Skeleton", "LAG_GRID_S",
           "SATURATED", "check_rotor_order", "commanded_speed", "correlation_time",
           "default_inertia", "fit_command_thrust", "fit_inertia", "fit_motor_map",
           "fit_thrust", "identify_from_logs", "thrust_curve_score"]
