"""Residual parts kept across the many model evaluations on one flight
(:func:`quadsim.gap.fitting.residuals` with ``memo``): the per-flight evidence and the
calibration's Jacobians evaluate hundreds of models on the same samples, and most of a
model's residual does not move when one parameter does.

What is kept, and what it is keyed by (an effect is its class and its values):

* per flight (:func:`flight_memo`): the body-to-world rotations of the logged attitude and a
  dict the effects keep their own motion-only values in (the cable's attachment
  acceleration and swings) -- keyed by the identity of the logged-motion arrays;
* per evaluation kind (:func:`memoised`, oldest evicted first past 64 entries): the measured
  wrench of one vehicle (mass, CoM, inertia), the rotor channel of one command -> speed
  model (:func:`rotor_key`: the effects with a speed factor or rotor dynamics), the model
  wrench of one set of effects that reach it (:func:`wrench_key`: a motor lag does not),
  the states shifted by one rotor delay;
* per flight and kind, in its motion dict (:func:`kept`, the least recently used evicted
  past :data:`KEPT` entries; used by :func:`quadsim.gap.residual.model_wrench`): the
  vehicle of the effects that change it, the air velocity of those that move the air, and
  each effect's loads on one vehicle, air velocity and set of rotor speeds -- or, for an
  effect that declares what its loads read (:attr:`quadsim.effects.base.EffectBase.loads_reads`),
  on those inputs and vehicle attributes alone -- so a Jacobian column recomputes only the
  effect whose parameter it moves.

Each entry holds the states it was computed on, so an id is never mistaken for another's.
Equality with the residual computed from scratch: tests/test_fast_paths.py.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import TYPE_CHECKING

import numpy as np

from ..effects.base import EffectBase

if TYPE_CHECKING:
    from ..vehicle.params import VehicleParams

__all__ = ["KEPT", "acting", "flight_memo", "identity", "kept", "memoised", "rotor_key",
           "wrench_key"]


#: kinds of :func:`memoised` entries that one model or one rotor timing owns (evicted oldest
#: first); the per-flight ones (:func:`flight_memo`) are kept.
_PER_EVALUATION = ("measured", "rotor", "wrench", "shifted")


def memoised(memo: dict, key: tuple, states, compute):
    """``memo[key]`` (computed once): parts of the residual that many evaluations on the
    same ``states`` share (the measured wrench of one vehicle; the rotor channel of one
    command -> speed model). The entry holds ``states`` so that its id stays its own;
    ``states`` may be a tuple of the arrays the key holds the ids of (the measured wrench:
    the motion, which every rotor timing of a flight shares), each compared by identity."""
    hit = memo.get(key)
    if hit is not None and _same(hit[0], states):
        return hit[1]
    if len(memo) > 64:          # the oldest of these entries go (the per-flight ones stay)
        for old in [k for k in memo if isinstance(k, tuple) and k[0] in _PER_EVALUATION][:16]:
            del memo[old]
    value = compute()
    memo[key] = (states, value)
    return value


def _same(kept_refs, refs) -> bool:
    """Whether ``refs`` is ``kept_refs``, or both are tuples of the same objects."""
    if kept_refs is refs:
        return True
    return (type(kept_refs) is tuple and type(refs) is tuple and len(kept_refs) == len(refs)
            and all(a is b for a, b in zip(kept_refs, refs)))


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


def wrench_key(states, params: VehicleParams, effects: list) -> tuple:
    """What the model wrench depends on besides ``states`` and ``params``: the class and
    values of every effect that reaches it (the others only move the rotor channel, so a
    motor-lag fit evaluates the wrench once per rotor timing)."""
    return ("wrench", id(states), id(params), acting(effects, _WRENCH_HOOKS))


#: the hooks through which an effect reaches the rotor channel
#: (:func:`quadsim.gap.rotor_channel.rotor_residual`).
_ROTOR_HOOKS = ("rotor_speed_rate", "speed_factor", "rotor_speed_factor")


def identity(effect) -> tuple:
    """(class, sorted values) of ``effect``: what it is (an effect is its class and its
    values; they are set once, at construction), kept on the instance after the first call."""
    key = effect.__dict__.get("_identity")
    if key is None:
        key = (type(effect), tuple(sorted(effect.values().items())))
        effect.__dict__["_identity"] = key
    return key


def acting(effects: list, hooks: tuple) -> tuple:
    """:func:`identity` of each effect, in order, whose class has its own version of one of
    ``hooks``."""
    out = []
    for effect in effects:
        hit = _OVERRIDES.get((type(effect), hooks))
        if hit is None:
            hit = _overrides(type(effect), hooks)
        if hit:
            key = effect.__dict__.get("_identity")
            out.append(identity(effect) if key is None else key)
    return tuple(out)


_OVERRIDES: dict[tuple, bool] = {}


def _overrides(cls: type, hooks: tuple) -> bool:
    """Whether ``cls`` has its own version of one of ``hooks`` (kept per class)."""
    key = (cls, hooks)
    hit = _OVERRIDES.get(key)
    if hit is None:
        hit = _OVERRIDES[key] = any(getattr(cls, hook, None) is not getattr(EffectBase, hook)
                                    for hook in hooks)
    return hit


#: entries of one kind that :func:`kept` holds per flight (the oldest used goes first): a
#: Jacobian moves one parameter at a time, so the unmoved effects' loads and the vehicle
#: of the point it differentiates at are used again for each column (48 loads of a
#: 30 000-sample flight: 160 MB at most)
KEPT = 48


def kept(motion: dict, kind: str, key: tuple, refs: tuple, compute):
    """``compute()``, kept in the flight's ``motion`` dict (:func:`flight_memo`) under
    ``kind`` and ``key``, least recently used evicted past :data:`KEPT` entries. ``refs``:
    the objects whose ids ``key`` holds; the entry keeps them (so no other object takes
    their ids while it lives) and is used only while they are the same objects."""
    store = motion.get(kind)
    if store is None:
        store = motion[kind] = OrderedDict()
    hit = store.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], refs)):
        store.move_to_end(key)
        return hit[1]
    value = compute()
    store[key] = (refs, value)
    store.move_to_end(key)
    if len(store) > KEPT:
        store.popitem(last=False)
    return value


def rotor_key(states, params: VehicleParams, effects: list) -> tuple:
    """What the rotor channel depends on besides ``states``: the motor map (``params``) and
    the effects with a speed factor or rotor dynamics, in order
    (:func:`quadsim.gap.rotor_channel.rotor_residual`)."""
    return ("rotor", id(states), id(params), acting(effects, _ROTOR_HOOKS))


