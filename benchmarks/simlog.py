"""A quadsim flight log from an independent simulator's true states (shared by its sources).

The Crazyflow and PyFlyt sources (:mod:`.crazyflow_source`, :mod:`.pyflyt_source`) both
simulate the motion of the centre of mass; a motion-capture marker set and an IMU sit on the
body origin (the geometric centre), so :func:`body_origin_log` moves every signal there
(``r = -com``, body frame)::

    p_o = p_c + R r        v_o = v_c + R (w x r)
    f_o = R^T (a_c - g) + alpha x r + w x (w x r)      (specific force, body frame, m/s^2)

and adds the sensor model of :class:`Sensors` (white noise, a gyro bias drawn per flight,
rotor-speed telemetry noise as a fraction of the hover speed, optionally the rotor-speed
log shifted late by ``rotor_delay`` s). One generator ``default_rng([seed, 7])`` draws every
noise in a fixed order, so the same states and seed give the same bytes.

Example::

    >>> log = body_origin_log(SimStates(...), com=np.zeros(3), sensors=Sensors(), seed=1,
    ...                       hover_speed=2300.0)
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from quadsim.core.frames import quat_multiply, quat_normalize, quat_to_rotmat
from quadsim.logs.flightlog import FlightLog
from quadsim.logs.sensors import rotation_quat

__all__ = ["Sensors", "SimStates", "body_origin_log", "jsonable", "truth_json"]


@dataclass(frozen=True)
class Sensors:
    """Sensor noise (1-sigma white noise unless named): position m, attitude rad, velocity
    m/s, gyro rad/s (+ a constant bias drawn per flight with ``gyro_bias`` sigma), accel m/s^2,
    rotor speed as a fraction of the hover speed."""

    position: float = 3e-4
    attitude: float = 1e-3
    velocity: float = 5e-3
    gyro: float = 5e-3
    gyro_bias: float = 2e-3
    accel: float = 0.03
    rotor: float = 0.003


@dataclass(frozen=True)
class SimStates:
    """True states of N samples at ``rate_hz`` (SI): CoM position and velocity (N, 3) world,
    attitude (N, 4) scalar-first body -> world, body rates and angular accelerations (N, 3)
    body, CoM acceleration (N, 3) world (gravity included), rotor speeds (N, R) rad/s and
    commands (N, R) in [0, 1]."""

    rate_hz: float
    pos: np.ndarray
    vel: np.ndarray
    quat: np.ndarray
    ang_vel: np.ndarray
    ang_acc: np.ndarray
    acc: np.ndarray
    rotor_speed: np.ndarray
    command: np.ndarray


def body_origin_log(states: SimStates, com: np.ndarray, sensors: Sensors, seed: int,
                    hover_speed: float, rotor_delay: float = 0.0,
                    gravity: float = 9.81) -> FlightLog:
    """The log of the body origin with the sensor model (module docstring)."""
    rng = np.random.default_rng([seed, 7])
    s = sensors
    n = states.pos.shape[0]
    t = np.arange(n) / states.rate_hz
    quat = quat_normalize(states.quat)
    rot = quat_to_rotmat(quat)
    w, alpha = states.ang_vel, states.ang_acc
    r = -np.asarray(com, dtype=float)                              # origin relative to the CoM
    position = states.pos + rot @ r
    velocity = states.vel + np.einsum("nij,nj->ni", rot, np.cross(w, r))
    g = np.array([0.0, 0.0, -gravity])
    specific = np.einsum("nji,nj->ni", rot, states.acc - g)         # body frame, at the CoM
    specific = specific + np.cross(alpha, r) + np.cross(w, np.cross(w, r))
    position = position + s.position * rng.standard_normal((n, 3))
    quat = quat_normalize(quat_multiply(quat, rotation_quat(s.attitude
                                                            * rng.standard_normal((n, 3)))))
    quat = np.where(quat[:, :1] < 0, -quat, quat)
    velocity = velocity + s.velocity * rng.standard_normal((n, 3))
    gyro = w + s.gyro_bias * rng.standard_normal(3) + s.gyro * rng.standard_normal((n, 3))
    accel = specific + s.accel * rng.standard_normal((n, 3))
    rotor = states.rotor_speed
    if rotor_delay:
        rotor = np.stack([np.interp(t - rotor_delay, t, c) for c in rotor.T], axis=-1)
    rotor = rotor + s.rotor * hover_speed * rng.standard_normal(rotor.shape)
    command = np.clip(states.command, 0.0, 1.0)
    return FlightLog(t, position, quat, velocity, gyro, accel, rotor, command, None, None)


def jsonable(value):
    """Numbers, tuples and arrays (nested in dicts) as JSON-ready floats and lists."""
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return np.asarray(value, dtype=float).tolist()
    return float(value)


def truth_json(truth: dict) -> str:
    """A truth sidecar as JSON text (sorted keys: same truth, same bytes)."""
    return json.dumps(truth, indent=1, sort_keys=True) + "\n"
