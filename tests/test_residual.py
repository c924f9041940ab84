"""Residual wrench: differentiator, balance on exact generated logs, effects, bad input."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from scipy.signal import freqz, savgol_coeffs

from benchmarks.synthetic import SensorNoise, synthetic_flight
from quadsim.core.errors import InputError
from quadsim.core.frames import rotate
from quadsim.effects import EffectContext, EffectSet, make_effect
from quadsim.gap.residual import (
    DEFAULT_WINDOW_S,
    flight_states,
    measured_wrench,
    model_wrench,
    window_samples,
)
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import load_params

EDGE = 60  # samples at each end where the filter runs on a partial window


def savgol_response_cutoff(window_s: float, dt: float, polyorder: int = 3) -> float:
    """-3 dB frequency (Hz) of the smoothing (deriv=0) Savitzky–Golay filter of
    :func:`flight_states` (window ``window_s``, sample step ``dt``, s)."""
    coeffs = savgol_coeffs(window_samples(window_s, dt, polyorder), polyorder)
    freq, response = freqz(coeffs, worN=4096, fs=1.0 / dt)
    below = np.nonzero(np.abs(response) < 1 / np.sqrt(2))[0]
    return float(freq[below[0]]) if len(below) else float(freq[-1])


@dataclass(frozen=True)
class Residual:
    """Measured minus model wrench per sample: body frame (N, 3) each (N, N m), the force
    also in the world frame."""

    force_body: np.ndarray
    torque_body: np.ndarray
    force_world: np.ndarray
    accel_source: str


def residual_wrench(log, params, effects=None, *, use_accelerometer: bool = True) -> Residual:
    """The wrench the model (``params`` + ``effects``) is missing, per sample of ``log``:
    Newton-Euler on the smoothed motion (:func:`measured_wrench`) less the model's
    (:func:`model_wrench`), as the diagnosis forms it."""
    states = flight_states(log, use_accelerometer=use_accelerometer, gravity=params.gravity)
    model_force, model_torque, vehicle = model_wrench(states, params, effects)
    meas_force, meas_torque = measured_wrench(states, vehicle)
    force = meas_force - model_force
    return Residual(force, meas_torque - model_torque, rotate(states.quat, force),
                    states.accel_source)


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def test_differentiator_is_zero_phase_and_exact_on_slow_signals():
    """A 1 Hz sine's derivative comes out without lag (savgol is symmetric)."""
    t = np.arange(0, 4, 0.002)
    omega = 2 * np.pi
    log = FlightLog(t, np.stack([np.sin(omega * t), np.zeros_like(t), np.ones_like(t)], -1),
                    np.tile([1.0, 0, 0, 0], (len(t), 1)))
    states = flight_states(log)
    inner = slice(EDGE, -EDGE)
    # Velocity from position: cos, with relative error below 0.5 % and no shift.
    assert np.allclose(states.velocity[inner, 0], omega * np.cos(omega * t[inner]),
                       atol=5e-3 * omega)
    lag = np.argmax(np.correlate(states.velocity[inner, 0], np.cos(omega * t[inner]), "full"))
    assert lag == len(t[inner]) - 1
    # Cutoff of the default window (documented ~11 Hz at 500 Hz sampling).
    assert 9.0 < savgol_response_cutoff(DEFAULT_WINDOW_S, 0.002) < 12.0


def _noise_bound(params, noise: SensorNoise, dt: float) -> tuple[float, float]:
    """Predicted RMS of the residual force / torque from white sensor noise through the filter."""
    n = round(DEFAULT_WINDOW_S / dt) | 1
    smooth = np.linalg.norm(savgol_coeffs(n, 3))
    deriv = np.linalg.norm(savgol_coeffs(n, 3, deriv=1, delta=dt))
    hover = np.sqrt(params.weight / (params.rotor_count * params.thrust_factor))
    arm = np.linalg.norm(params.rotor_positions[0])
    rotor_force = 2 * params.thrust_factor * hover * noise.rotor * hover * smooth
    force = np.hypot(params.mass * noise.accel * smooth, 2 * rotor_force)
    torque = np.hypot(np.max(params.inertia) * noise.gyro * deriv, 2 * arm * rotor_force)
    return float(force), float(torque)


def test_no_effect_residual_is_within_sensor_noise(cf):
    noise = SensorNoise()
    log = synthetic_flight(cf, [], duration=6.0, seed=4, noise=noise)
    res = residual_wrench(log, cf)
    force_bound, torque_bound = _noise_bound(cf, noise, 0.002)
    force, torque = res.force_body[EDGE:-EDGE], res.torque_body[EDGE:-EDGE]
    assert np.all(np.sqrt(np.mean(force ** 2, axis=0)) < 1.5 * force_bound)
    assert np.all(np.sqrt(np.mean(torque ** 2, axis=0)) < 1.5 * torque_bound)
    assert np.all(np.abs(force.mean(axis=0)) < 0.2 * force_bound)
    # Against the weight: the model is complete to 0.3 % of m g.
    assert np.sqrt(np.mean(force ** 2)) < 3e-3 * cf.weight


def test_noiseless_residual_is_zero_with_accelerometer_or_kinematics(cf):
    log = synthetic_flight(cf, [], duration=5.0, seed=1, noise=None)
    for use_acc in (True, False):
        res = residual_wrench(log, cf, use_accelerometer=use_acc)
        assert res.accel_source == ("accelerometer" if use_acc else "kinematics")
        assert np.abs(res.force_body[EDGE:-EDGE]).max() < 1e-4 * cf.weight
        # Torque: the filter smooths Omega before squaring, a 1e-3 effect on fast manoeuvres.
        assert np.abs(res.torque_body[EDGE:-EDGE]).max() < 1e-3 * cf.weight * 0.05


@pytest.mark.parametrize("name, values", [
    ("rotor_drag", {"coefficient": 1e-6}),
    ("body_drag", {"cd_area": 0.01, "cd_area_vertical": 0.01}),
    ("gyroscopic", {"rotor_inertia": 1e-7}),
])
def test_one_effect_residual_matches_the_effects_own_load(cf, name, values):
    """The residual of the nominal model is the effect's own force/torque (within noise)."""
    effect = make_effect(name, **values)
    noise = SensorNoise()
    log = synthetic_flight(cf, [effect], duration=6.0, seed=2, noise=noise)
    res = residual_wrench(log, cf)
    states = flight_states(log)
    ctx = EffectContext(states.t, states.position, states.velocity, states.quat,
                        states.body_rate, states.velocity, states.rotor_speed,
                        states.rotor_accel, cf, states.vbat)
    loads = EffectSet((effect,)).loads(ctx)
    inner = slice(EDGE, -EDGE)
    force_bound, torque_bound = _noise_bound(cf, noise, 0.002)
    own_force, own_torque = loads.force_world[inner], loads.torque_body[inner]
    err_f = res.force_world[inner] - own_force
    err_t = res.torque_body[inner] - own_torque
    assert np.sqrt(np.mean(err_f ** 2, axis=0)).max() < 1.5 * force_bound
    assert np.sqrt(np.mean(err_t ** 2, axis=0)).max() < 1.5 * torque_bound
    # ... and the effect is well above the noise, so the comparison means something.
    signal = max(np.sqrt(np.mean(own_force ** 2)) / force_bound,
                 np.sqrt(np.mean(own_torque ** 2)) / torque_bound)
    assert signal > 3
    # With the effect in the model the residual is back to noise.
    fixed = residual_wrench(log, cf, [effect])
    assert np.sqrt(np.mean(fixed.torque_body[inner] ** 2, axis=0)).max() < 1.5 * torque_bound


def test_bad_input(cf):
    log = synthetic_flight(cf, [], duration=1.0, seed=0, noise=None)
    three = FlightLog(log.t, log.position, log.quat, log.velocity, log.body_rate, log.accel,
                      log.rotor_speed[:, :3], None, None, None)
    with pytest.raises(InputError, match="3 rotor columns, the model 'crazyflie21' has 4"):
        residual_wrench(three, cf)
    bare = FlightLog(log.t, log.position, log.quat)
    with pytest.raises(InputError, match="no measured rotor speeds"):
        residual_wrench(bare, cf)
    short = FlightLog(log.t[:20], log.position[:20], log.quat[:20],
                      rotor_speed=log.rotor_speed[:20])
    with pytest.raises(InputError, match="fewer than the"):
        residual_wrench(short, cf)
