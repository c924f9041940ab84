"""The residual a parameter set leaves on a flight log, per sample: the Newton-Euler wrench
the model misses (force and torque), joined over a log's airborne stretches; the rotor-speed
channel (measured speed ahead minus the model's prediction) and the static command -> speed
map it uses; the memo that keeps the parts of a residual that do not move between model
evaluations on one flight.

Memo
----

Residual parts kept across the many model evaluations on one flight
(:func:`quadsim.gap.fitting.residuals` with ``memo``): the per-flight evidence and the
calibration's Jacobians evaluate hundreds of models on the same samples, and most of a
model's residual does not move when one parameter does.

What is kept, and what it is keyed by (an effect is its class and its values):

* per flight (:func:`flight_memo`): the body-to-world rotations of the logged attitude and a
  dict the effects keep their own motion-only values in (the cable's attachment
  acceleration and swings, the rotor drag's hub terms) -- keyed by the identity of the
  logged-motion arrays;
* per evaluation kind (:func:`memoised`, oldest evicted first past :func:`entries_kept`
  entries): the measured
  wrench of one vehicle (mass, CoM, inertia), the rotor channel of one command -> speed
  model (:func:`rotor_key`: the effects with a speed factor or rotor dynamics) and its
  command side (:func:`rotor_model`: the same for every rotor delay), the model
  wrench of one set of effects that reach it (:func:`wrench_key`: a motor lag does not),
  the states shifted by one rotor delay;
* per sequence of effect objects (:func:`effects_plan`, the last :data:`PLANS_KEPT`): the
  keys above and which effects have loads and what they read, worked out once and not
  per evaluation; the vehicle's attribute values that an effect's loads read are kept
  with the vehicle object (:func:`_vehicle_values`);
* per flight and kind, in its motion dict (:func:`kept`, the least recently used evicted
  past :func:`entries_kept` entries; used by :func:`quadsim.gap.residual.model_wrench`): the
  vehicle of the effects that change it, the air velocity of those that move the air, and
  each effect's loads on one vehicle, air velocity and set of rotor speeds -- or, for an
  effect that declares what its loads read (:attr:`quadsim.effects.base.EffectBase.loads_reads`),
  on those inputs and vehicle attributes alone -- so a Jacobian column recomputes only the
  effect whose parameter it moves.

Each entry holds the states it was computed on, so an id is never mistaken for another's.
Equality with the residual computed from scratch: tests/test_fast_paths.py.

Residual wrench
---------------

Residual wrench: the force and torque a parameter set is missing, per sample of a flight log.

The model says the rotors (and any effects it includes) push the vehicle with a wrench
``(F_model, M_model)``; the log says what the vehicle actually did. Newton–Euler turns the
measured motion into the wrench that must have acted::

    F_meas = m * f_com                (body frame, N; f = specific force at the CoM)
    M_meas = I w_dot + w x (I w)      (body frame, about the CoM, N m)

and the residual is ``F_meas - F_model``, ``M_meas - M_model``: zero (up to sensor noise) when
the model is complete. ``f`` comes from the accelerometer when the log has one (it measures
the specific force at the body origin; the CoM offset adds ``w_dot x c + w x (w x c)``),
otherwise from kinematics ``R^T (a_world + g z)`` with ``a_world`` the second derivative of
position (or first of velocity).

Differentiator
--------------
The log is first resampled onto a uniform grid (median step; linear interpolation,
normalised-linear for quaternions), then every signal that enters the balance (accelerometer,
body rate, velocity/position, rotor speeds) is smoothed and differentiated with the same
Savitzky–Golay filter (``scipy.signal.savgol_filter``; default window 0.1 s, cubic). The
filter is a symmetric FIR, so it is zero-phase: **no lag** between the differentiated motion
and the rotor speeds, and because all signals pass the same filter the balance is not
distorted by different delays. Its amplitude response is flat at low frequency and falls to
-3 dB near ``1.1 / window`` for the smoothed value (about 11 Hz for 0.1 s, cubic; the long
window keeps the noise of differentiated gyro and rotor speeds, which would bias inertia and
rotor-inertia estimates low, small); content
above that is attenuated in both sides of the balance alike (docs/gap.md, "Residual wrench").

Example::

    >>> from quadsim.logs.flightlog import load_log
    >>> from quadsim.vehicle.params import load_params
    >>> from quadsim.gap.residual import flight_states, measured_wrench, model_wrench
    >>> params = load_params("crazyflie21")
    >>> states = flight_states(load_log("flight.csv.gz"), gravity=params.gravity)
    >>> force, torque, vehicle = model_wrench(states, params)   # (N, 3) each, body frame
    >>> measured = measured_wrench(states, vehicle)
    >>> measured[0] - force, measured[1] - torque               # the residual, N and N m

Conventions: body x forward, y left, z up; quaternions scalar-first body-to-world; rotor
speeds rad/s; all arrays have the sample axis first.

Several airborne stretches
--------------------------

A flight of several airborne stretches (take-offs) as one set of states.

A log with several take-offs keeps every airborne stretch as a segment of one flight
(:func:`quadsim.logs.spans.join_airborne`, :attr:`quadsim.logs.flightlog.FlightLog.segments`).
Each stretch is resampled, smoothed and differentiated alone (:func:`quadsim.gap.residual.
flight_states`; all on one time step), trimmed at its own ends and decimated alone
(:func:`quadsim.gap.diagnose.prepare`), and only then are the states joined: the residual is
per sample, so no sample's residual mixes two stretches; the time axis keeps its jump (a
non-uniform time base is read by interpolation where a delay is applied,
:func:`quadsim.gap.reference.read_later`, within one step of a join).

Example::

    >>> from quadsim.gap.residual import joined_states
    >>> states = joined_states([flight_states(p, dt=0.002) for p in log.parts()])

Command -> speed map
--------------------

The static command -> rotor-speed map of the gap diagnosis (fitted from data).

Logs normalise commands differently (``quadsim.fly``: speed / max_speed, or the command the
set's own motor map gives; the Crazyflie firmware: PWM / 65535), so the rotor channel's
static map is taken from the data (training or reference flights): what the rotor channel
then measures is the rotor *dynamics*, and effects upstream of the speed (a battery's
voltage, a motor lag) act on top of it.

Example::

    >>> from quadsim.gap.residual import fit_motor_map, speed_of_command
    >>> tuned = fit_motor_map([states], params)          # FlightStates with commands
    >>> speed_of_command(tuned, np.full((1, 4), 0.5))    # rad/s per rotor

Commands are normalised 0-1 (per rotor); speeds in rad/s.

Rotor-speed channel
-------------------

The rotor-speed channel of the gap diagnosis: the measured rotor speed ``ROTOR_HORIZON_S``
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

    >>> from quadsim.gap.residual import rotor_residual
    >>> r = rotor_residual(states, params, [make_effect("motor_lag", time_constant=0.03)])
    >>> r.shape        # (N, R): zero for the first horizon's samples and across flights
"""

from __future__ import annotations

import dataclasses
import functools
import operator
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import InputError
from ..core.frames import cross, quat_normalize, rotate_inverse
from ..core.lag import first_order_lag
from ..effects.base import Effect, EffectBase, EffectContext, EffectLoads, EffectSet
from ..logs.flightlog import FlightLog, body_rate_from_quat
from ..logs.savgol import savgol  # scipy's savgol_filter, the ends' fits cached
from ..vehicle.params import MotorMap, VehicleParams
from ..vehicle.rotors import allocation_matrix

__all__ = ["KEPT", "MEMO_VALUES", "acting", "entries_kept", "flight_memo", "identity", "kept",
           "EffectsPlan", "effects_plan", "PLANS_KEPT",
           "memoised", "rotor_key", "FIT_RATE_HZ",
           "wrench_key", "CHANNELS", "DEFAULT_WINDOW_S", "FlightStates", "channel_unit",
           "flight_states", "measured_wrench", "model_wrench", "resample_uniform",
           "rotor_matrices", "rotor_wrench", "window_samples", "joined_states", "fit_motor_map",
           "load_exponent", "command_speed", "fit_set_map", "speed_of_command",
           "fit_command_map", "map_misfit",
           "command_of_speed",
           "MAP_WINDOW_S", "MAP_MIN_RANGE", "FLAT_COMMAND", "flat_command", "ROTOR_HORIZON_S",
           "ROTOR_SUBSTEPS",
           "min_time_constant", "rate_owner", "rotor_residual", "RotorModel", "rotor_model"]


if TYPE_CHECKING:
    from ..vehicle.params import VehicleParams



#: kinds of :func:`memoised` entries that one model or one rotor timing owns (evicted oldest
#: first); the per-flight ones (:func:`flight_memo`) are kept.
_PER_EVALUATION = ("measured", "rotor", "rotor_model", "wrench", "shifted",
                   "scaled_command")


def memoised(memo: dict, key: tuple, states, compute):
    """``memo[key]`` (computed once): parts of the residual that many evaluations on the
    same ``states`` share (the measured wrench of one vehicle; the rotor channel of one
    command -> speed model). The entry holds ``states`` so that its id stays its own;
    ``states`` may be a tuple of the arrays the key holds the ids of (the measured wrench:
    the motion, which every rotor timing of a flight shares), each compared by identity."""
    hit = memo.get(key)
    if hit is not None and _same(hit[0], states):
        return hit[1]
    limit = entries_kept(len(states[0]) if type(states) is tuple else len(states.t), 64)
    if len(memo) > limit:       # the oldest of these entries go (the per-flight ones stay)
        old = [k for k in memo if isinstance(k, tuple) and k[0] in _PER_EVALUATION]
        for k in old[:max(16, limit // 4)]:
            del memo[k]
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

    value = (quat_to_rotmat(states.quat), {_LIMIT: entries_kept(len(states.t), KEPT)})
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
#: (:func:`quadsim.gap.residual.rotor_residual`).
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


class EffectsPlan:
    """What one sequence of effect objects is, for the memo (worked out once per sequence,
    :func:`effects_plan`; an effect is its class and its values, set at construction): the
    :func:`acting` keys of the model wrench (``wrench``), of the vehicle (``vehicle``:
    ``apply_to_params``) and of the air velocity (``air``); ``loads``: (effect,
    :func:`identity`, what its loads read) of each effect without internal state whose
    class has its own ``loads``, in order (what it reads: None for anything, else (the
    indices of its context fields in ``(air_velocity, rotor_speed, rotor_accel, vbat)``,
    the fields, the vehicle attributes), :attr:`quadsim.effects.base.EffectBase.loads_reads`);
    ``stateful``: whether any effect has internal state (then the loads go through
    :meth:`quadsim.effects.base.EffectSet.loads`); :meth:`rotor` the :func:`rotor_key` part
    per rotor count. Each effect's part of these depends on that effect alone, in order:
    ``prefix``, the plan of ``effects``' first effects, gives theirs as they are (a fit's
    shared effects, then its own ones, which move at every step)."""

    __slots__ = ("effects", "wrench", "vehicle", "air", "loads", "stateful", "_rotor",
                 "_owner", "factor", "_prefix")

    def __init__(self, effects: tuple, prefix: EffectsPlan | None = None):
        self.effects = effects
        self._prefix = prefix
        if prefix is None:
            wrench, vehicle, air, loads, factor = [], [], [], [], []
            self.stateful = False
        else:
            wrench, vehicle, air, loads, factor = (
                list(prefix.wrench), list(prefix.vehicle), list(prefix.air),
                list(prefix.loads), list(prefix.factor))
            self.stateful = prefix.stateful
            effects = effects[len(prefix.effects):]
        for effect in effects:
            cls = type(effect)
            facts = _CLASS_FACTS.get(cls)
            if facts is None:
                facts = _CLASS_FACTS[cls] = _class_facts(cls)
            stateful = facts[4] and effect.state_size()
            self.stateful = self.stateful or bool(stateful)
            if not (facts[0] or facts[6]):
                continue                # no hook of the model wrench or the command factor
            key = effect.__dict__.get("_identity")
            if key is None:
                key = identity(effect)
            if facts[6]:
                factor.append(key)
            if not facts[0]:
                continue                # no hook of the model wrench
            wrench.append(key)
            if facts[1]:
                vehicle.append(key)
            if facts[2]:
                air.append(key)
            if facts[3] and not stateful:
                loads.append((effect, key, facts[5]))
        self.wrench, self.vehicle, self.air = tuple(wrench), tuple(vehicle), tuple(air)
        self.loads = tuple(loads)
        self._rotor: dict = {}
        self._owner: tuple = ()
        #: :func:`identity` of each effect with a speed factor (``speed_factor``,
        #: ``rotor_speed_factor``), in order: what the command factor depends on
        self.factor = tuple(factor)

    @property
    def owner(self):
        """:func:`rate_owner` of the effects (worked out once)."""
        if not self._owner:
            prefix = self._prefix
            owner = None if prefix is None else prefix.owner
            if owner is None:
                owner = rate_owner(self.effects[0 if prefix is None else
                                                len(prefix.effects):])
            self._owner = (owner,)
        return self._owner[0]

    def rotor(self, rotors: int) -> tuple:
        """The effects' part of :func:`rotor_key` for ``rotors`` rotors (kept per count)."""
        hit = self._rotor.get(rotors)
        if hit is None:
            prefix = self._prefix
            hit = self._rotor[rotors] = _rotor_part(self.effects, rotors) if prefix is None \
                else prefix.rotor(rotors) + _rotor_part(self.effects[len(prefix.effects):],
                                                        rotors)
        return hit


_CLASS_FACTS: dict[type, tuple] = {}


def _class_facts(cls: type) -> tuple:
    """What :class:`EffectsPlan` reads of an effect class: whether it has its own version
    of a hook of the model wrench, of ``apply_to_params``, of ``air_velocity``, of
    ``loads``, of ``state_size``, what its loads read (``loads_reads`` with the
    fields' indices in :data:`_CONTEXT_INPUTS`, or None), and whether it has its own
    ``speed_factor`` or ``rotor_speed_factor``."""
    reads = getattr(cls, "loads_reads", None)
    if reads is not None:
        fields, attributes = reads
        reads = (tuple(_CONTEXT_INPUTS.index(name) for name in fields), fields, attributes)
    return (_overrides(cls, _WRENCH_HOOKS), _overrides(cls, ("apply_to_params",)),
            _overrides(cls, ("air_velocity",)), cls.loads is not EffectBase.loads,
            getattr(cls, "state_size", EffectBase.state_size) is not EffectBase.state_size,
            reads, _overrides(cls, ("speed_factor", "rotor_speed_factor")))


#: the :class:`quadsim.effects.base.EffectContext` fields an effect's ``loads_reads`` may
#: name, in the order :func:`model_wrench` hands them to the memo
_CONTEXT_INPUTS = ("air_velocity", "rotor_speed", "rotor_accel", "vbat")
#: plans kept (:func:`effects_plan`): a weighing's explanations and their Jacobian columns
#: build a few hundred effect sequences per flight
PLANS_KEPT = 512
_PLANS: dict = {}


def effects_plan(effects) -> EffectsPlan:
    """The :class:`EffectsPlan` of the effect objects ``effects`` (a sequence), kept by
    their ids (the entry holds the objects, so an id is never another's) for the last
    :data:`PLANS_KEPT` sequences."""
    effects = tuple(effects)
    return _plan(effects, tuple(map(id, effects)))


def _plan(effects: tuple, key: tuple) -> EffectsPlan:
    """:func:`effects_plan` of ``effects`` with their ids ``key``; one not kept is built on
    the plan of all but its last effect (kept or built so too)."""
    hit = _PLANS.get(key)
    if hit is not None and all(map(operator.is_, hit.effects, effects)):
        return hit
    plan = EffectsPlan(effects, _plan(effects[:-1], key[:-1]) if len(effects) > 1 else None)
    if len(_PLANS) >= PLANS_KEPT:
        del _PLANS[next(iter(_PLANS))]
    _PLANS[key] = plan
    return plan


def _overrides(cls: type, hooks: tuple) -> bool:
    """Whether ``cls`` has its own version of one of ``hooks`` (kept per class)."""
    key = (cls, hooks)
    hit = _OVERRIDES.get(key)
    if hit is None:
        hit = _OVERRIDES[key] = any(getattr(cls, hook, None) is not getattr(EffectBase, hook)
                                    for hook in hooks)
    return hit


#: entries of one kind that :func:`kept` holds per flight at least (the oldest used goes
#: first): a Jacobian moves one parameter at a time, so the unmoved effects' loads and the
#: vehicle of the point it differentiates at are used again for each column (48 loads of a
#: 30 000-sample flight: 160 MB at most)
KEPT = 48
#: float64 values (64 MiB) that one kind of kept entries (:func:`kept`) and the memo's
#: per-evaluation entries (:func:`memoised`) may hold per flight, an entry counted as 16
#: values per sample (a wrench 6, a rotor channel or shifted rotor speeds 4-8, an effect's
#: loads 6-10): a short flight keeps many more entries than the floor, so that what the
#: explanations' fits revisit (the loads at an earlier delay, the shifted states of an
#: earlier step) is not computed again; a long one keeps the floor.
MEMO_VALUES = 2 ** 23
#: where a flight's motion dict (:func:`flight_memo`) holds its :func:`entries_kept`
_LIMIT = "gap.entries_kept"


def entries_kept(samples: int, floor: int) -> int:
    """Entries of one kind kept per flight of ``samples`` samples: :data:`MEMO_VALUES` over
    16 values per sample, at least ``floor``."""
    return max(floor, MEMO_VALUES // (16 * max(1, samples)))


def kept(motion: dict, kind: str, key: tuple, refs: tuple, compute):
    """``compute()``, kept in the flight's ``motion`` dict (:func:`flight_memo`) under
    ``kind`` and ``key``, least recently used evicted past :func:`entries_kept` entries
    (:data:`KEPT` in a dict not made by :func:`flight_memo`). ``refs``:
    the objects whose ids ``key`` holds; the entry keeps them (so no other object takes
    their ids while it lives) and is used only while they are the same objects."""
    store = motion.get(kind)
    if store is None:
        store = motion[kind] = OrderedDict()
    hit = store.get(key)
    if hit is not None and all(map(operator.is_, hit[0], refs)):
        store.move_to_end(key)
        return hit[1]
    value = compute()
    store[key] = (refs, value)
    store.move_to_end(key)
    if len(store) > motion.get(_LIMIT, KEPT):
        store.popitem(last=False)
    return value


def rotor_key(states, params: VehicleParams, effects: list) -> tuple:
    """What the rotor channel depends on besides ``states``: the motor map (``params``) and
    the effects with a speed factor or rotor dynamics, in order
    (:func:`quadsim.gap.residual.rotor_residual`). An effect whose only such hook is a
    per-rotor factor (``rotor_speed_factor``, one propeller's speed per command) enters by
    the factor it gives, and not at all where it gives none: the channel multiplies the
    factors in order and skips a None, so a propeller's thrust moved alone (its factor
    None or unchanged) reuses the channel."""
    rotors = params.rotor_count if states.command is None else states.command.shape[1]
    return ("rotor", id(states), id(params), _rotor_part(effects, rotors))


def _rotor_part(effects, rotors: int) -> tuple:
    """The effects' part of :func:`rotor_key` for ``rotors`` rotors."""
    out = []
    for effect in effects:
        cls = type(effect)
        if not _overrides(cls, _ROTOR_HOOKS):
            continue
        if _overrides(cls, _DYNAMIC_HOOKS):
            out.append(identity(effect))
            continue
        factor = effect.rotor_speed_factor(rotors)
        if factor is not None:
            out.append(("rotor_speed_factor",
                        np.asarray(factor, dtype=float).tobytes()))
    return tuple(out)


#: the rotor-channel hooks other than the static per-rotor factor (:func:`rotor_key`)
_DYNAMIC_HOOKS = ("rotor_speed_rate", "speed_factor")


#: Savitzky–Golay window (s) used unless told otherwise.
DEFAULT_WINDOW_S = 0.1
#: Hz; the rate the diagnosis fits at (:func:`quadsim.gap.diagnose.prepare` decimates the
#: states to it; re-exported there as ``diagnose.FIT_RATE_HZ``).
FIT_RATE_HZ = 100.0
CHANNELS = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


def channel_unit(name: str) -> str:
    """Unit of a residual channel: Fx..Fz N, Mx..Mz N m, a rotor-speed channel rad/s."""
    return {"F": "N", "M": "N m"}.get(name[0], "rad/s")


@dataclass(frozen=True)
class FlightStates:
    """A log on a uniform grid with smoothed values and derivatives (all SI, sample axis first).

    t (N,); position, velocity, accel_world (N, 3) world; quat (N, 4); body_rate,
    body_accel (N, 3) body (rad/s, rad/s^2); specific_force (N, 3) body at the origin (m/s^2);
    rotor_speed, rotor_accel (N, R) or None; command (N, R) normalised or None; vbat (N,) or
    None; accel_source: "accelerometer" or "kinematics"; window_s, polyorder: the filter;
    name: where the log came from; pose: False for a log without a pose (IMU and motors
    only): position and velocity are then zero, stand-ins that no effect weighed on it
    reads (:attr:`quadsim.effects.facts.EffectFacts.needs_pose`, :mod:`quadsim.gap.logcheck`);
    attitude: whether ``quat`` is the logged attitude (True with a pose). Without a pose,
    accel_world is the accelerometer turned to the world, ``R f - g e_z``, and quat the
    logged attitude or, without one, the gyro's own frame (the body rate integrated from
    the accelerometer's tilt at the start, yaw 0: :func:`quadsim.gap.logcheck.posefree_states`).
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    accel_world: np.ndarray
    quat: np.ndarray
    body_rate: np.ndarray
    body_accel: np.ndarray
    specific_force: np.ndarray
    rotor_speed: np.ndarray | None
    rotor_accel: np.ndarray | None
    command: np.ndarray | None
    vbat: np.ndarray | None
    accel_source: str
    window_s: float
    polyorder: int
    name: str = ""
    pose: bool = True
    attitude: bool = True
    #: the rotor speeds were synthesised from the log's commands
    #: (:func:`quadsim.gap.logcheck.synthesise_speeds`): model speeds, on which an effect
    #: upstream of the speed (a battery's sag) acts (:func:`quadsim.gap.fitting.residuals`)
    synthesised: bool = False

    def __len__(self) -> int:
        return len(self.t)

    def take(self, index: np.ndarray) -> FlightStates:
        """The states at the sample indices (or boolean mask) ``index``."""
        def pick(value):
            return None if value is None else value[index]

        return FlightStates(self.t[index], self.position[index], self.velocity[index],
                            self.accel_world[index], self.quat[index], self.body_rate[index],
                            self.body_accel[index], self.specific_force[index],
                            pick(self.rotor_speed), pick(self.rotor_accel), pick(self.command),
                            pick(self.vbat), self.accel_source, self.window_s, self.polyorder,
                            self.name, self.pose, self.attitude, self.synthesised)


# ----------------------------------------------------------------------------- resampling


def _quat_continuous(quat: np.ndarray) -> np.ndarray:
    """Flip signs so that neighbouring quaternions are in the same hemisphere."""
    quat = np.array(quat, dtype=float)
    flips = np.sign(np.sum(quat[1:] * quat[:-1], axis=-1))
    quat[1:] *= np.cumprod(np.where(flips == 0, 1.0, flips))[:, None]
    return quat


def resample_uniform(log: FlightLog, dt: float | None = None) -> FlightLog:
    """``log`` on a uniform time grid (step ``dt``, default the median step), by linear
    interpolation (quaternions: interpolated componentwise after a sign fix, renormalised)."""
    t = np.asarray(log.t, dtype=float)
    if len(t) < 2:
        raise InputError(f"{log.path or 'log'}: t: fewer than 2 samples")
    step = float(np.median(np.diff(t))) if dt is None else float(dt)
    grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step + 1e-9)) + 1)

    def interp(value):
        if value is None:
            return None
        value = np.asarray(value, dtype=float)
        if value.ndim == 1:
            return np.interp(grid, t, value)
        return np.stack([np.interp(grid, t, value[:, i]) for i in range(value.shape[1])], -1)

    quat = quat_normalize(interp(_quat_continuous(log.quat)))
    return FlightLog(grid, interp(log.position), quat, interp(log.velocity),
                     interp(log.body_rate), interp(log.accel), interp(log.rotor_speed),
                     interp(log.rotor_command), interp(log.vbat), log.path)


def window_samples(window_s: float, dt: float, polyorder: int = 3) -> int:
    """The Savitzky–Golay window in samples: ``window_s / dt`` (s / s) rounded, made odd,
    and at least the shortest window of order ``polyorder``."""
    n = round(window_s / dt)
    n += 1 - n % 2  # odd
    return max(n, polyorder + 2 + (polyorder + 1) % 2)


# ----------------------------------------------------------------------------- states


def flight_states(log: FlightLog, *, window_s: float = DEFAULT_WINDOW_S, polyorder: int = 3,
                  use_accelerometer: bool = True, gravity: float = 9.81,
                  dt: float | None = None) -> FlightStates:
    """Resample ``log`` and smooth/differentiate it with one Savitzky–Golay filter.

    Raises :class:`InputError` if the log is shorter than the filter window."""
    log = resample_uniform(log, dt)
    step = float(log.t[1] - log.t[0])
    window = window_samples(window_s, step, polyorder)
    if len(log.t) < window + 2:
        raise InputError(f"{log.path or 'log'}: t: {len(log.t)} samples, fewer than the "
                         f"{window}-sample smoothing window ({window_s} s)")

    def smooth(x, deriv=0):
        return savgol(x, window, polyorder, deriv=deriv, delta=step)   # savgol_filter's

    quat = quat_normalize(smooth(_quat_continuous(log.quat)))
    rate_raw = log.body_rate if log.body_rate is not None else body_rate_from_quat(log.t, log.quat)
    body_rate, body_accel = smooth(rate_raw), smooth(rate_raw, 1)
    if log.velocity is not None:
        velocity, accel_world = smooth(log.velocity), smooth(log.velocity, 1)
    else:
        velocity, accel_world = smooth(log.position, 1), smooth(log.position, 2)
    if use_accelerometer and log.accel is not None and np.all(np.isfinite(log.accel)):
        specific_force, source = smooth(log.accel), "accelerometer"
    else:
        specific_force = rotate_inverse(quat, accel_world + np.array([0.0, 0.0, gravity]))
        source = "kinematics"
    rotor_speed = rotor_accel = None
    if log.rotor_speed is not None:
        rotor_speed, rotor_accel = smooth(log.rotor_speed), smooth(log.rotor_speed, 1)
    command = None if log.rotor_command is None else smooth(log.rotor_command)
    vbat = None if log.vbat is None else smooth(log.vbat)
    return FlightStates(log.t, smooth(log.position), velocity, accel_world, quat, body_rate,
                        body_accel, specific_force, rotor_speed, rotor_accel, command, vbat,
                        source, float(window_s), int(polyorder),
                        str(log.path) if log.path is not None else "")


# ----------------------------------------------------------------------------- the balance


def _effect_set(effects: Iterable[Effect] | EffectSet | None) -> EffectSet:
    if effects is None:
        return EffectSet(())
    if isinstance(effects, EffectSet):
        return effects
    return EffectSet(tuple(effects))


def _require_rotors(states: FlightStates, params: VehicleParams) -> np.ndarray:
    if states.rotor_speed is None:
        raise InputError(f"{states.name or 'log'}: rotor_1..rotor_N: the log has no measured "
                         "rotor speeds; the residual wrench needs them")
    if states.rotor_speed.shape[1] != params.rotor_count:
        raise InputError(f"{states.name or 'log'}: rotor_1..rotor_N: "
                         f"{states.rotor_speed.shape[1]} rotor columns, the model "
                         f"{params.name!r} has {params.rotor_count} rotors")
    return states.rotor_speed


def rotor_wrench(vehicle: VehicleParams, loads, speed: np.ndarray,
                 matrices: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Body-frame wrench (N, 6) of the rotors alone: force (N) and torque about the CoM (N m)
    of speeds ``speed`` (N, R) rad/s with the effects' per-rotor ``loads.thrust_scale`` and
    ``loads.rotor_offset`` (a thrust offset o_i acts along axis a_i at hub r_i: force
    o_i a_i, torque o_i (r_i - c) x a_i). The effects' other loads are not included.
    ``matrices``: :func:`rotor_matrices` of ``vehicle`` when the caller keeps them."""
    allocation_t, offset_wrench = rotor_matrices(vehicle) if matrices is None else matrices
    squared, offset = _thrusts(loads, speed)
    wrench = squared @ allocation_t
    if offset is None:
        return wrench                       # no offsets: nothing to add
    return wrench + offset @ offset_wrench


def _thrusts(loads, speed: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(the squared speeds (N, R) times ``loads.thrust_scale``, ``loads.rotor_offset``
    (N, R) or None where both offsets are neutral) of :func:`rotor_wrench`."""
    neutral = getattr(loads, "is_neutral", lambda name: False)
    squared = np.square(speed)
    if not neutral("thrust_scale"):         # a scale of one changes nothing
        squared = squared * loads.thrust_scale
    if neutral("thrust_offset") and neutral("curve_offset"):
        return squared, None
    return squared, loads.rotor_offset


def _rotor_force_torque(loads, speed: np.ndarray, halves: tuple) -> tuple[np.ndarray,
                                                                          np.ndarray]:
    """:func:`rotor_wrench`'s force (N, 3) and torque (N, 3) as two arrays of their own
    (contiguous: the residual's differences on them run several times faster than on the
    wrench's column views), from ``halves``, the force and torque columns of
    :func:`rotor_matrices` (:func:`_vehicle_matrices`): the same products, each element
    the same sum over the rotors."""
    force_map, torque_map, offset_force, offset_torque = halves
    squared, offset = _thrusts(loads, speed)
    force, torque = squared @ force_map, squared @ torque_map
    if offset is None:
        return force, torque
    return force + offset @ offset_force, torque + offset @ offset_torque


def rotor_matrices(vehicle: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """The (R, 6) maps of :func:`rotor_wrench`: squared speeds to the wrench (the allocation
    matrix, transposed) and thrust offsets (N) to the wrench."""
    axes = vehicle.rotor_axes
    offset = np.hstack([axes, cross(vehicle.rotor_positions - vehicle.com, axes)])
    return allocation_matrix(vehicle).T, offset


def model_wrench(states: FlightStates, params: VehicleParams,
                 effects: Iterable[Effect] | EffectSet | None = None,
                 *, rotor_speed: np.ndarray | None = None, rotation: np.ndarray | None = None,
                 flight_memo: dict | None = None
                 ) -> tuple[np.ndarray, np.ndarray, VehicleParams]:
    """Body-frame force (N, 3) and torque about the CoM (N, 3) that the model (``params``
    plus ``effects``) predicts from the measured states and rotor speeds; also the effective
    parameter set (after the effects' ``apply_to_params``). ``rotation``: the states'
    body-to-world matrices (N, 3, 3) when the caller keeps them; ``flight_memo``: handed to
    the effects as :attr:`quadsim.effects.base.EffectContext.flight_memo` (values that depend
    only on the logged motion of ``states``), where the vehicle, the air velocity and each
    effect's loads are also kept (:func:`quadsim.gap.residual.kept`: the same numbers, computed
    once per effect, vehicle, air velocity and rotor speeds, or per effect and what it
    declares its loads read, :attr:`quadsim.effects.base.EffectBase.loads_reads`)."""
    effect_set = _effect_set(effects)
    speed = _require_rotors(states, params) if rotor_speed is None else rotor_speed
    accel = states.rotor_accel if states.rotor_accel is not None else np.zeros_like(speed)
    if flight_memo is None:
        vehicle = effect_set.apply_to_params(params)
        air = states.velocity - effect_set.air_velocity(states.t, states.position)
        vbat = states.vbat if states.vbat is not None else np.full(len(states.t), np.nan)
        matrices = None
    else:
        plan = effects_plan(effect_set.effects)
        vehicle, matrices, values = kept(
            flight_memo, "vehicle", (id(params), plan.vehicle), (params,),
            lambda: _vehicle_matrices(effect_set.apply_to_params(params), flight_memo))
        air = kept(flight_memo, "air", plan.air, (),
                   lambda: states.velocity - effect_set.air_velocity(states.t, states.position))
        vbat = states.vbat if states.vbat is not None else kept(
            flight_memo, "no_vbat", (), (), lambda: np.full(len(states.t), np.nan))
    ctx = EffectContext(states.t, states.position, states.velocity, states.quat,
                        states.body_rate, air, speed, accel, vehicle, vbat,
                        rotation=rotation, flight_memo=flight_memo,
                        accel_world=None if states.pose else states.accel_world)
    if flight_memo is None:
        loads = effect_set.loads(ctx)
    elif plan.stateful:
        loads = effect_set.loads(ctx, kept=_keeper(flight_memo, ctx, values))
    else:       # EffectSet.loads through _keeper, without its per-effect lookups
        inputs = (air, speed, accel, vbat)
        context_key = None
        parts = []
        for effect, ident, reads in plan.loads:
            if reads is None:       # it may read anything: keyed by the whole context
                if context_key is None:
                    refs = (vehicle,) + inputs
                    context_key = tuple(map(id, refs))
                part = kept(flight_memo, "loads", (ident,) + context_key, refs,
                            functools.partial(effect.loads, ctx))
            else:
                index, fields, attributes = reads
                own = tuple(map(inputs.__getitem__, index))
                part = kept(flight_memo, "loads",
                            (ident, fields, tuple(map(id, own)),
                             _vehicle_values(values, vehicle, attributes)),
                            own, functools.partial(effect.loads, ctx))
            if part is not None:
                parts.append(part)
        loads = EffectLoads.combine(parts, speed.shape[0], speed.shape[1])
    if matrices is None:
        wrench = rotor_wrench(vehicle, loads, speed)
        force, torque = wrench[:, :3], wrench[:, 3:]
    else:
        force, torque = _rotor_force_torque(loads, speed, matrices[2])
    if not loads.is_neutral("force_world"):     # a zero external load adds nothing
        force = force + ctx.to_body(loads.force_world)
    if not loads.is_neutral("torque_body"):
        torque = torque + loads.torque_body
    return force, torque, vehicle


def _vehicle_matrices(vehicle: VehicleParams, flight_memo: dict):
    """``vehicle``, its :func:`rotor_matrices` with their force and torque columns apart
    (contiguous (R, 3) each: the allocation's, the offsets'; :func:`_rotor_force_torque`)
    and a dict for its :func:`_vehicle_values`; the matrices kept in ``flight_memo`` by
    what they depend on (the rotors, the CoM, the thrust and drag factors): a vehicle that
    differs in its mass or inertia alone shares them."""
    key = (id(vehicle.rotors), np.asarray(vehicle.com, dtype=float).tobytes(),
           float(vehicle.thrust_factor), float(vehicle.drag_factor))

    def compute():
        allocation_t, offset = rotor_matrices(vehicle)
        halves = tuple(np.ascontiguousarray(m[:, cols]) for m in (allocation_t, offset)
                       for cols in (slice(0, 3), slice(3, 6)))
        return allocation_t, offset, halves
    return vehicle, kept(flight_memo, "rotor_matrices", key, (vehicle.rotors,), compute), {}


def _vehicle_values(values: dict, vehicle: VehicleParams, attributes: tuple) -> tuple:
    """The values (float64 bytes) of ``vehicle``'s ``attributes``, kept in ``values`` (the
    dict :func:`_vehicle_matrices` made for this vehicle object): an effect's loads that
    read only these stay the same when a fit moves another part of the vehicle (an
    inertia, a thrust factor)."""
    if not attributes:
        return ()
    hit = values.get(attributes)
    if hit is None:
        hit = values[attributes] = tuple(np.asarray(getattr(vehicle, name),
                                                    dtype=float).tobytes()
                                         for name in attributes)
    return hit


def _keeper(flight_memo: dict, ctx: EffectContext, values: dict):
    """The ``kept`` callable of :meth:`quadsim.effects.base.EffectSet.loads` on ``ctx``:
    each effect's loads kept in ``flight_memo`` (:func:`kept`) by what they read."""
    refs = (ctx.params, ctx.air_velocity, ctx.rotor_speed, ctx.rotor_accel, ctx.vbat)
    context_key = tuple(map(id, refs))
    inputs = dict(zip(_CONTEXT_INPUTS, refs[1:]))

    def keep(effect, compute):
        reads = getattr(type(effect), "loads_reads", None)
        if reads is None:       # it may read anything: keyed by the whole context
            return kept(flight_memo, "loads", (identity(effect),) + context_key, refs,
                        compute)
        fields, attributes = reads
        own = tuple(inputs[name] for name in fields)
        key = (identity(effect), fields, tuple(map(id, own)),
               _vehicle_values(values, ctx.params, attributes))
        return kept(flight_memo, "loads", key, own, compute)
    return keep


def measured_wrench(states: FlightStates, params: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame force (N, 3) and torque about the CoM (N, 3) implied by the measured motion
    for a vehicle with ``params``' mass, CoM and inertia (Newton–Euler)."""
    w, w_dot, com = states.body_rate, states.body_accel, params.com
    if np.any(com):
        lever = cross(w_dot, com) + cross(w, cross(w, com))
        force = params.mass * (states.specific_force + lever)
    else:                                   # the CoM at the origin: no lever arm
        force = params.mass * states.specific_force
    inertia = params.inertia
    torque = w_dot @ inertia.T + cross(w, w @ inertia.T)
    return force, torque


def joined_states(parts: list[FlightStates]) -> FlightStates:
    """The states of ``parts`` (in time order, one filter and step) concatenated along the
    sample axis; one part is returned as it is. Raises ValueError for parts with different
    filters or a None channel in some parts only."""
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    for p in parts[1:]:
        if (p.window_s, p.polyorder, p.accel_source) != (first.window_s, first.polyorder,
                                                         first.accel_source):
            raise ValueError("joined_states: the parts were smoothed differently")
    arrays = {}
    for f in dataclasses.fields(FlightStates):
        values = [getattr(p, f.name) for p in parts]
        if not isinstance(values[0], np.ndarray) and values[0] is not None:
            continue
        if any(v is None for v in values):
            if not all(v is None for v in values):
                raise ValueError(f"joined_states: {f.name} in some parts only")
            continue
        arrays[f.name] = np.concatenate(values, axis=0)
    return dataclasses.replace(first, **arrays)


def fit_motor_map(flights: list[FlightStates], params: VehicleParams, *,
                  duty_voltage: float | None = None) -> VehicleParams:
    """``params`` with a per-rotor straight-line map cmd (0-1) -> speed fitted on ``flights``.

    ``duty_voltage`` (V; None: the command alone): the map's command axis is the command
    times the logged battery voltage over ``duty_voltage`` (``MotorMap.duty_voltage``;
    every flight must log ``vbat``). Physics: a DC motor driven at duty u from a battery at
    V turns where ``u V = k Omega + (R d / k) Omega^2`` (:func:`load_exponent`), so its
    steady speed is a function of u V alone, and a map read on flights at one charge
    transfers to a flight at another only in u V (docs/identification.md, "The rotor channels
    held out").

    Logs normalise commands differently (``quadsim.fly``: speed / max_speed, or the command
    the set's own motor map gives; the Crazyflie firmware: PWM / 65535), so the rotor
    channel's static map is taken from the (training or reference) data; what the channel
    then measures is the rotor *dynamics*.

    The map is static, so it is fitted on both signals averaged over
    :data:`MAP_WINDOW_S` (moving mean, per flight, edges dropped): a measured speed that
    follows the command with a lag tau (motor, ESC telemetry, filtering) regressed on the
    raw command has its slope shrunk to the command's autocorrelation at tau (a
    30 ms lag on a 2 Hz manoeuvre: cos(2 pi 2 0.03) = 0.93), and a vehicle flying at other
    commands than the training flights (heavier, faster) would then show the map's error as
    a gap on the rotor channel. What the moving mean still passes of a manoeuvre the lag
    attenuates too, so the command is taken through the rotors' lag first (:func:`map_lag`).

    Per rotor, the map is the straight line ``a + k command`` or the proportional gain
    through the origin ``k command`` (an ideal motor and ESC). The line needs both a range of
    commands of at least :data:`MAP_MIN_RANGE` of their mean and the data's support
    (:func:`_line_supported`: the Bayesian information criterion on the averaged samples,
    counted as one per window). Why the range: over a narrower one (a gentle path) the
    line's slope is noise, and the moving mean's leftover lag still favours it. Why the
    support: on a motor whose speed is proportional to its command, the range alone takes
    a line whose intercept is noise, off by a fraction of the rotor channel's noise at
    another command, which the propeller reading's speed-per-command exponent takes up
    (measured: CHANGELOG.md, "fit_motor_map's measurements")."""
    if duty_voltage is not None:
        if any(f.command is not None and f.vbat is None for f in flights):
            raise ValueError("fit_motor_map: duty_voltage needs every flight's vbat")
        flights = [f if f.command is None else dataclasses.replace(
            f, command=f.command * (np.asarray(f.vbat, float) / duty_voltage)[:, None])
            for f in flights]
    lines = _static_lines(flights)
    if lines is None:
        return params
    ends = [[intercept, intercept + slope] for slope, intercept in lines]
    source = "fitted on the training flights (quadsim.gap)"
    if duty_voltage is not None:
        source += f", in command x vbat / {duty_voltage:.4g} V"
    return params.replace(motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array(ends),
                                             source, duty_voltage=duty_voltage))


def _static_lines(flights: list[FlightStates]) -> list[tuple[float, float]] | None:
    """Per rotor, the static map (slope, intercept) from ``flights``' commands (whatever
    their unit) to their rotor speeds (rad/s), as :func:`fit_motor_map` states it: on
    :data:`MAP_WINDOW_S` window means through the rotors' timing (:func:`map_lag`), the
    line ``a + k command`` where the commands span :data:`MAP_MIN_RANGE` of their mean and
    the data support it (:func:`_line_supported`), else the gain through the origin
    ``k command`` (intercept 0). None without a flight logging both, or where a rotor's
    commands or speeds do not vary at all."""
    means = _window_means(flights)
    if means is None:
        return None
    command, speed, windows, origin = means
    lines = []
    for i in range(speed.shape[1]):
        c, w, o = command[:, i], speed[:, i], origin[:, i]
        if np.ptp(c) <= 0 or np.ptp(o) <= 0:
            return None
        slope, intercept = float(o @ w / (o @ o)), 0.0
        if np.ptp(c) >= MAP_MIN_RANGE * np.mean(np.abs(c)):
            line = np.polyfit(c, w, 1)
            if _line_supported(c, w, (slope, intercept), line, windows, origin=o):
                slope, intercept = line
        lines.append((float(slope), float(intercept)))
    return lines


def fit_set_map(flights: list[FlightStates], params: VehicleParams, *,
                duty_voltage: float | None = None) -> VehicleParams:
    """``params`` with its own motor map corrected per rotor by a gain and an offset fitted
    on ``flights``: the map in the set's own shape, so that what the set declares (a curved
    table, a battery-voltage law) is not read as an effect. ``params`` without a map: as
    :func:`fit_motor_map`.

    The model: the speed the set's map gives for each logged command at its logged battery
    voltage, ``x = MotorMap.speed_at(command, vbat)`` (rad/s; the map's table and voltage
    law, the one law ``quadsim.fly`` logs through), then per rotor ``speed = a + k x``
    fitted by :func:`_static_lines` on ``x`` in place of the command (the same window
    means, timing, range rule and information criterion as :func:`fit_motor_map`'s line in
    the command). The result is a map in unit ``"1"`` over the set's table normalised (so a
    PWM table is read exactly as the set's map reads it, :meth:`MotorMap.to_unit`), its
    speeds ``a + k table`` and the set's voltage law kept: ``speed_at`` gives
    ``(a + k table(u)) (1 + g (v - v_ref))``, which differs from ``a + k x`` by
    ``a g (v - v_ref)``: with the offset a fraction of the speed and the law's factor within
    a few per cent of 1 (crazyflie21: 0.249 1/V over a 0.15 V sag, 3.7 %), a fraction of
    the rotor channel's noise. A set whose map fits its flights gives k 1 and a 0 (to
    round-off on exact flights), a real sag beyond the set's law remains in the speeds.

    ``duty_voltage`` (V; None: not used): for a set whose map declares no voltage law, the
    map is read in command x vbat / ``duty_voltage`` (:func:`fit_motor_map`'s reason: a
    DC motor's speed follows duty x voltage; the held-out diagnosis passes it where the
    flights were flown at different charges); ignored where the set declares a law (the
    set's law reads the charge). A table whose speed falls along it is kept as it is."""
    mm = params.motor_map
    if mm is None:
        return fit_motor_map(flights, params, duty_voltage=duty_voltage)
    law = mm.reference_voltage is not None and mm.voltage_gain != 0.0
    duty = mm.duty_voltage if law or duty_voltage is None else duty_voltage
    if duty is not None and any(f.command is not None and f.vbat is None for f in flights):
        raise ValueError("fit_set_map: duty_voltage needs every flight's vbat")
    base = MotorMap("1", mm.normalised(np.asarray(mm.command, float)),
                    np.asarray(mm.speed, float), mm.source, mm.reference_voltage,
                    mm.voltage_gain, 0.0, duty)
    through = [f if f.command is None else dataclasses.replace(
        f, command=base.speed_at(f.command, None if f.vbat is None
                                 else np.asarray(f.vbat, float)))
        for f in flights]
    lines = _static_lines(through)
    if lines is None:
        return params
    speed = np.array([intercept + slope * row
                      for (slope, intercept), row in zip(lines, base.speed)])
    source = (f"the parameter set's map ({mm.source}) with a per-rotor gain and offset "
              "fitted on the training flights (quadsim.gap)")
    if duty is not None and not law:
        source += f", in command x vbat / {duty:.4g} V"
    return params.replace(motor_map=dataclasses.replace(base, speed=speed, source=source))


def fit_command_map(flights: list[FlightStates], params: VehicleParams, *,
                    duty_voltage: float | None = None) -> VehicleParams:
    """``params`` with the static command -> speed map fitted on ``flights`` in the form they
    show: where the set has a motor map, its own map with a per-rotor gain and offset
    (:func:`fit_set_map`) unless the straight line per rotor in the command
    (:func:`fit_motor_map`, a gain through the origin where the commands span too narrow a
    range) fits them better beyond chance; without a map the line. ``duty_voltage``: passed
    to both, as they read it. Where one form has nothing to fit (no flight logging
    commands and speeds, or commands the set's table reads as one speed), the other.

    Which: the line where its steady speeds (:func:`command_speed`) leave a sum of squares
    against the logged rotor speeds, both averaged over :data:`MAP_WINDOW_S` (moving mean
    per flight, as the maps are fitted; :func:`map_misfit`), smaller than the set's form's
    by more than chance allows (:func:`_form_ratio`: an F test at :data:`FORM_LEVEL`),
    else the set's form. Why both: a vehicle flown through the set's own map (a
    Crazyflie's firmware PWM table and battery law, ``quadsim.fly``'s commands) bends away
    from a line, and the bend left on the rotor channel, or the set's voltage law read as a
    line in the command alone, reads as an effect where nothing changed; a
    speed-controlled motor (an ESC holding the commanded speed, most simulators) is a line
    that the set's curved table would bend, and the bend reads as an effect instead
    (measured: CHANGELOG.md, "The held-out command map in the form the training flights
    show")."""
    line = fit_motor_map(flights, params, duty_voltage=duty_voltage)
    if params.motor_map is None:
        return line
    shaped = fit_set_map(flights, params, duty_voltage=duty_voltage)
    if shaped is params or line is params:       # one form has nothing to fit: the other
        return line if shaped is params else shaped
    # rad^2/s^2 over rad^2/s^2; the floor only keeps an exact line (misfit 0) from dividing
    # by zero: any misfit of the set's form is then beyond chance
    ratio = map_misfit(flights, shaped) / max(map_misfit(flights, line), 1e-300)
    return line if ratio > _form_ratio(flights) else shaped


#: the one-sided level (probability, dimensionless) at which the training flights must
#: prefer the line to the set's form (:func:`fit_command_map`, :func:`_form_ratio`): the
#: conventional 95 %, the set's declared form kept unless the data reject it
FORM_LEVEL = 0.95


def _form_ratio(flights: list[FlightStates]) -> float:
    """The misfit ratio (set's form over line) beyond which the line replaces the set's form:
    the F distribution's :data:`FORM_LEVEL` quantile with the flights' independent window
    means as both degrees of freedom (each flight's duration over :data:`MAP_WINDOW_S`,
    times its rotors; both forms fit a gain and an offset per rotor). Why a test, not the
    smaller misfit: the set declares its form, and held out the training flights carry the
    change to be read; a battery's sag leaves about as much misfit on either form, and a
    near tie must not hand the sag to a line that reads part of it away (measured: the
    same CHANGELOG.md entry). The 95 % level: the usual one-sided test size; the F
    quantile assumes the window means' errors independent and alike on both forms."""
    from scipy.stats import f as f_dist

    dof = 0.0
    for f in flights:
        if f.command is None or f.rotor_speed is None or len(f.t) < 2:
            continue
        dof += (float(f.t[-1] - f.t[0]) / MAP_WINDOW_S) * f.rotor_speed.shape[1]
    return float(f_dist.ppf(FORM_LEVEL, max(dof, 1.0), max(dof, 1.0)))


def map_misfit(flights: list[FlightStates], params: VehicleParams) -> float:
    """Sum of squares (rad^2/s^2) of ``params``' steady rotor speeds (:func:`command_speed`)
    against the logged ones, both as :data:`MAP_WINDOW_S` moving means per flight (edges
    dropped, :func:`_moving_mean`), over every flight logging commands and speeds (0.0 for
    none)."""
    total = 0.0
    for f in flights:
        if f.command is None or f.rotor_speed is None or len(f.t) < 2:
            continue
        dt = float(np.median(np.diff(f.t)))
        error = _moving_mean(command_speed(f, params) - f.rotor_speed, dt)
        total += float(np.sum(error * error))
    return total


def proportional_rotors(params: VehicleParams) -> tuple[bool, ...]:
    """Per rotor, whether ``params``' motor map is a gain through the origin
    (``speed = k command``: a two-point map in unit "1" from command 0 at speed 0, as
    :func:`fit_motor_map` writes where the references' commands do not determine a line);
    () without a map. Its slope at the references' level is then an assumption (an ideal
    motor and ESC), which the discrepancy term carries
    (:func:`quadsim.gap.reference.fit_discrepancy`)."""
    mm = params.motor_map
    if mm is None or mm.command_unit != "1":
        return ()
    command, speed = np.asarray(mm.command, float), np.asarray(mm.speed, float)
    if command.shape != (2,) or command[0] != 0.0 or speed.ndim != 2:
        return ()
    return tuple(bool(row[0] == 0.0) for row in speed)


#: window (s) of the moving mean on which the static motor map is fitted.
MAP_WINDOW_S = 0.5
#: relative range of the (averaged) commands below which the map is a proportional gain.
MAP_MIN_RANGE = 0.05


def load_exponent(flights: list[FlightStates], params: VehicleParams
                  ) -> tuple[float, float] | None:
    """How much faster a motor spins per command when its propeller's load torque falls, as
    the references' own command -> speed map says: (alpha, its spread) with a command giving
    (1 + change)^-alpha of its speed for a propeller whose thrust and drag torque per Omega^2
    change by ``change`` (:mod:`quadsim.effects.thrust_factor`); None where the commands span
    less than :data:`MAP_MIN_RANGE` of their mean (the slope is noise there).

    Physics: a motor driven by a duty cycle u at voltage V turns where
    ``u V = k Omega + (R d / k) Omega^2`` (back EMF and the resistive drop of the load
    torque d Omega^2). At a fixed command a load change d (1 + c) moves the speed by
    ``dln Omega / dc = -s / (1 + s)``, s = R d Omega / k^2 the load's share, and the map's
    elasticity is ``eps = dln Omega / dln u = (1 + s) / (1 + 2 s)``; so
    ``alpha = 1 / eps - 1``. A straight line ``Omega = a + k_u u`` through the hover speed
    h has eps = (h - a) / h there: ``alpha = a / (h - a)``. A speed-controlled motor (an ESC
    holding the commanded speed, most simulators) has a map through the origin: alpha 0.
    Per rotor, the line over the windows' means (:data:`MAP_WINDOW_S`, as the map) with its
    intercept's standard error (samples counted one per window); alpha's spread is that
    error (delta method) and the rotors' own spread, added in squares.

    The textbook DC motor at 75 % voltage efficiency is 0.2, the prior where this returns
    None. What it reads on each benchmark source and on real flights: CHANGELOG.md:
    Docstrings as contracts."""
    from ..vehicle.params import hover_speed

    means = _window_means(flights)
    if means is None:
        return None
    command, speed, windows, _ = means
    windows = max(3.0, windows)
    hover = hover_speed(params)
    alpha, var = [], []
    for i in range(speed.shape[1]):
        c, w = command[:, i], speed[:, i]
        if np.ptp(c) < MAP_MIN_RANGE * np.mean(np.abs(c)) or len(c) < 3:
            return None
        slope, intercept = np.polyfit(c, w, 1)
        rss = float(np.sum((w - slope * c - intercept) ** 2))
        sxx = float(np.sum((c - c.mean()) ** 2))
        # the intercept's standard error, samples counted one per window
        se = np.sqrt(rss / (len(c) - 2) * (1 / len(c) + c.mean() ** 2 / sxx)
                     * len(c) / windows)
        if not hover > intercept:
            return None
        alpha.append(intercept / (hover - intercept))
        var.append((hover * se / (hover - intercept) ** 2) ** 2)
    alpha = np.asarray(alpha)
    spread = float(np.sqrt(np.mean(var) + (np.var(alpha, ddof=1) if len(alpha) > 1 else 0.0)))
    return float(alpha.mean()), spread


#: :func:`_window_means`' last inputs (the flights' t, command and rotor-speed arrays, held)
#: and result, as one tuple read and replaced whole (no call can pair one call's inputs with
#: another's result): a caller that reads the same flights' window means again gets them
#: without the timing search (:func:`map_lag`)
_LAST_MEANS: list = [None]


def _window_means(flights: list[FlightStates]) -> tuple | None:
    """The flights' commands, passed through the rotors' timing (:func:`map_lag`), and rotor
    speeds averaged over :data:`MAP_WINDOW_S` (moving mean, per flight, edges dropped;
    (M, R) each, pooled): (the commands through the line's timing, the speeds, how many
    windows they span, the commands through the gain's timing); None without a flight
    logging both. The last call's answer is kept and given again (the same arrays, not to
    be written to) while the flights hold the same t, command and rotor-speed arrays."""
    arrays = tuple((f.t, f.command, f.rotor_speed) for f in flights)
    last = _LAST_MEANS[0]
    if last is not None and len(last[0]) == len(arrays) and all(
            a is b for old, new in zip(last[0], arrays) for a, b in zip(old, new)):
        return last[1]
    value = _computed_window_means(flights)
    _LAST_MEANS[0] = (arrays, value)
    return value


def _computed_window_means(flights: list[FlightStates]) -> tuple | None:
    """:func:`_window_means` computed."""
    usable = [f for f in flights if f.command is not None and f.rotor_speed is not None]
    if not usable:
        return None
    dt = [float(np.median(np.diff(f.t))) if len(f.t) > 1 else 1.0 for f in usable]
    speed = np.concatenate([_moving_mean(f.rotor_speed, w) for f, w in zip(usable, dt)])
    (_, command), (_, origin) = map_lag(usable, dt, speed)
    windows = sum((f.t[-1] - f.t[0]) / MAP_WINDOW_S for f in usable if len(f.t) > 1)
    return command, speed, float(windows), origin


#: relative range (of the largest size) below which a rotor's window-mean commands count
#: as not varying (:func:`map_lag`, :func:`flat_command`). The window means of a constant
#: command, or of a manoeuvre whose period divides :data:`MAP_WINDOW_S` (a 2 Hz sine),
#: differ by round-off alone (measured 6e-15-2e-13 of their size on tests/test_gap.py's
#: flights): a straight line through them is rank-deficient (numpy's ``polyfit`` cut-off is
#: len x eps of the scaled columns, 4e-13 at 2000 samples, 1.3e-10 at 600 000) and its
#: slope is round-off. A logged command that varies does so by at least its quantum
#: (1/65535 of full scale on a 16-bit PWM: 1.5e-5), four decades above.
FLAT_COMMAND = 1e-9


def flat_command(c: np.ndarray) -> bool:
    """Whether the window-mean commands ``c`` (M,) of one rotor do not vary: their range at
    most :data:`FLAT_COMMAND` of their largest size (all zero included)."""
    c = np.asarray(c, float)
    return bool(np.ptp(c) <= FLAT_COMMAND * np.max(np.abs(c))) if c.size else True


#: the lags (s) :func:`map_lag` tries: 0 to 0.2 s (motor time constants plus the rotor
#: log's delay: 7-60 ms on the sources benchmarked, benchmarks/README.md) in steps of 5 ms,
#: a twelfth of the slowest: the slope's error from a lag off by half a step is below 0.1 %
MAP_LAGS_S = np.arange(0.0, 0.2001, 0.005)


def _through(flight, timing: tuple[str, float], dt: float) -> np.ndarray:
    """A flight's commands (N, R) through ``timing`` (:func:`map_lag`): ``("lag", tau)`` a
    first-order lag (:func:`quadsim.core.lag.first_order_lag`), ``("delay", d)`` a delay of
    d seconds (linear interpolation, held at the first sample before it)."""
    kind, value = timing
    if kind == "lag" or value <= 0:
        return first_order_lag(flight.command, value, dt)
    t = np.arange(len(flight.command)) * dt
    return np.stack([np.interp(t - value, t, c) for c in np.asarray(flight.command, float).T],
                    axis=1)


def map_lag(flights: list, dt: list[float], speed: np.ndarray) -> tuple[tuple, tuple]:
    """The timing between the commands and the rotor speeds of ``flights`` (each logging
    both; ``dt`` their sample steps, s; ``speed`` (M, R) their speeds' window means,
    :func:`_window_means`) that the static map fits best, for each map form: ((the line's
    timing, its commands' window means (M, R)), (the gain through the origin's timing, its
    commands' window means)). A timing is ``("lag", tau)`` or ``("delay", d)`` (s, each one
    of :data:`MAP_LAGS_S`, :func:`_through`); best: the least residual sum of squares, over
    the rotors, of the form fitted from the window means of the command through it to those
    of the speed. Why through a timing: window means of a command that moves within the
    window and of a speed that follows it late differ by the timing's attenuation
    (1 / sqrt(1 + (2 pi f tau)^2) for a lag), so on the raw command the slope shrinks and the
    line takes a false intercept (benchmarks/README.md, drone-models). Why both timing forms
    and a timing per map form: a lag taken for a delayed speed leaves a slope error the
    line's intercept takes up, and :func:`_line_supported` compares the forms with the same
    freedom only when each has its own best timing. A rotor whose command does not vary
    (:func:`flat_command`: its window means equal to round-off, where a line through them is
    rank-deficient): no timing is read (``("lag", 0.0)`` for both, the raw command's means)."""
    def means(timing):
        return np.concatenate([_moving_mean(_through(f, timing, w), w)
                               for f, w in zip(flights, dt)])

    raw = means(("lag", 0.0))
    best = {"line": (("lag", 0.0), raw, np.inf), "gain": (("lag", 0.0), raw, np.inf)}
    for timing in [("lag", float(v)) for v in MAP_LAGS_S] \
            + [("delay", float(v)) for v in MAP_LAGS_S[1:]]:
        command = raw if timing == ("lag", 0.0) else means(timing)
        if any(flat_command(command[:, i]) for i in range(speed.shape[1])):
            return (("lag", 0.0), raw), (("lag", 0.0), raw)
        rss = {"line": line_rss(command, speed),
               "gain": float(np.sum((speed - np.einsum("ij,ij->j", command, speed)
                                     / np.einsum("ij,ij->j", command, command) * command) ** 2))}
        for form, value in rss.items():
            if value < best[form][2]:
                best[form] = (timing, command, value)
    return best["line"][:2], best["gain"][:2]


def line_rss(x: np.ndarray, y: np.ndarray) -> float:
    """Residual sum of squares of the least-squares lines ``y[:, i] = a_i + b_i x[:, i]``
    (x, y (M, R); each column its own line), summed over the columns: the residuals
    ``y - ybar - b (x - xbar)`` with ``b = Sxy / Sxx`` about the columns' means, formed and
    squared (no difference of large sums). The same line as ``np.polyfit(x, y, 1)``, its
    sum of squares equal to polyfit's to rounding (the closed form instead of an SVD per
    column). A column whose x does not vary gives ``y``'s own sum of squares about its mean."""
    dx = x - x.mean(axis=0)
    dy = y - y.mean(axis=0)
    sxx = np.einsum("ij,ij->j", dx, dx)
    slope = np.divide(np.einsum("ij,ij->j", dx, dy), sxx, out=np.zeros_like(sxx),
                      where=sxx > 0)
    r = dy - slope * dx
    return float(np.sum(r * r))


def _line_supported(c: np.ndarray, w: np.ndarray, gain: tuple, line, windows: float, *,
                    origin: np.ndarray | None = None) -> bool:
    """Whether the straight line beats the gain through the origin by the Bayesian
    information criterion (one parameter more): ``n ln(RSS_gain / RSS_line) > ln n``, with
    n the number of independent samples, one per :data:`MAP_WINDOW_S` window of the
    flights (``windows``: the moving mean makes the samples within a window nearly one).
    ``c``: the commands the line is fitted on, ``origin`` those the gain is (each through
    its own timing, :func:`map_lag`; None: ``c``)."""
    n = max(float(windows), 2.0)
    o = c if origin is None else origin
    rss_gain = float(np.sum((w - gain[0] * o - gain[1]) ** 2))
    rss_line = float(np.sum((w - np.polyval(line, c)) ** 2))
    if rss_line <= 0.0:
        return rss_gain > 0.0
    return n * np.log(max(rss_gain, 1e-300) / rss_line) > np.log(n)


def _moving_mean(x: np.ndarray, dt: float) -> np.ndarray:
    """(N, C) moving mean over MAP_WINDOW_S ('valid' part; the signal itself when shorter)."""
    n = max(1, int(round(MAP_WINDOW_S / dt)))
    if len(x) <= n:
        return x
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    return (c[n:] - c[:-n]) / n


def command_speed(states: FlightStates, params: VehicleParams) -> np.ndarray | None:
    """Commanded rotor speed (N, R) rad/s from the normalised commands ``states.command``
    (0-1): the parameter set's motor map at the logged battery voltage,
    ``MotorMap.speed_at(command, vbat)`` (its one law, the one :func:`command_of_speed`
    inverts and ``quadsim.fly`` logs through): the map's table, times the voltage law
    ``1 + voltage_gain (vbat - reference_voltage)`` where the set declares one, and a map in
    command x voltage (``duty_voltage``) read at ``command vbat / duty_voltage``. Without a
    voltage log (``states.vbat`` None) the map as stated (the flight taken at the map's
    reference voltage, or at ``duty_voltage``); without a map ``command * max_speed``.
    None without commands."""
    if states.command is None:
        return None
    mm = params.motor_map
    if mm is None:
        return speed_of_command(params, states.command)
    vbat = None if states.vbat is None else np.asarray(states.vbat, float)
    return mm.speed_at(_map_units(params, states.command), vbat)


def _map_units(params: VehicleParams, command: np.ndarray) -> np.ndarray:
    """Normalised 0-1 command -> the motor map's own command unit (0-1 spans its table)."""
    return params.motor_map.to_unit(command)


def speed_of_command(params: VehicleParams, command: np.ndarray) -> np.ndarray:
    """Steady rotor speed (rad/s) of normalised commands (..., R): the motor map (a map in
    other units, e.g. PWM, is spanned by 0-1 over its table), else ``command * max_speed``."""
    if params.motor_map is not None:
        return params.motor_map.speed_of(_map_units(params, command))
    return command * params.max_speed


def command_of_speed(params: VehicleParams, speed: np.ndarray,
                     vbat: np.ndarray | None = None) -> np.ndarray:
    """Inverse of :func:`speed_of_command` (N, R) (monotone part of the map): normalised
    commands from speeds (rad/s). ``vbat`` (N,) (V): the battery voltages the speeds are
    reached at, read through the map's voltage law (``MotorMap.command_at``, the inverse
    of ``MotorMap.speed_at``); None: the map as stated (at its reference voltage)."""
    if params.motor_map is None:
        return speed / params.max_speed
    mm = params.motor_map
    return mm.normalised(mm.command_at(speed, vbat))


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
    return _heun_sum(gain * start, [weights[k] * cmd[k:k + n] for k in range(steps + 1)])


def _heun_sum(out: np.ndarray, terms) -> np.ndarray:
    """``out`` + terms[0] + terms[1] + ..., added in that order (:func:`heun_linear`'s sum:
    the terms w_k cmd_k do not depend on the measured speeds, so a fit that reads them at
    many delays keeps them, :attr:`RotorModel.terms`). ``out`` is written into."""
    for term in terms:
        np.add(out, term, out=out)
    return out


@dataclass(frozen=True)
class RotorModel:
    """What the rotor channel's prediction takes from the commands and the effects, not from
    the measured rotor speeds (:func:`rotor_residual`): ``steps`` samples ahead
    (:data:`ROTOR_HORIZON_S`), ``n`` predicted samples, ``cmd`` (N, R) the commanded speeds
    (rad/s) with the effects' command factor applied, ``owner`` the effect that defines the
    rotor dynamics (None: a command is reached at once), ``tau`` its time constant (s) where
    it is a lag the same up and down (:func:`heun_linear`), else None, ``dt`` the sample
    step (s) and ``valid`` (N - steps,) False where a prediction crosses a flight boundary
    (None: none does). A fit that reads the rotor speeds at many delays keeps one per
    command -> speed model (:func:`rotor_model`)."""

    steps: int
    n: int
    cmd: np.ndarray
    owner: object | None
    tau: float | None
    dt: float
    valid: np.ndarray | None

    @functools.cached_property
    def terms(self) -> tuple:
        """The command's terms w_k cmd[k:k+n] of :func:`heun_linear` (k = 0..steps, each
        (n, R) rad/s; read only), kept: the same products at every rotor delay. Only for a
        linear lag (``tau`` not None). (steps + 1) R values per sample (13 x 4 on a
        100 Hz fit; the 26 real mixed flights build at most 51 models each, ~11 MB)."""
        _, weights = _heun_weights(self.steps, self.dt / ROTOR_SUBSTEPS, self.tau)
        out = tuple(weights[k] * self.cmd[k:k + self.n] for k in range(self.steps + 1))
        for term in out:
            term.flags.writeable = False
        return out


def rotor_model(states: FlightStates, params: VehicleParams, effects: list, *,
                memo: dict | None = None) -> RotorModel:
    """The :class:`RotorModel` of ``params``' motor map and ``effects`` on the commands and
    times of ``states``. ``memo``: a flight's (:func:`memoised`), where it is kept per
    command, time and battery arrays, ``params`` and the effects' rotor hooks
    (:func:`rotor_key`): the states read at another rotor delay share those arrays."""
    if memo is None or states.command is None:
        return _rotor_model(states, params, effects, memo)
    arrays = (states.t, states.command, states.vbat, params)
    key = ("rotor_model",) + tuple(map(id, arrays)) + (
        effects_plan(effects).rotor(states.command.shape[1]),)
    return memoised(memo, key, arrays, lambda: _rotor_model(states, params, effects, memo))


def _rotor_model(states: FlightStates, params: VehicleParams, effects: list,
                 memo: dict | None) -> RotorModel:
    dt = float(states.t[1] - states.t[0]) if len(states.t) > 1 else 1.0
    steps = max(1, round(ROTOR_HORIZON_S / dt))

    def scaled():
        # Effects upstream of the speed (battery voltage) scale the speed a command gives;
        # it is static (a battery changes the steady speed, not how fast the rotor gets
        # there): only a dynamics effect (motor_lag) makes the rotor follow with a lag.
        factor = EffectSet(tuple(effects)).command_factor(states.t, states.vbat,
                                                          cmd.shape[1])
        return cmd if factor is None else cmd * factor

    if memo is None or states.command is None:
        cmd = command_speed(states, params)
        cmd = scaled()
        owner = rate_owner(effects)
    else:
        arrays = (states.command, states.vbat, params)
        cmd = memoised(memo, ("command_speed", id(states.command), id(states.vbat), id(params)),
                       arrays, lambda: command_speed(states, params))
        plan = effects_plan(effects)
        # the same for every rotor timing and lag: kept per command, battery and factors
        cmd = memoised(memo, ("scaled_command", id(states.t), id(states.command),
                              id(states.vbat), id(params), plan.factor),
                       (states.t,) + arrays, scaled)
        owner = plan.owner
    n = len(states.t) - steps
    valid = np.abs(states.t[steps:] - states.t[:n] - steps * dt) < 0.5 * dt
    return RotorModel(steps, n, cmd, owner, _linear_time_constant(owner), dt,
                      None if valid.all() else valid)


def rotor_residual(states: FlightStates, params: VehicleParams, effects: list, *,
                   memo: dict | None = None) -> np.ndarray:
    """Measured rotor speed at t + h minus the model's prediction from the state at t.
    ``memo``: a flight's (:func:`memoised`), where the commanded speeds of ``params``' motor
    map and the :class:`RotorModel` are kept (the same for every rotor delay of one flight)."""
    model = rotor_model(states, params, effects, memo=memo)
    steps, n, cmd, owner, dt = model.steps, model.n, model.cmd, model.owner, model.dt
    speed = states.rotor_speed
    if owner is None:
        predicted = cmd[steps:]
    elif model.tau is not None:
        # heun_linear with the command's terms kept (the same numbers, in the same order)
        gain, _ = _heun_weights(steps, dt / ROTOR_SUBSTEPS, model.tau)
        predicted = _heun_sum(gain * speed[:n], model.terms)
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
    if model.valid is not None:
        out[steps:][~model.valid] = 0.0
    return out
