"""Attitude as logs have it: Euler angles in the usual conventions -> our quaternion.

Our attitude is the body-to-world quaternion (w, x, y, z) with the body x forward, y left,
z up and the world z up. Logs state attitude as Euler angles in one of these conventions
(:data:`CONVENTIONS`; ``convert --euler NAME``):

==============  ==========================================================================
name            meaning
==============  ==========================================================================
``flu``         z-y-x (yaw psi, then pitch theta, then roll phi, each about the turned
                axis) of a body x forward, y left, z up in a z-up world:
                ``R = Rz(psi) Ry(theta) Rx(phi)``. Nose down is +pitch (a right-handed turn
                about +y, which points left); yaw anticlockwise seen from above.
``frd``         the same z-y-x sequence of a body x forward, y right, z down in a
                north-east-down world (PX4, ArduPilot ``ATT``): nose up is +pitch, yaw
                clockwise from north. ``R_ours = P R_frd P`` with ``P = diag(1, -1, -1)``:
                roll stays, pitch and yaw change sign.
``crazyflie``   the Crazyflie firmware's ``stateEstimate.roll/pitch/yaw``: FLU, z-y-x, but
                pitch logged with the opposite sign (nose up is +pitch: the firmware
                negates it "for the legacy CF2 body coordinate system").
==============  ==========================================================================

Angles in radians inside; importers convert degrees at the boundary. Which convention a log
uses is not always written in it (pitch's sign is the usual doubt): :func:`pitch_sign_from_gyro`
compares the pitch rate of the angles with the gyro, so a wrong convention is refused by the
gyro check (:func:`quadsim.logs.checks.check_gyro`) like a wrong quaternion is.

Example::

    >>> quat = quat_from_euler(roll, pitch, yaw, convention="frd")     # (N, 4) wxyz
"""

from __future__ import annotations

import numpy as np

from ..core.frames import euler_to_quat

__all__ = ["ACCEL_WINDOW_S", "CONVENTIONS", "pitch_from_velocity", "pitch_sign_from_gyro",
           "quat_from_euler"]

CONVENTIONS = ("flu", "frd", "crazyflie")


def _zyx_quat(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """q = qz(yaw) qy(pitch) qx(roll), (N, 4) wxyz."""
    return euler_to_quat(np.stack([roll, pitch, yaw], axis=-1))


def quat_from_euler(roll, pitch, yaw, *, convention: str = "flu") -> np.ndarray:
    """Body-to-world quaternions (N, 4) wxyz, our frames, from Euler angles (N,) rad in
    ``convention`` (see the module table). Raises ValueError for an unknown convention."""
    roll, pitch, yaw = (np.asarray(a, dtype=float) for a in (roll, pitch, yaw))
    if convention == "flu":
        return _zyx_quat(roll, pitch, yaw)
    if convention == "frd":
        return _zyx_quat(roll, -pitch, -yaw)
    if convention == "crazyflie":
        return _zyx_quat(roll, -pitch, yaw)
    raise ValueError(f"Euler convention {convention!r}: expected one of {', '.join(CONVENTIONS)}")


def pitch_sign_from_gyro(t: np.ndarray, roll: np.ndarray, pitch: np.ndarray,
                         gyro_y: np.ndarray) -> float:
    """The sign (+1, -1) and strength of the pitch angle's rate against the body y rate:
    the correlation of ``d pitch/dt`` with ``cos(roll) w_y`` (near level flight, the FLU pitch
    rate is about the body y rate). Returns the correlation in [-1, 1]: near +1 the angles
    are FLU (nose down +), near -1 the pitch is logged nose-up positive; 0 when the flight
    does not pitch."""
    rate = np.gradient(np.unwrap(np.asarray(pitch, float)), np.asarray(t, float))
    ref = np.cos(roll) * np.asarray(gyro_y, float)
    ok = np.isfinite(rate) & np.isfinite(ref)
    if ok.sum() < 10 or np.std(rate[ok]) == 0 or np.std(ref[ok]) == 0:
        return 0.0
    return float(np.corrcoef(rate[ok], ref[ok])[0, 1])


#: smoothing window (s) of the velocity's derivative in :func:`pitch_from_velocity`: an
#: on-board velocity estimate is smooth below ~5 Hz; 0.2 s keeps that band and damps the
#: differentiated noise.
ACCEL_WINDOW_S = 0.2


def pitch_from_velocity(t: np.ndarray, roll: np.ndarray, yaw: np.ndarray,
                        velocity: np.ndarray, gravity: float = 9.81
                        ) -> tuple[np.ndarray, float]:
    """The FLU pitch (N,) rad of a multirotor whose log has roll and yaw (rad, FLU) and the
    world velocity (N, 3) m/s (z up) but no pitch, and the rms (rad) by which the roll the
    same construction implies differs from the logged roll (its check).

    A multirotor's thrust lies along its body z, so the specific force ``a + g e_z`` (``a``
    the velocity's Savitzky-Golay derivative over ``ACCEL_WINDOW_S``) points along body z:
    turned by ``-yaw`` it is proportional to ``(sin(pitch) cos(roll), -sin(roll),
    cos(pitch) cos(roll))``, so ``pitch = atan2(f_x', f_z')`` and the implied roll is
    ``atan2(-f_y', hypot(f_x', f_z'))``. What it costs: the tilt is biased by drag / weight
    (a body drag tilts the specific force away from body z) and lags by the velocity
    estimate's own smoothing; the pitch rate is not the gyro's."""
    from scipy.signal import savgol_filter

    t = np.asarray(t, float)
    dt = float(np.median(np.diff(t)))
    window = max(5, round(ACCEL_WINDOW_S / dt) | 1)
    window = min(window, len(t) - (1 - len(t) % 2))
    accel = savgol_filter(np.asarray(velocity, float), window, 3, deriv=1, delta=dt, axis=0)
    f = accel + np.array([0.0, 0.0, gravity])
    c, s = np.cos(yaw), np.sin(yaw)
    fx, fy = c * f[:, 0] + s * f[:, 1], -s * f[:, 0] + c * f[:, 1]
    pitch = np.arctan2(fx, f[:, 2])
    implied = np.arctan2(-fy, np.hypot(fx, f[:, 2]))
    diff = np.angle(np.exp(1j * (implied - np.asarray(roll, float))))
    return pitch, float(np.sqrt(np.mean(diff ** 2)))
