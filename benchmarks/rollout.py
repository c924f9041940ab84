"""Many short open-loop predictions at once: fixed-step RK4 on the analytic engine's equations.

:func:`quadsim.sim.engines.simulate` integrates each control period with an adaptive
DOP853 step at rtol 1e-11, which is what a proof of two engines' agreement needs, but a
prediction benchmark asks for something else: tens of thousands of 0.5 s windows, each from
its own measured initial state and driven by its own measured rotor speeds. :func:`rollout`
advances all of them together with the classical fourth-order Runge–Kutta method on the very
same right-hand side (:func:`quadsim.sim.analytic.state_derivative`, or its compiled form from
:mod:`quadsim.sim.compiled` when numba is installed and every effect has a fast form), with
``substeps`` equal steps per control period and the quaternions renormalised after each step
(the engine renormalises after each hold interval). Every effect of the library acts exactly as
in the engines.

Inputs are held per control period (zero-order hold) and clipped to each parameter set's
``[min_speed, max_speed]`` like the engines' commands. Units SI: m, m/s, rad/s, s.

Accuracy: RK4's local error is O(dt^5); at the 10 ms control period of the nano-drone
benchmark with one step per period the result differs from ``simulate(engine="analytic")`` by
less than 1e-6 m and 1e-5 rad/s after 0.5 s on a tumbling 37 g Crazyflie with rotor drag and
blade flapping (``benchmarks/tests/test_rollout.py``; 2 substeps: 1.3e-8 m).

Example::

    >>> from quadsim.vehicle.params import load_params, hover_speed
    >>> from benchmarks.rollout import rollout
    >>> p = load_params("crazyflie21")
    >>> start = {"position": np.zeros((2, 3)), "velocity": np.zeros((2, 3)),
    ...          "quat": np.tile([1.0, 0, 0, 0], (2, 1)), "body_rate": np.zeros((2, 3))}
    >>> out = rollout(p, initial=start, rotor_speed_series=np.full((2, 50, 4), hover_speed(p)),
    ...               control_period=0.01)
    >>> out["position"].shape                     # (B, N + 1, 3): the start, then each period
    (2, 51, 3)
"""

from __future__ import annotations

import numpy as np

from quadsim.core.errors import InputError, SimulationError
from quadsim.core.frames import quat_normalize
from quadsim.effects.base import EffectSet
from quadsim.sim.analytic import (
    STATE_BOUND,
    BatchEffects,
    body_arrays,
    pack_state,
    state_derivative,
)
from quadsim.vehicle.params import VehicleParams

__all__ = ["rollout"]


def _right_hand_side(params: list[VehicleParams], effects: BatchEffects, body, fast: bool):
    if fast:
        from quadsim.sim.compiled import analytic_fast_rhs

        compiled = analytic_fast_rhs(params, effects, body)
        if compiled is not None:
            return compiled

    def rhs(t, y, command):
        return state_derivative(t, y, body=body, effects=effects, command=command)

    return rhs


def rollout(params: VehicleParams, *, initial: dict, rotor_speed_series: np.ndarray,
            control_period: float, effects: EffectSet | None = None, substeps: int = 2,
            fast: bool = True, hold_body_rate: bool = False) -> dict:
    """Open-loop RK4 predictions of B simulations of one vehicle with one effect set.

    ``initial``: dict of (B, ...) arrays ``position`` (m), ``velocity`` (m/s, world),
    ``quat`` (wxyz body to world), ``body_rate`` (rad/s) and, when an effect gives the
    rotors dynamics, ``rotor_speed`` (rad/s; default the first command). ``rotor_speed_series``
    (B, N, R): rotor speeds (rad/s) held over each control period. Returns dict of
    (B, N + 1, ...) arrays ``position, velocity, quat, body_rate``. Raises
    :class:`SimulationError` when a prediction leaves the state bounds or turns NaN.

    ``hold_body_rate``: the body rates stay at their initial values (their derivative is set
    to zero at every stage) -- the assumption that a fast on-board rate loop holds an
    unobserved rate set-point, as in the nano-drone benchmark's physics baseline; the
    translational equations and every effect's force are unchanged."""
    series = np.asarray(rotor_speed_series, dtype=float)
    if series.ndim != 3 or series.shape[2] != params.rotor_count:
        raise InputError(f"rotor_speed_series: expected (B, N, {params.rotor_count}), "
                         f"got {series.shape}")
    if not np.all(np.isfinite(series)):
        raise InputError("rotor_speed_series: contains NaN or infinite values")
    if not (control_period > 0 and int(substeps) >= 1):
        raise InputError("control_period must be positive and substeps at least 1")
    batch, periods, _ = series.shape
    effect_set = effects if effects is not None else EffectSet()
    modified = effect_set.apply_to_params(params)
    commands = np.clip(series, modified.min_speed, modified.max_speed)
    plist = [modified] * batch
    batch_effects = BatchEffects([effect_set] * batch, plist)
    body = body_arrays(plist)
    full = _right_hand_side(plist, batch_effects, body, fast)

    def rhs(t, yy, held):
        rate = full(t, yy, held)
        if hold_body_rate:
            rate.reshape(batch, -1)[:, 10:13] = 0.0
        return rate

    start = {k: np.asarray(initial[k], dtype=float).reshape(batch, -1)
             for k in ("position", "velocity", "quat", "body_rate")}
    start["rotor_speed"] = np.asarray(initial.get("rotor_speed", commands[:, 0]), dtype=float)
    dynamics = batch_effects.rotor_dynamics
    y = pack_state(start, dynamics).reshape(batch, -1)
    if batch_effects.state_size:
        y = np.concatenate([y, batch_effects.initial_state(start)], 1)
    y = y.ravel()
    width = y.size // batch
    dt = control_period / int(substeps)
    states = [y.reshape(batch, width)[:, :13].copy()]
    for k in range(periods):
        held = np.ascontiguousarray(commands[:, k])
        for j in range(int(substeps)):
            t = k * control_period + j * dt
            k1 = rhs(t, y, held)
            k2 = rhs(t + dt / 2, y + dt / 2 * k1, held)
            k3 = rhs(t + dt / 2, y + dt / 2 * k2, held)
            k4 = rhs(t + dt, y + dt * k3, held)
            y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            state = y.reshape(batch, width)
            state[:, 6:10] = quat_normalize(state[:, 6:10])
        row = y.reshape(batch, width)[:, :13]
        if not np.all(np.isfinite(row)) or np.abs(row).max() > STATE_BOUND:
            bad = np.flatnonzero(~np.all(np.isfinite(row), 1)
                                 | (np.abs(row).max(1) > STATE_BOUND))
            raise SimulationError(f"rollout: prediction(s) {bad[:5].tolist()} diverged at "
                                  f"t = {(k + 1) * control_period:.4g} s")
        states.append(row.copy())
    stacked = np.stack(states, axis=1)
    return {"position": stacked[..., 0:3], "velocity": stacked[..., 3:6],
            "quat": stacked[..., 6:10], "body_rate": stacked[..., 10:13]}
