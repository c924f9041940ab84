"""A realistic sensor pipeline over :func:`quadsim.logs.generate.generate_flight` (second benchmark
source).

quadsim's own closed loop (geometric controller, an engine) flies the vehicle with the
hidden effects; what the diagnosis then gets is not the simulator's state but what a
motion-capture + onboard-telemetry setup records (:func:`realistic_log`):

==============  ==========================================================================
signal          model (defaults in :class:`Pipeline`)
==============  ==========================================================================
position        motion capture: truth at ``t - mocap_latency`` (s) + white noise (m)
attitude        motion capture: truth at ``t - mocap_latency`` x small random rotation (rad)
velocity        central finite difference of the mocap positions (m/s)
accelerometer   NOT an IMU: second central difference of the mocap positions, zero-phase
                2nd-order Butterworth low-pass at ``accel_cutoff`` (Hz), + g, rotated into
                the body frame with the mocap attitude (m/s^2 specific force)
gyro            truth + constant bias + white noise (rad/s), on the log's time base
rotor speed     first-order low-pass (time constant ``rotor_tau``, s, an ESC telemetry
                filter) of the truth, delayed by ``rotor_delay`` (s), + white noise
                (fraction of hover speed), quantised to ``rotor_quantum`` (rad/s)
command         exact (as logged by the flight controller)
vbat            truth + white noise (V)
==============  ==========================================================================

The delays and filters are typical of real logs (motion-capture latency 5-20 ms, ESC
telemetry 10-30 ms; 5-50 ms overall) and are *not* modelled by the diagnosis, so
they leave a floor any independent source has.

Example::

    >>> from quadsim.vehicle.params import load_params
    >>> from quadsim.effects import make_effect
    >>> log = pipeline_flight(load_params("crazyflie21"),
    ...                       [make_effect("mass_offset", mass=0.004)], seed=1)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, filtfilt, lfilter

from quadsim.core.frames import quat_multiply, quat_normalize, quat_to_rotmat
from quadsim.effects.base import EffectSet
from quadsim.logs.flightlog import FlightLog
from quadsim.logs.sensors import rotation_quat
from quadsim.vehicle.params import VehicleParams, hover_speed

__all__ = ["Pipeline", "pipeline_flight", "realistic_log"]


@dataclass(frozen=True)
class Pipeline:
    """Sensor-pipeline settings (SI: s, m, rad, rad/s, Hz, V; rotor_noise: fraction of hover)."""

    mocap_latency: float = 0.008
    position_noise: float = 3e-4
    attitude_noise: float = 1e-3
    accel_cutoff: float = 20.0
    gyro_noise: float = 0.01
    gyro_bias: float = 0.003
    rotor_tau: float = 0.015
    rotor_delay: float = 0.010
    rotor_noise: float = 0.003
    rotor_quantum: float = 1.0
    vbat_noise: float = 0.01


def _delayed(t: np.ndarray, values: np.ndarray, delay: float) -> np.ndarray:
    """values at t - delay (linear interpolation; the first sample is held before the start)."""
    return np.stack([np.interp(t - delay, t, c) for c in values.T], axis=-1)


def realistic_log(true_log: FlightLog, params: VehicleParams, seed: int,
                  pipeline: Pipeline = Pipeline()) -> FlightLog:
    """What the sensors record of ``true_log`` (a noise-free log); see the module docstring."""
    rng = np.random.default_rng(seed)
    t, n = true_log.t, len(true_log.t)
    dt = float(np.median(np.diff(t)))
    position = _delayed(t, true_log.position, pipeline.mocap_latency)
    position = position + pipeline.position_noise * rng.standard_normal((n, 3))
    quat = quat_normalize(_delayed(t, true_log.quat, pipeline.mocap_latency))
    tilt = rotation_quat(pipeline.attitude_noise * rng.standard_normal((n, 3)))
    quat = quat_normalize(quat_multiply(quat, tilt))
    quat = np.where(quat[:, :1] < 0, -quat, quat)
    velocity = np.gradient(position, t, axis=0)
    accel_world = np.gradient(velocity, t, axis=0)
    b, a = butter(2, pipeline.accel_cutoff * 2.0 * dt)
    accel_world = filtfilt(b, a, accel_world, axis=0)
    accel_world[:, 2] += params.gravity
    accel = np.einsum("nji,nj->ni", quat_to_rotmat(quat), accel_world)
    gyro = (true_log.body_rate + pipeline.gyro_bias
            + pipeline.gyro_noise * rng.standard_normal((n, 3)))
    rotor = None
    if true_log.rotor_speed is not None:
        alpha = dt / (pipeline.rotor_tau + dt)
        rotor = lfilter([alpha], [1.0, alpha - 1.0], true_log.rotor_speed, axis=0,
                        zi=(1.0 - alpha) * true_log.rotor_speed[:1])[0]
        rotor = _delayed(t, rotor, pipeline.rotor_delay)
        noise = pipeline.rotor_noise * hover_speed(params)
        rotor = rotor + noise * rng.standard_normal(rotor.shape)
        rotor = np.round(rotor / pipeline.rotor_quantum) * pipeline.rotor_quantum
    vbat = None
    if true_log.vbat is not None:
        vbat = true_log.vbat + pipeline.vbat_noise * rng.standard_normal(n)
    return FlightLog(t, position, quat, velocity, gyro, accel, rotor, true_log.rotor_command,
                     vbat, None)


def pipeline_flight(params: VehicleParams, effects=(), *, seed: int = 0, duration: float = 8.0,
                    speed: float = 1.0, path: str = "lissajous", engine: str = "analytic",
                    pipeline: Pipeline = Pipeline()) -> FlightLog:
    """Fly ``params`` + hidden ``effects`` with :func:`quadsim.logs.generate.generate_flight` (no
    sensor model), then pass the true log through :func:`realistic_log`."""
    from quadsim.logs.generate import generate_flight

    size = 1.0 if params.mass > 0.2 else 0.5
    true_log, _ = generate_flight(params, path, EffectSet(tuple(effects)), None, seed,
                                  engine=engine, duration=duration, control_period=0.004,
                                  speed=speed * size, size=size)
    return realistic_log(true_log, params, seed, pipeline)
