"""Blade flapping per body axis from flight logs, below the band where the rotors drive the body
(pure math).

In translating flight the roll/pitch torque of the measured rotor speeds, below ~2 Hz, turns
the body little: most of it balances an aerodynamic moment, the flapping moment of rotors in
edgewise flow (:mod:`quadsim.effects.blade_flapping`, rotor axes along body z)::

    M = tau + c f,        f = sum_i Omega_i (v_y, -v_x)        (roll, pitch; (rad/s)(m/s))

with ``tau`` the rotors' moment (N m: roll ``b sum_i y_i Omega_i^2``, pitch ``-b sum_i x_i
Omega_i^2``), ``M`` the moment the body shows (N m: roll ``I_xx wdot_x + (I_zz - I_yy) w_y
w_z``, pitch ``I_yy wdot_y + (I_xx - I_zz) w_x w_z``), ``v`` the body-frame velocity (m/s;
still air) and ``c`` the effect's ``roll`` or ``pitch`` coefficient (kg m/rad).

Per axis and log ``k``: ``tau - M`` and ``f`` are low-passed alike below :data:`CUTOFF_HZ`
(zero-phase 2nd-order Butterworth of each signal less its mean) and each log's mean is
removed (each log its own constant: a CoM offset or trim torque that does not move with the
air speed); then ``tau - M = -c f`` by least squares over every log's samples together::

    c = -sum_k f_k . (tau - M)_k / sum_k f_k . f_k

Interval: delete-one-log jackknife, 95 % = value +- 1.96 se, so the spread between logs (the
flapping's dependence on speed, battery, regime) is in it. Identified when at least
:data:`MIN_LOGS` logs give the jackknife and the 95 % interval excludes 0; otherwise the value
is reported with the reason and not used.

This is the estimator of ``benchmarks.rotation_analysis --write-effects`` (its
``low_band_pooled`` calls :func:`flapping_estimate`); what it reads on the nano-drone
benchmark's training runs: docs/identification.md, "Blade flapping per axis from the logs".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from .logseries import Estimate, LogSeries, Skeleton, confidence_interval

#: below this (Hz) the rotors' roll/pitch torque balances air moments and the body barely turns
#: (on the nano-drone training runs the rotor-speed differences track the angular
#: acceleration only between ~1.5 and 8 Hz, issue 45; benchmarks/HISTORY.md, "Rotation: what
#: the logs say"); above it the angular acceleration, the inertia's uncertainty and the rotor-data
#: timing (up to +-17.5 ms per log) dominate the difference tau - M. The value is
#: rotation_analysis's, whose results (9.54e-8 / 1.35e-7) the estimator reproduces
CUTOFF_HZ = 2.0
#: the delete-one-log jackknife needs this many logs: with two its two replicates give no
#: usable spread (the same count as quadsim.identify.rotation's delete-one-log jackknife)
MIN_LOGS = 3
#: the library's parameter per axis (quadsim.effects.blade_flapping)
AXES = ("roll", "pitch")


@dataclass(frozen=True)
class FlappingPart:
    """One log's low-passed, mean-removed signals on one axis: ``regressor`` f (N,)
    (rad/s)(m/s) and ``balance`` tau - M (N,) N m (module doc)."""

    name: str
    regressor: np.ndarray
    balance: np.ndarray


def flapping_regressor(rotor_speed: np.ndarray, velocity_body: np.ndarray) -> np.ndarray:
    """(N, 2) roll, pitch regressor ``sum_i Omega_i (v_y, -v_x)`` ((rad/s)(m/s)) from the
    rotor speeds (N, R) rad/s and the body-frame velocity (N, 3) m/s: the moment of
    :func:`quadsim.effects.blade_flapping.flapping_moment` per unit coefficient, rotors along
    body z."""
    s = np.sum(np.abs(np.asarray(rotor_speed, float)), axis=1)
    v = np.asarray(velocity_body, float)
    return np.column_stack([s * v[:, 1], -s * v[:, 0]])


def flapping_part(name: str, torque: np.ndarray, moment: np.ndarray, regressor: np.ndarray,
                  rate: float, *, cutoff_hz: float = CUTOFF_HZ) -> FlappingPart:
    """:class:`FlappingPart` of one log on one axis: ``torque`` tau (N,) N m, ``moment`` M
    (N,) N m, ``regressor`` f (N,) (rad/s)(m/s), ``rate`` the samples' rate (Hz, uniform),
    low-passed below ``cutoff_hz`` (default :data:`CUTOFF_HZ`; module doc)."""
    sos = signal.butter(2, cutoff_hz, fs=rate, output="sos")
    low = lambda x: signal.sosfiltfilt(sos, x - x.mean())            # noqa: E731
    diff = low(np.asarray(torque, float)) - low(np.asarray(moment, float))
    f = low(np.asarray(regressor, float))
    return FlappingPart(name, f - f.mean(), diff - diff.mean())


def _fit(parts: list[FlappingPart]) -> float:
    x = np.concatenate([p.regressor for p in parts])
    y = np.concatenate([p.balance for p in parts])
    return -float(x @ y) / float(x @ x)


def flapping_estimate(parts: list[FlappingPart], axis: str) -> Estimate:
    """The coefficient ``axis`` (``roll`` or ``pitch``, kg m/rad) from the logs' parts
    (module doc: pooled least squares, delete-one-log jackknife, the acceptance). Not
    identified (``identified=False``, the reason in ``why``) with fewer than
    :data:`MIN_LOGS` logs (interval nan) or an interval that includes 0; the quality names
    each log's own value."""
    n = len(parts)
    value = _fit(parts)
    per_log = ", ".join(f"{_fit([p]):.3g}" for p in parts)
    if n >= MIN_LOGS:
        reps = np.array([_fit(parts[:k] + parts[k + 1:]) for k in range(n)])
        se = float(np.sqrt((n - 1) / n * np.sum((reps - reps.mean()) ** 2)))
        ci = confidence_interval(value, se)
    else:
        se, ci = float("nan"), (float("nan"), float("nan"))
    quality = (f"below {CUTOFF_HZ:g} Hz least squares of the rotor torque less the body's "
               f"moment on the flapping regressor sum Omega (v_y, -v_x), {n} log(s) together, "
               f"each its own constant (quadsim.identify.flapping); per log {per_log}; 95 % "
               f"+- {1.96 * se:.2g} (delete-one-log jackknife)")
    if n < MIN_LOGS:
        why = (f"blade flapping {axis} not identified: {n} log(s), the delete-one-log "
               f"jackknife needs {MIN_LOGS} (fit {value:.3g} kg m/rad, no interval)")
        return Estimate(value, ci, quality, False, why)
    if ci[0] <= 0.0 <= ci[1]:
        why = (f"blade flapping {axis} not identified: {value:.3g} kg m/rad, 95 % "
               f"[{ci[0]:.3g}, {ci[1]:.3g}] includes 0")
        return Estimate(value, ci, quality, False, why)
    return Estimate(value, ci, quality)


def body_moment(body_rate: np.ndarray, body_accel: np.ndarray,
                inertia: tuple[float, float, float]) -> np.ndarray:
    """(N, 2) roll, pitch moment the body shows, ``J wdot + w x J w`` (N m) for a diagonal
    inertia (Ixx, Iyy, Izz) kg m^2, body rate (N, 3) rad/s and angular acceleration (N, 3)
    rad/s^2."""
    ixx, iyy, izz = inertia
    w, a = np.asarray(body_rate, float), np.asarray(body_accel, float)
    return np.column_stack([ixx * a[:, 0] + (izz - iyy) * w[:, 1] * w[:, 2],
                            iyy * a[:, 1] + (ixx - izz) * w[:, 0] * w[:, 2]])


def identify_flapping(logs: list[LogSeries], skeleton: Skeleton, b: float,
                      inertia: tuple[float, float, float]) -> list[Estimate | None]:
    """[roll, pitch] blade flapping (kg m/rad) of the logs with rotor speeds and a body-frame
    velocity (:class:`LogSeries` ``velocity``); b the thrust factor (N s^2/rad^2), inertia the
    diagonal (Ixx, Iyy, Izz) kg m^2 the body's moment is taken with; ``[None, None]`` without
    such a log."""
    usable = [s for s in logs if s.rotor_speed is not None and s.velocity is not None]
    if not usable:
        return [None, None]
    arms = skeleton.positions - skeleton.com
    parts: list[list[FlappingPart]] = [[], []]
    for s in usable:
        rate = 1.0 / float(np.median(np.diff(s.t)))
        omega2 = np.square(s.rotor_speed)
        torque = b * np.column_stack([omega2 @ arms[:, 1], -(omega2 @ arms[:, 0])])
        moment = body_moment(s.body_rate, s.body_accel, inertia)
        f = flapping_regressor(s.rotor_speed, s.velocity)
        for axis in range(2):
            parts[axis].append(flapping_part(s.name, torque[:, axis], moment[:, axis],
                                             f[:, axis], rate))
    return [flapping_estimate(parts[axis], name) for axis, name in enumerate(AXES)]


__all__ = ["AXES", "CUTOFF_HZ", "MIN_LOGS", "FlappingPart", "body_moment", "flapping_estimate",
           "flapping_part", "flapping_regressor", "identify_flapping"]
