"""Residual parts kept across the many model evaluations on one flight
(:func:`quadsim.gap.fitting.residuals` with ``memo``): the per-flight evidence and the
calibration's Jacobians evaluate hundreds of models on the same samples, and most of a
model's residual does not move when one parameter does.

What is kept, and what it is keyed by (an effect is its class and its values):

* per flight (:func:`flight_memo`): the body-to-world rotations of the logged attitude and a
  dict the effects keep their own motion-only values in (the cable's attachment
  acceleration and swings) -- keyed by the identity of the logged-motion arrays;
* per evaluation kind (:func:`_memo`, oldest evicted first past 64 entries): the measured
  wrench of one vehicle (mass, CoM, inertia), the rotor channel of one command -> speed
  model (:func:`_rotor_key`: the effects with a speed factor or rotor dynamics), the model
  wrench of one set of effects that reach it (:func:`_wrench_key`: a motor lag does not),
  the states shifted by one rotor delay.

Each entry holds the states it was computed on, so an id is never mistaken for another's.
Equality with the residual computed from scratch: tests/test_fast_paths.py.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..effects.base import EffectBase

if TYPE_CHECKING:
    from ..vehicle.params import VehicleParams
    from .residual import FlightStates

__all__ = ["flight_memo"]


#: kinds of :func:`_memo` entries that one model or one rotor timing owns (evicted oldest
#: first); the per-flight ones (:func:`flight_memo`) are kept.
_PER_EVALUATION = ("measured", "rotor", "wrench", "shifted")


def _memo(memo: dict, key: tuple, states, compute):
    """``memo[key]`` (computed once): parts of the residual that many evaluations on the
    same ``states`` share (the measured wrench of one vehicle; the rotor channel of one
    command -> speed model). The entry holds ``states`` so that its id stays its own."""
    hit = memo.get(key)
    if hit is not None and hit[0] is states:
        return hit[1]
    if len(memo) > 64:          # the oldest of these entries go (the per-flight ones stay)
        for old in [k for k in memo if isinstance(k, tuple) and k[0] in _PER_EVALUATION][:16]:
            del memo[old]
    value = compute()
    memo[key] = (states, value)
    return value


def flight_memo(memo: dict, states) -> tuple[np.ndarray, dict]:
    """What depends only on the logged motion of ``states`` (t, position, velocity, quat,
    body_rate), kept in ``memo`` across evaluations: the body-to-world rotations (N, 3, 3)
    and a dict the effects keep their own such values in
    (:attr:`quadsim.effects.base.EffectContext.flight_memo`). States that share those arrays
    (a rotor-delay shift moves only the rotor speeds) share the entry."""
    arrays = (states.t, states.position, states.velocity, states.quat, states.body_rate)
    key = ("motion",) + tuple(map(id, arrays))
    hit = memo.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], arrays)):
        return hit[1]
    from ..core.frames import quat_to_rotmat

    value = (quat_to_rotmat(states.quat), {})
    memo[key] = (arrays, value)
    return value


#: the hooks through which an effect reaches the model wrench (:func:`model_wrench`); an
#: effect that keeps :class:`EffectBase`'s neutral ones (a motor lag, a battery's speed factor)
#: acts on the rotor-speed channel only.
_WRENCH_HOOKS = ("loads", "apply_to_params", "air_velocity")


def _wrench_key(states: FlightStates, params: VehicleParams, effects: list) -> tuple:
    """What the model wrench depends on besides ``states`` and ``params``: the class and
    values of every effect that reaches it (the others only move the rotor channel, so a
    motor-lag fit evaluates the wrench once per rotor timing)."""
    return ("wrench", id(states), id(params), _acting(effects, _WRENCH_HOOKS))


#: the hooks through which an effect reaches the rotor channel (:func:`_rotor_channel`).
_ROTOR_HOOKS = ("rotor_speed_rate", "speed_factor")


def _acting(effects: list, hooks: tuple) -> tuple:
    """(class, values) of each effect, in order, whose class has its own version of one of
    ``hooks`` (an effect is its class and its values)."""
    return tuple((type(e), tuple(sorted(e.values().items()))) for e in effects
                 if any(getattr(type(e), hook, None) is not getattr(EffectBase, hook)
                        for hook in hooks))


def _rotor_key(states: FlightStates, params: VehicleParams, effects: list) -> tuple:
    """What the rotor channel depends on besides ``states``: the motor map (``params``) and
    the effects with a speed factor or rotor dynamics, in order (:func:`_rotor_channel`)."""
    return ("rotor", id(states), id(params), _acting(effects, _ROTOR_HOOKS))
