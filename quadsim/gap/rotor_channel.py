"""The rotor-speed channel of the gap diagnosis: the measured rotor speed ``ROTOR_HORIZON_S``
ahead minus the model's prediction from the speed now and the logged commands.

Where commands are logged, the effects upstream of the measured speed (a motor lag, a
battery's voltage, a propeller's load) are seen only here: with measured rotor speeds they
do not change the wrench. The prediction integrates the first effect that defines rotor
dynamics (:func:`rate_owner`, e.g. ``motor_lag``: dOmega/dt = (Omega_c - Omega) / tau) by
``ROTOR_SUBSTEPS`` Heun steps per sample with the command interpolated inside the sample; a
lag that is the same up and down has the same numbers in closed form (:func:`heun_linear`).
A static factor (a battery, a propeller's load: ``EffectSet.command_factor``) scales the
command; without dynamics the commanded speed is reached at once.

Units: rad/s (speeds), s (times). Example::

    >>> from quadsim.gap.rotor_channel import rotor_residual
    >>> r = rotor_residual(states, params, [make_effect("motor_lag", time_constant=0.03)])
    >>> r.shape        # (N, R): zero for the first horizon's samples and across flights
"""

from __future__ import annotations

import functools

import numpy as np

from ..effects.base import EffectSet
from ..vehicle.params import VehicleParams
from .motor_map import command_speed
from .residual import FlightStates

__all__ = ["ROTOR_HORIZON_S", "ROTOR_SUBSTEPS", "min_time_constant", "rate_owner",
           "rotor_residual"]

#: horizon (s) of the rotor-speed channel: speed predicted this far ahead from the measured
#: one. Longer than the smoothing window, so that the (smoothed) noise of the starting speed is
#: not correlated with the noise at the end (it would reward a spurious lag).
ROTOR_HORIZON_S = 0.12
ROTOR_SUBSTEPS = 4


def min_time_constant(dt: float) -> float:
    """The shortest rotor time constant (s) a fit on samples ``dt`` apart takes: one Heun
    sub-step of :func:`rotor_residual`, ``dt / ROTOR_SUBSTEPS``. Shorter is not resolved at
    that sample rate, and below half of it the sub-steps turn unstable (amplification
    1 + z + z^2 / 2 >= 1 for z = -h / tau <= -2): a fit there would read the measured speed
    through the unstable integration."""
    return dt / ROTOR_SUBSTEPS


def rate_owner(effects) -> object | None:
    """The first effect that defines rotor dynamics (``rotor_speed_rate`` not None: a motor
    lag), or None: then a commanded speed is reached at once (a speed factor, a battery, is
    static)."""
    probe = np.zeros((1, 1))
    return next((e for e in effects
                 if e.rotor_speed_rate(np.zeros(1), probe, probe) is not None), None)


def _linear_time_constant(owner) -> float | None:
    """The time constant (s) of a first-order lag that is the same up and down
    (``MotorLag``: dOmega/dt = (Omega_c - Omega) / tau, linear in both speeds), else None."""
    from ..effects.motor_lag import MotorLag

    if type(owner) is not MotorLag:
        return None
    tau = owner.time_constant
    down = owner.time_constant_down
    return float(tau) if tau > 0.0 and (down <= 0.0 or down == tau) else None


@functools.lru_cache(maxsize=64)
def _heun_weights(steps: int, h: float, tau: float) -> tuple[float, np.ndarray]:
    """(a^(S steps), w_0..w_steps) of :func:`heun_linear` (kept: a fit asks for the same
    time constant many times). The weights are read only."""
    a = 1.0 - h / tau + h * h / (2.0 * tau * tau)
    b0 = h / (2.0 * tau) - h * h / (2.0 * tau * tau)
    b1 = h / (2.0 * tau)
    gain = 1.0
    weights = np.zeros(steps + 1)
    for k in range(steps):
        for j in range(ROTOR_SUBSTEPS):
            f0, f1 = j / ROTOR_SUBSTEPS, (j + 1) / ROTOR_SUBSTEPS
            # W' = a W + b0 ((1 - f0) c_k + f0 c_k+1) + b1 ((1 - f1) c_k + f1 c_k+1)
            gain *= a
            weights *= a
            weights[k] += b0 * (1.0 - f0) + b1 * (1.0 - f1)
            weights[k + 1] += b0 * f0 + b1 * f1
    weights.setflags(write=False)
    return gain, weights


def heun_linear(start: np.ndarray, cmd: np.ndarray, steps: int, h: float, tau: float,
                 n: int) -> np.ndarray:
    """:func:`rotor_residual`'s Heun integration for a linear lag, in closed form.

    One Heun sub-step of dW/dt = (c - W) / tau with the command going from c0 to c1 is
    affine: ``W' = a W + b0 c0 + b1 c1`` with ``a = 1 - h/tau + h^2/(2 tau^2)``,
    ``b0 = h/(2 tau) - h^2/(2 tau^2)``, ``b1 = h/(2 tau)`` (k1 = (c0 - W)/tau,
    k2 = (c1 - W - h k1)/tau, W' = W + h (k1 + k2)/2). The command is interpolated
    linearly inside each sample, so after ``steps`` samples of ROTOR_SUBSTEPS sub-steps the
    prediction is ``a^(S steps) W_0 + sum_k w_k cmd_k`` (weights w_k from the same
    recursion, once): the same numbers as stepping the rate function, to round-off, at a
    few array operations instead of 2 S steps rate evaluations."""
    gain, weights = _heun_weights(steps, h, tau)
    out = gain * start
    for k in range(steps + 1):
        out = out + weights[k] * cmd[k:k + n]
    return out


def rotor_residual(states: FlightStates, params: VehicleParams, effects: list) -> np.ndarray:
    """Measured rotor speed at t + h minus the model's prediction from the state at t."""
    dt = float(states.t[1] - states.t[0]) if len(states.t) > 1 else 1.0
    steps = max(1, round(ROTOR_HORIZON_S / dt))
    cmd = command_speed(states, params)
    # Effects upstream of the speed (battery voltage) scale the speed a command gives; it is
    # static (a battery changes the steady speed, not how fast the rotor gets there): only a
    # dynamics effect (motor_lag) makes the rotor follow with a lag.
    factor = EffectSet(tuple(effects)).command_factor(states.t, states.vbat, cmd.shape[1])
    if factor is not None:
        cmd = cmd * factor
    speed = states.rotor_speed
    n = len(states.t) - steps
    owner = rate_owner(effects)
    linear = _linear_time_constant(owner)
    if owner is None:
        predicted = cmd[steps:]
    elif linear is not None:
        predicted = heun_linear(speed[:n], cmd, steps, dt / ROTOR_SUBSTEPS, linear, n)
    else:
        # ROTOR_SUBSTEPS Heun steps per sample (stable for time constants down to about
        # dt / (2 ROTOR_SUBSTEPS)).
        rate_fn = owner.rotor_speed_rate
        predicted = speed[:n].copy()
        h = dt / ROTOR_SUBSTEPS
        for k in range(steps):
            start, slope = cmd[k:k + n], cmd[k + 1:k + 1 + n] - cmd[k:k + n]
            for j in range(ROTOR_SUBSTEPS):
                # Heun (RK2) with the command interpolated inside the sample (holding it
                # would add a half-sample lag that the fit would take from the time constant).
                c0 = start + (j / ROTOR_SUBSTEPS) * slope
                c1 = start + ((j + 1) / ROTOR_SUBSTEPS) * slope
                k1 = rate_fn(states.t[k:k + n], c0, predicted)
                k2 = rate_fn(states.t[k:k + n], c1, predicted + h * k1)
                predicted = predicted + 0.5 * h * (k1 + k2)
    out = np.zeros_like(speed)
    out[steps:] = speed[steps:] - predicted
    # Stacked flights: a prediction across a flight boundary (time jump) is not scored.
    valid = np.abs(states.t[steps:] - states.t[:n] - steps * dt) < 0.5 * dt
    out[steps:][~valid] = 0.0
    return out
