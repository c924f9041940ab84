"""Physical ranges and rates every imported log must respect (PX4 ULog, Crazyflie uSD,
ArduPilot DataFlash, CSV and Parquet alike): the last line of defence against corrupt
files that parse, and against unit slips the loader's own unit checks
(:mod:`quadsim.logs.flightlog`: RPM, deg/s, g, mV) do not catch.

Refused (one :func:`~quadsim.core.errors.field_error` line naming the file, the column, the
CSV line and the value), with the limits and why they hold for any multirotor:

=====================  ===============================  ======================================
check                  limit                            why
=====================  ===============================  ======================================
position               ``|p|`` <= ``MAX_POSITION_M``     a local frame about the take-off
                       = 1e5 m                          point; 100 km is beyond any flight
velocity               ``|v|`` <= ``MAX_SPEED``          the fastest racing quadrotors fly
                       = 100 m/s                        about 70 m/s
position steps         ``|dp|/dt`` <= ``MAX_SPEED``      the same bound between two samples
                       (with 0.05 m of slack per step)  (a jump of km in one step is corrupt)
position units         displacement over 0.1 s windows  positions in mm with v in m/s make
                       / integrated v in 0.1..10        the ratio 1000 (``x..z`` named)
position units,        position's acceleration over     mm give 1000, cm 100 (``x..z``
no velocity            0.2 s windows / the accelero-    named)
                       meter's (R a - g) <= 10
specific force         ``|a|`` <= ``MAX_SPECIFIC_FORCE`` accelerometers saturate at 16-32 g
                       = 400 m/s^2
attitude rate          rotation between samples / dt    above the gyro bound of the loader
                       <= ``MAX_ATTITUDE_RATE``         (60 rad/s): a motion-capture glitch
                       = 100 rad/s                      of 0.1 rad at 500 Hz reads 50 rad/s
rotor speed            >= ``-MIN_ROTOR_SPEED`` (1 rad/s) a speed is a magnitude
battery voltage        0..100 V                         (mV is the loader's own check)
time step              <= ``MAX_STEP_S`` = 3600 s        an hour without a sample: two logs or
                                                        a corrupt timestamp (ArduPilot pauses
                                                        logging for minutes while disarmed)
time precision         every step >= 1e-13 x ``|t|``     stored time must resolve its steps
sample count           >= ``MIN_SAMPLES`` = 2            a time base needs two samples (the
                                                        diagnosis asks for 2 s of flight)
=====================  ===============================  ======================================

Example::

    >>> from quadsim.logs.plausible import check_plausible
    >>> check_plausible("f.csv", t, {"position": p, "velocity": v, ...})   # raises
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.integrate import cumulative_trapezoid

from ..core.errors import field_error

__all__ = [
    "MAX_POSITION_M",
    "MAX_SPECIFIC_FORCE",
    "MAX_SPEED",
    "MAX_STEP_S",
    "MIN_SAMPLES",
    "check_plausible",
]

MAX_POSITION_M = 1e5
MAX_SPEED = 100.0
STEP_SLACK_M = 0.05
MAX_SPECIFIC_FORCE = 400.0
MAX_ATTITUDE_RATE = 100.0
MIN_ROTOR_SPEED = 1.0
MAX_VBAT = 100.0
MAX_STEP_S = 3600.0
MIN_SAMPLES = 2
#: a step below this fraction of |t| is not resolved (double precision: 2.2e-16 relative;
#: 1e-13 keeps the step to 0.2 %)
TIME_PRECISION = 1e-13
#: displacement / integrated velocity over WINDOW_S windows (moving >= MIN_MOVING m/s)
POSITION_VELOCITY_RATIO = (0.1, 10.0)
MIN_MOVING = 0.2
WINDOW_S = 0.1
#: without velocity: the positions' acceleration / the accelerometer's over ACCEL_WINDOW_S
#: windows where the latter exceeds MIN_ACCEL_JUDGED m/s^2 (cm gives 100, mm 1000)
POSITION_ACCEL_RATIO = 10.0
ACCEL_WINDOW_S = 0.2
MIN_ACCEL_JUDGED = 0.3


def _line(row: int) -> str:
    return f"line {row + 2}"


def _worst(norms: np.ndarray) -> int:
    return int(np.nanargmax(norms))


def _check_norm(path, column: str, values, limit: float, unit: str, what: str) -> None:
    if values is None:
        return
    norms = np.linalg.norm(values, axis=1) if values.ndim == 2 else np.abs(values)
    if np.nanmax(norms, initial=0.0) > limit:
        row = _worst(norms)
        raise field_error(path, column, f"{_line(row)}: |{what}| = {norms[row]:.4g} {unit}, "
                          f"above {limit:g} {unit} (no multirotor; a corrupt or mis-scaled "
                          "value)")


def _check_time(path, t: np.ndarray) -> None:
    if len(t) < MIN_SAMPLES:
        raise field_error(path, "t", f"{len(t)} sample(s); at least {MIN_SAMPLES} are needed")
    steps = np.diff(t)
    if steps.max() > MAX_STEP_S:
        row = int(np.argmax(steps)) + 1
        raise field_error(path, "t", f"{_line(row)}: step of {steps[row - 1]:.4g} s after "
                          f"{t[row - 1]:.6g} s, over {MAX_STEP_S:g} s: two logs joined or a "
                          "corrupt timestamp")
    resolution = TIME_PRECISION * np.abs(t[1:])
    if (steps < resolution).any():
        row = int(np.argmax(steps < resolution)) + 1
        raise field_error(path, "t", f"{_line(row)}: step {steps[row - 1]:.3g} s at t = "
                          f"{t[row]:.17g} s is below the time's precision; write time "
                          "relative to the start of the log")


def _check_steps(path, t: np.ndarray, position: np.ndarray, velocity, log: dict) -> None:
    if velocity is not None:  # a unit slip first: its message names the unit
        _check_position_units(path, t, position, velocity, log)
    elif log.get("accel") is not None:
        _check_position_accel(path, t, position, log)
    dt = np.diff(t)
    step = np.linalg.norm(np.diff(position, axis=0), axis=1)
    ok = np.isfinite(step)
    too_fast = ok & (step > MAX_SPEED * dt + STEP_SLACK_M)
    if too_fast.any():
        row = int(np.argmax(too_fast)) + 1
        typical = float(np.median(step[ok] / dt[ok])) if ok.any() else 0.0
        hint = (f" (median speed {typical:.4g} m/s over the whole log: positions in mm or cm?)"
                if typical > MAX_SPEED else "")
        raise field_error(path, "x..z", f"{_line(row)}: position moves {step[row - 1]:.4g} m "
                          f"in {dt[row - 1]:.4g} s ({step[row - 1] / dt[row - 1]:.4g} m/s, "
                          f"above {MAX_SPEED:g} m/s): a jump no multirotor makes{hint}")


def _time_in_ms(t: np.ndarray, log: dict) -> bool:
    """The gyro turns ~1000 x faster than the quaternions do on this time axis."""
    rate = log.get("body_rate")
    if rate is None:
        return False
    turn = _rotation_rate(t, log["quat"])
    gyro = np.linalg.norm(0.5 * (rate[1:] + rate[:-1]), axis=1)
    use = np.isfinite(turn) & np.isfinite(gyro) & (turn > 0)
    return use.sum() > 5 and 300 < float(np.median(gyro[use]) / np.median(turn[use])) < 3000


def _check_position_units(path, t, position, velocity, log) -> None:
    """Displacement over 0.1 s windows against the integrated velocity: gain ~1."""
    steps = np.diff(t)
    dt = float(np.median(steps))
    m = max(1, round(WINDOW_S / dt))
    k = np.arange(0, len(t), m)
    if len(k) < 3:
        return
    moved = position[k[1:]] - position[k[:-1]]
    integral = cumulative_trapezoid(velocity, t, axis=0, initial=0)
    flown = integral[k[1:]] - integral[k[:-1]]
    span = t[k[1:]] - t[k[:-1]]
    norm = np.sum(flown * flown, axis=1)
    use = (np.isfinite(moved).all(axis=1) & np.isfinite(flown).all(axis=1)
           & (np.sqrt(norm) > MIN_MOVING * WINDOW_S) & (span < 2.0 * m * dt))  # no gap inside
    if use.sum() < 5:
        return
    ratio = float(np.median(np.sum(moved[use] * flown[use], axis=1) / norm[use]))
    lo, hi = POSITION_VELOCITY_RATIO
    if not lo <= ratio <= hi:
        if 3e-4 < ratio < 3e-3 and _time_in_ms(t, log):
            raise field_error(path, "t", f"position changes {ratio:.4g} x as far as the "
                              "logged velocity integrates to, and the gyro turns ~1000 x "
                              "faster than the quaternions: time in ms? (expected s)")
        hint = (" (positions in mm?)" if 300 < ratio < 3000 else
                " (positions in cm?)" if 30 < ratio < 300 else
                " (velocity in mm/s?)" if 3e-4 < ratio < 3e-3 else "")
        raise field_error(path, "x..z", f"position changes {ratio:.4g} x as far as the "
                          f"logged velocity integrates to (median over {int(use.sum())} windows "
                          f"of {WINDOW_S:g} s; expected 1): positions in m, velocity in m/s{hint}")


def _check_position_accel(path, t, position, log, gravity: float = 9.81) -> None:
    """Without a velocity column: the positions' acceleration against the accelerometer's.

    Over ``ACCEL_WINDOW_S`` windows k, the second difference of the position,
    ``(p_{k+1} - 2 p_k + p_{k-1}) / T^2`` (central: the mean acceleration over the two
    windows around k), must equal the specific force turned to the world frame minus
    gravity, ``R(q) a - g e_z``, averaged the same way (a triangle weight over the two
    windows; both as the change of the mean velocity from one window to the next, so the
    IMU's unknown initial velocity cancels). The gain of the first on the second (least
    squares over windows where the accelerometer's acceleration exceeds
    ``MIN_ACCEL_JUDGED``) is ~1; positions in mm give ~1000, in cm ~100: refused above
    ``POSITION_ACCEL_RATIO`` naming ``x..z``."""
    from ..core.frames import quat_to_rotmat

    steps = np.diff(t)
    dt = float(np.median(steps))
    m = max(1, round(ACCEL_WINDOW_S / dt))
    k = np.arange(0, len(t), m)
    if len(k) < 7:
        return
    world = np.einsum("nij,nj->ni", quat_to_rotmat(log["quat"]), log["accel"])
    world[:, 2] -= gravity
    bad = ~np.isfinite(world).all(axis=1)  # NaN runs (kept in optional columns): skipped
    world[bad] = 0.0
    near_bad = np.convolve(bad, np.ones(3), mode="same") > 0  # a NaN spoils its neighbours
    bad_before = np.concatenate([[0], np.cumsum(near_bad)])[k]  # such samples before each k

    span = (t[k[1:]] - t[k[:-1]])[:, None]
    scale = 0.5 * (span[1:] + span[:-1])
    # mean velocity over each window, from the positions and (up to a constant) the IMU
    moved = (position[k[1:]] - position[k[:-1]]) / span
    flown = cumulative_trapezoid(cumulative_trapezoid(world, t, axis=0, initial=0), t, axis=0,
                                 initial=0)     # trapezoid integrals from t[0], (N, 3)
    flown = (flown[k[1:]] - flown[k[:-1]]) / span
    from_position = (moved[1:] - moved[:-1]) / scale
    from_imu = (flown[1:] - flown[:-1]) / scale
    clean = (bad_before[2:] - bad_before[:-2]) == 0  # no NaN in the two windows
    use = (clean & np.isfinite(from_imu).all(axis=1) & np.isfinite(from_position).all(axis=1)
           & (np.abs(span[1:, 0] - span[:-1, 0]) < 0.5 * m * dt)         # no gap inside
           & (np.linalg.norm(from_imu, axis=1) > MIN_ACCEL_JUDGED))
    if use.sum() < 5:
        return
    a, b = from_position[use].ravel(), from_imu[use].ravel()
    gain = float(a @ b / (b @ b))
    if gain > POSITION_ACCEL_RATIO:
        hint = (" (positions in mm?)" if 300 < gain < 3000 else
                " (positions in cm?)" if 30 < gain < 300 else "")
        raise field_error(path, "x..z", f"position accelerates {gain:.4g} x as much as the "
                          f"accelerometer says (R a - g over {int(use.sum())} windows of "
                          f"{ACCEL_WINDOW_S:g} s; expected 1; no velocity column to compare "
                          f"with): positions in m, specific force in m/s^2{hint}")


def _rotation_rate(t: np.ndarray, quat: np.ndarray) -> np.ndarray:
    """Angle (rad) between consecutive unit quaternions / dt (N-1,)."""
    dot = np.abs(np.sum(quat[1:] * quat[:-1], axis=1))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0)) / np.diff(t)


def check_plausible(path: str | Path, t: np.ndarray, log: dict) -> None:
    """Raise for the first value outside the module's table. ``log``: the loader's arrays
    (``position`` (N, 3) m, ``velocity`` (N, 3) m/s, ``quat`` (N, 4) unit (position and
    quat None in an IMU-only log), ``accel``
    (N, 3) m/s^2, ``rotor_speed`` (N, R) rad/s, ``vbat`` (N,) V; None when absent)."""
    path = Path(path)
    _check_time(path, t)
    _check_norm(path, "x..z", log["position"], MAX_POSITION_M, "m", "position")
    _check_norm(path, "vx..vz", log.get("velocity"), MAX_SPEED, "m/s", "velocity")
    _check_norm(path, "ax..az", log.get("accel"), MAX_SPECIFIC_FORCE, "m/s^2",
                "specific force")
    if log["position"] is not None:
        _check_steps(path, t, log["position"], log.get("velocity"), log)
    rate = _rotation_rate(t, log["quat"]) if log["quat"] is not None else np.zeros(0)
    if np.nanmax(rate, initial=0.0) > MAX_ATTITUDE_RATE:
        row = int(np.nanargmax(rate)) + 1
        raise field_error(path, "qw..qz", f"{_line(row)}: attitude turns at {rate[row - 1]:.4g} "
                          f"rad/s between two samples, above {MAX_ATTITUDE_RATE:g} rad/s: a "
                          "corrupt quaternion")
    speed = log.get("rotor_speed")
    if speed is not None and np.nanmin(speed, initial=0.0) < -MIN_ROTOR_SPEED:
        row = int(np.nanargmin(np.nanmin(speed, axis=1)))
        raise field_error(path, "rotor_*", f"{_line(row)}: rotor speed "
                          f"{np.nanmin(speed[row]):.4g} rad/s; speeds are magnitudes (>= 0)")
    vbat = log.get("vbat")
    if vbat is not None and np.nanmin(vbat, initial=0.0) < 0:
        row = int(np.nanargmin(vbat))
        raise field_error(path, "vbat", f"{_line(row)}: {vbat[row]:.4g} V; a battery "
                          f"voltage lies in 0-{MAX_VBAT:g} V")
