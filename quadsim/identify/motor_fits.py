"""The command -> rotor-speed map (with battery voltage and motor lag) and the commands-only
command -> thrust map of ``identify --logs``; formulas in :mod:`quadsim.identify.from_logs`.

Example::

    >>> from quadsim.identify.motor_fits import fit_motor_map
    >>> fit_motor_map(series)["time_constant"]        # s, series: LogSeries per log
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import InputError
from ..core.lag import first_order_lag
from .logseries import (
    Estimate,
    LogSeries,
    Skeleton,
    confidence_interval,
    correlation_time,
    origin_fit,
    refuse_mixed,
)
from .sanity import r2_text

#: commands at or above this (normalised) are saturated and left out of the motor map.
SATURATED = 0.99
#: motor lag grid (s).
LAG_GRID_S = np.arange(0.0, 0.2001, 0.0025)


# ----------------------------------------------------------------------------- motor map


def _map_normal_equations(logs: list[LogSeries], tau: float, dt: float, v_ref: float | None):
    """Per rotor (X'X, X'y, y'y, n) of the lagged map regression at lag ``tau``."""
    count = logs[0].command.shape[1]
    width = 3 if v_ref is not None else 2
    xx = np.zeros((count, width, width))
    xy = np.zeros((count, width))
    yy = np.zeros(count)
    n = np.zeros(count, int)
    for s in logs:
        cols = [np.ones_like(s.command), s.command]
        if v_ref is not None:
            cols.append(s.command * (s.vbat - v_ref)[:, None])
        lagged = first_order_lag(np.stack(cols, 2), tau, dt)          # (N, R, width)
        keep = lagged[:, :, 1] < SATURATED
        keep[: int(5 * tau / dt) + 1] = False                # the filter's start-up
        for i in range(count):
            x, y = lagged[keep[:, i], i], s.rotor_speed[keep[:, i], i]
            xx[i] += x.T @ x
            xy[i] += x.T @ y
            yy[i] += y @ y
            n[i] += len(y)
    return xx, xy, yy, n


def _map_sse(logs, tau, dt, v_ref):
    xx, xy, yy, n = _map_normal_equations(logs, tau, dt, v_ref)
    coef = np.stack([np.linalg.solve(a, c) for a, c in zip(xx, xy)])
    sse = yy - np.einsum("ij,ij->i", coef, xy)
    return float(sse.sum()), coef, sse, xy, n


def _map_correlation(s: LogSeries, coef: np.ndarray, tau: float, dt: float,
                     v_ref: float | None) -> float:
    """Correlation time (samples) of rotor 1's map residual on one log."""
    cols = [np.ones(len(s.t)), s.command[:, 0]]
    if v_ref is not None:
        cols.append(s.command[:, 0] * (s.vbat - v_ref))
    x = first_order_lag(np.stack(cols, 1), tau, dt)
    return correlation_time(s.rotor_speed[:, 0] - x @ coef)


def fit_motor_map(logs: list[LogSeries]) -> dict:
    """Per-rotor ``Omega = L_tau[a + k cmd (1 + gamma (v - v_ref))]`` (see module): least
    squares per lag on the normal equations, the lag on :data:`LAG_GRID_S` (coarse, then
    refined around the best)."""
    dt = float(np.median(np.diff(logs[0].t)))
    voltages = [s.vbat for s in logs]
    has_v = all(v is not None for v in voltages) and float(np.ptp(np.concatenate(voltages))) >= 0.05
    v_ref = float(np.median(np.concatenate(voltages))) if has_v else None
    coarse = LAG_GRID_S[::4]
    sse_coarse = [_map_sse(logs, tau, dt, v_ref)[0] for tau in coarse]
    k = int(np.argmin(sse_coarse))
    low, high = coarse[max(0, k - 1)], coarse[min(len(coarse) - 1, k + 1)]
    fine = LAG_GRID_S[(LAG_GRID_S >= low) & (LAG_GRID_S <= high)]
    results = {float(tau): _map_sse(logs, tau, dt, v_ref) for tau in fine}
    best = min(results, key=lambda tau: results[tau][0])
    total, coef, sse, xy, n = results[best]
    s2 = total / max(1, int(n.sum()) - coef.size)
    inside = [tau for tau, r in results.items()
              if r[0] - total <= 3.84 * s2 * _map_correlation(logs[0], coef[0], best, dt, v_ref)]
    # R^2 per rotor: 1 - SSE / (sum y^2 - n mean^2); mean from the constant column's X'y
    mean = xy[:, 0] / n
    yy = sse + np.einsum("ij,ij->i", coef, xy)
    r2 = 1.0 - sse / (yy - n * mean ** 2)
    gammas = (coef[:, 2] / coef[:, 1]).tolist() if has_v else []
    return {"speed": [[float(c[0]), float(c[0] + c[1])] for c in coef],
            "reference_voltage": v_ref,
            "voltage_gain": float(np.mean(gammas)) if has_v else 0.0,
            "voltage_gain_spread": float(np.std(gammas)) if has_v else 0.0,
            "time_constant": best, "time_constant_ci": (min(inside), max(inside)),
            "r2": r2.tolist(), "samples": int(n.min()),
            "command_range": (float(min(s.command.min() for s in logs)),
                              float(max(s.command.max() for s in logs)))}


# ----------------------------------------------------------------------------- commands only


def fit_command_thrust(logs: list[LogSeries], skeleton: Skeleton) -> tuple[Estimate, dict, str]:
    """Commands only: ``m f_z = sum T(u_i)``, ``T = c2 u^2 + c1 u`` (see module). Returns
    b (scaled by the skeleton's max_speed), a motor map table, and the fit's one-line summary."""
    if skeleton.max_speed is None:
        raise InputError(f"{skeleton.path}: rotors.max_speed: missing; logs without rotor "
                         "speeds fix only b Omega^2, and the speed scale comes from max_speed "
                         "(the rotor speed at full command: motor kV x battery voltage, or a "
                         "tachometer)")
    has_v = all(s.vbat is not None for s in logs)
    v_ref = float(np.median(np.concatenate([s.vbat for s in logs]))) if has_v else None
    us, ys = [], []
    for s in logs:
        u = s.command if not has_v else s.command * (s.vbat / v_ref)[:, None]
        us.append(u)
        ys.append(skeleton.mass * s.specific_force[:, 2])
    refuse_mixed([(s.name, *origin_fit(np.sum(u * u, 1), y)[:2]) for s, u, y in zip(logs, us, ys)],
                 "cmd_*: thrust per squared command (N)")
    u, y = np.concatenate(us), np.concatenate(ys)
    x = np.stack([np.sum(u * u, 1), np.sum(u, 1)], 1)
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    res = y - x @ coef
    cov = np.linalg.inv(x.T @ x) * float(res @ res) / max(1, len(y) - 2) * correlation_time(res)
    r2 = 1.0 - float(res @ res) / float(np.sum((y - y.mean()) ** 2))
    c2, c1 = (float(c) for c in coef)
    shape = ""
    if not (c1 >= 0 and c2 + c1 > 0 and 2 * c2 + c1 > 0):
        # the data do not fix the curve's shape (T not increasing on 0..1): one parameter,
        # T = c2 u^2 (b Omega^2 with the speed proportional to u), fixed by the hover level
        shape = (f"; the two-term fit ({c2:.3g} u^2 + {c1:.3g} u, R^2 {r2:.3f}) is not "
                 "increasing on 0..1: the shape is not determined, T = c2 u^2 assumed")
        xq = x[:, :1]
        c2, c1 = float(xq[:, 0] @ y / (xq[:, 0] @ xq[:, 0])), 0.0
        res = y - c2 * xq[:, 0]
        cov = np.zeros((2, 2))
        cov[0, 0] = float(res @ res) / max(1, len(y) - 1) * correlation_time(res) / float(
            xq[:, 0] @ xq[:, 0])
        r2 = 1.0 - float(res @ res) / float(np.sum((y - y.mean()) ** 2))
    full = c2 + c1
    if not full > 0:
        raise InputError(f"{logs[0].name}: cmd_*: the command -> thrust fit gives no thrust at "
                         f"full command (c2 {c2:.3g}, c1 {c1:.3g} N): commands not normalised "
                         "0-1, or too little range flown")
    se_full = math.sqrt(max(float(cov[0, 0] + cov[1, 1] + 2 * cov[0, 1]), 0.0))
    b = full / skeleton.max_speed ** 2
    grid = np.linspace(0.0, 1.0, 11)
    thrust = np.clip(c2 * grid ** 2 + c1 * grid, 0.0, None)
    speed = np.sqrt(thrust / b)
    summary = (f"command -> thrust per rotor T(u) = {c2:.4g} u^2 + {c1:.4g} u N (u = cmd"
               + (f" x vbat / {v_ref:.3g} V" if has_v else "")
               + f"), {r2_text(r2)} over {len(y)} samples of {len(logs)} log(s); "
               f"T(1) = {full:.4g} +- {1.96 * se_full:.2g} N{shape}")
    estimate = Estimate(b, confidence_interval(b, b * 1.96 * se_full / full),
                        f"commands only: b = T(1) / max_speed^2 with the skeleton's max_speed "
                        f"{skeleton.max_speed:.5g} rad/s; {summary}")
    table = {"command": grid.tolist(), "speed": [speed.tolist()] * logs[0].command.shape[1],
             "reference_voltage": v_ref, "voltage_gain": (1.0 / v_ref) if has_v else 0.0}
    return estimate, table, summary


def commanded_speed(s: LogSeries, motor: dict) -> np.ndarray:
    """Steady speed (N, R) rad/s of the log's commands on the fitted map (no lag)."""
    a = np.array([p[0] for p in motor["speed"]])
    k = np.array([p[1] - p[0] for p in motor["speed"]])
    gain = np.ones(len(s.t))
    if motor["reference_voltage"] is not None and s.vbat is not None:
        gain = 1.0 + motor["voltage_gain"] * (s.vbat - motor["reference_voltage"])
    return a + k * s.command * gain[:, None]
