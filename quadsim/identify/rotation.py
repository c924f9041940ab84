"""Roll and pitch inertia from the band where the rotors drive the body (pure math).

The whole-band fit of :func:`quadsim.identify.from_logs.fit_inertia` regresses the rotor torque
on the angular acceleration at every frequency. In translating flight most of the roll/pitch
torque of the measured rotor speeds, below ~2 Hz, balances aerodynamic moments (blade
flapping, the rotor drag's lever) and turns the body little: that torque has no angular
acceleration to go with it, and the fit explains too little to give an inertia (CHANGELOG.md:
Docstrings as contracts). Between ``BAND_HZ`` the
rotors drive the body: there the measured moment follows ``b l dOmega^2`` with a flat gain and
a few milliseconds of delay (docs/nanodrone.md, "Why the rotor speeds over-predict roll and
pitch"; the per-run tables: benchmarks/HISTORY.md, "Rotation: what the logs say").

Per log: torque ``tau = b sum_i y_i Omega_i^2`` (roll; pitch ``-b sum_i x_i Omega_i^2``) and
the body terms ``wdot_x`` and ``w_y w_z`` (roll; pitch ``wdot_y``, ``w_x w_z``) are band-passed
alike (zero-phase 4th-order Butterworth, ``BAND_HZ``); the torque is delayed by the log's own
lag ``d`` of the moment behind the logged torque (the grid ``DELAY_GRID_S`` value with the best
R^2, since the timing between rotor data and state differs per log by up to tens of ms on real
logs; negative when the rotor data are logged late) and
``tau(t - d) = I_xx wdot_x + (I_zz - I_yy) w_y w_z`` is solved by least squares over all logs.
Interval: delete-one-log jackknife (delete-one-block over ``BLOCKS`` blocks for one log), so
the spread between logs is in it. Identified when R^2 >= ``BAND_R2`` and the 95 % half-width
is below ``BAND_CI`` of the value, as the whole-band fit is; logs sampled below
``2.5 BAND_HZ[1]`` cannot show the band and leave the axis unidentified.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from ..gap.calibrate import BAND_HZ, BAND_R2
from .logseries import Estimate, LogSeries, Skeleton, confidence_interval

#: per-log delay of the torque behind the body terms (s): real logs' rotor-data timing is off
#: by up to +-17.5 ms (nano-drone benchmark, per run), 2.5 ms steps (~9 deg at 10 Hz)
DELAY_GRID_S = tuple(float(d) for d in np.round(np.arange(-0.030, 0.0301, 0.0025), 4))
#: acceptance's 95 % half-width, as the whole-band fit (quadsim.identify.from_logs INERTIA_CI);
#: the band (BAND_HZ) and R^2 (BAND_R2) are the gap calibration's, one source for both
BAND_CI = 0.15
#: jackknife blocks when only one log is given
BLOCKS = 8


def _shift(x: np.ndarray, delay_samples: float) -> np.ndarray:
    n = np.arange(len(x), dtype=float)
    return np.interp(n - delay_samples, n, x)


def band_parts(torque: np.ndarray, accel: np.ndarray, gyro: np.ndarray, rate: float):
    """Band-passed (torque (N,), body terms (N, 2)) of one log per delay of
    :data:`DELAY_GRID_S` (module doc), or None when the log is sampled too slowly for the
    band. ``torque``: the rotors' moment about one body axis (N m); ``accel``: that axis'
    angular acceleration (rad/s^2); ``gyro``: its gyroscopic product (rad^2/s^2: ``w_y w_z``
    for roll, ``w_x w_z`` for pitch); ``rate``: the samples' rate (Hz, uniform)."""
    if rate < 2.5 * BAND_HZ[1]:
        return None
    sos = signal.butter(4, BAND_HZ, btype="bandpass", fs=rate, output="sos")
    band = lambda x: signal.sosfiltfilt(sos, x, axis=0)               # noqa: E731
    body = band(np.column_stack([accel, gyro]))
    return {d: (band(_shift(np.asarray(torque, float), d * rate)), body) for d in DELAY_GRID_S}


def _band_parts(log: LogSeries, skeleton: Skeleton, b: float, axis: int):
    """:func:`band_parts` of one log's rotor torque ``b sum_i y_i Omega_i^2`` (roll; pitch
    ``-b sum_i x_i Omega_i^2``)."""
    dt = float(np.median(np.diff(log.t)))
    arms = skeleton.positions - skeleton.com
    omega2 = np.square(log.rotor_speed)
    torque = b * (omega2 @ arms[:, 1] if axis == 0 else -(omega2 @ arms[:, 0]))
    w = log.body_rate
    gyro = w[:, 1] * w[:, 2] if axis == 0 else w[:, 0] * w[:, 2]
    return band_parts(torque, log.body_accel[:, axis], gyro, 1.0 / dt)


def _solve(parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, float]:
    y = np.concatenate([p[0] for p in parts])
    x = np.vstack([p[1] for p in parts])
    coef = np.linalg.lstsq(x, y, rcond=None)[0]
    u = y - x @ coef
    return coef, 1.0 - float(u @ u) / float(np.sum((y - y.mean()) ** 2))


def band_estimate(per_log: list[dict], name: str) -> Estimate | None:
    """The inertia ``name`` (kg m^2) from the :func:`band_parts` of each log (module doc:
    each log at its own best delay, least squares over all, delete-one-log jackknife, the
    acceptance); None without a log that shows the band."""
    per_log = [p for p in per_log if p is not None]
    if not per_log:
        return None
    best = [max(p, key=lambda d, p=p: _solve([p[d]])[1]) for p in per_log]
    parts = [p[d] for p, d in zip(per_log, best)]
    coef, r2 = _solve(parts)
    value = float(coef[0])
    if len(parts) >= 3:
        reps = [_solve(parts[:k] + parts[k + 1:])[0][0] for k in range(len(parts))]
    else:
        reps = []
        for k in range(BLOCKS):
            cut = []
            for y, x in parts:
                keep = np.ones(len(y), bool)
                keep[k * len(y) // BLOCKS:(k + 1) * len(y) // BLOCKS] = False
                cut.append((y[keep], x[keep]))
            reps.append(_solve(cut)[0][0])
    reps = np.asarray(reps)
    g = len(reps)
    se = float(np.sqrt((g - 1) / g * np.sum((reps - reps.mean()) ** 2)))
    delays = ", ".join(f"{1e3 * d:+.1f}" for d in best)
    quality = (f"band {BAND_HZ[0]:g}-{BAND_HZ[1]:g} Hz least squares of the rotor torque on "
               f"the angular acceleration (quadsim.identify.rotation), per-log lag of the "
               f"moment behind the logged torque {delays} ms; R^2 {r2:.3f}; 95 % half-width "
               f"{100 * 1.96 * se / abs(value):.1f} % (delete-one-"
               f"{'log' if len(parts) >= 3 else 'block'} jackknife)")
    if value > 0 and r2 >= BAND_R2 and 1.96 * se < BAND_CI * value:
        return Estimate(value, confidence_interval(value, se), quality)
    why = (f"band {BAND_HZ[0]:g}-{BAND_HZ[1]:g} Hz fit {name} {value:.3g} kg m^2, "
           f"R^2 {r2:.2f}, 95 % half-width {1.96 * se:.2g} kg m^2: below the "
           f"acceptance (R^2 >= {BAND_R2}, half-width < {100 * BAND_CI:.0f} %)")
    return Estimate(value, confidence_interval(value, se), quality, False, why)


def band_inertia(logs: list[LogSeries], skeleton: Skeleton, b: float) -> list[Estimate | None]:
    """[Ixx, Iyy] (kg m^2) from ``BAND_HZ`` (see module); ``None`` for an axis no log can show.

    logs: the logs with rotor speeds (LogSeries, uniform grid); b: thrust factor (N s^2/rad^2).
    An estimate below the acceptance has ``identified=False`` and its reason in ``why``."""
    return [band_estimate([_band_parts(s, skeleton, b, axis) for s in logs
                           if s.rotor_speed is not None], name)
            for axis, name in ((0, "Ixx"), (1, "Iyy"))]


def with_band_inertia(inertia: list[Estimate], logs: list[LogSeries], skeleton: Skeleton,
                      b: float) -> list[Estimate]:
    """The whole-band estimates, each one not identified replaced by the band estimate when
    that is identified (else its reason gets the band fit's appended)."""
    band = band_inertia(logs, skeleton, b)
    out = []
    for whole, part in zip(inertia, band):
        if whole.identified or part is None:
            out.append(whole)
        elif part.identified:
            out.append(Estimate(part.value, part.ci95,
                                part.quality + "; the whole-band fit not used: " + whole.why))
        else:
            out.append(Estimate(whole.value, whole.ci95, whole.quality, False,
                                whole.why + "; " + part.why))
    return out


__all__ = ["BAND_CI", "BAND_HZ", "BAND_R2", "DELAY_GRID_S", "band_estimate", "band_inertia",
           "band_parts", "with_band_inertia"]
