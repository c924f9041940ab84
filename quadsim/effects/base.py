"""The one interface every unmodelled effect implements, and how effects are combined.

An effect can act in four places; it implements the hooks it needs and inherits the
neutral default for the rest (see :class:`EffectBase`):

1. ``apply_to_params(params) -> params`` — static changes of the vehicle (extra mass, CoM
   offset, inertia error). Engines build their model from the returned set.
2. ``rotor_speed_rate(t, commanded, actual) -> dOmega/dt`` (B, R) or ``None`` — rotor-speed
   dynamics (motor lag). ``None`` means the rotor follows its command at once.
3. ``air_velocity(t, position) -> (B, 3)`` or ``None`` — world-frame wind velocity (m/s);
   the engine subtracts it from the vehicle velocity to give the relative air velocity in the
   :class:`EffectContext` that drag effects read.
4. ``loads(ctx) -> EffectLoads`` — per-rotor thrust scale / offset, and an external force
   (world frame, at the CoM) and torque (body frame).
5. ``speed_factor(t, vbat=None) -> (B,)`` or ``None`` — the steady rotor speed a command gives,
   relative to nominal (battery voltage). It multiplies the commanded speed before the
   rotor-speed dynamics; without a dynamics effect the rotor follows the scaled command with
   the fast first-order response :data:`SPEED_RESPONSE_S`. ``rotor_speed_factor(rotors) ->
   (R,)`` or ``None``: the same per rotor and constant (one propeller's load on its DC
   motor); :meth:`EffectSet.command_factor` is the product of both.
6. Internal state (optional, e.g. a swinging payload): ``state_size() -> S`` (0 = none),
   ``initial_state(params, vehicle) -> (B, S)`` from the vehicle's initial snapshot (dict of
   (B, ...) arrays ``position, velocity, quat, body_rate``), and ``state_rate(ctx) -> (B, S)``.
   The engines integrate the state with the vehicle (the analytic engine inside its ODE, the
   MuJoCo runner by RK4 over each timestep) and hand each effect its own slice as
   ``ctx.effect_state`` in ``loads`` and ``state_rate``. Effects with state cannot be fitted
   from a residual wrench alone (the state is not logged); fast engine paths may refuse them.

Both engines (analytic and MuJoCo) call the same hooks on the same numbers each step and
apply the result with the same :func:`quadsim.vehicle.rotors` geometry, so an effect acts
identically in both by construction; a test per effect checks it.

All arrays carry a leading batch axis B (B simulations advanced in one Python call).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from ..core.frames import quat_to_rotmat
from ..vehicle.params import VehicleParams
from .facts import EffectFacts

#: time constant (s) with which a rotor follows a command scaled by ``speed_factor`` when no
#: effect defines rotor dynamics (fast against flight dynamics, slow enough for the engines'
#: fixed-step rotor integration at 1 ms).
SPEED_RESPONSE_S = 0.005
#: the most rotors an effect's per-rotor parameters address (thrust_mismatch's rotor_1..8)
MAX_ROTORS = 8


def _rotor_factor(effect, rotors: int):
    hook = getattr(effect, "rotor_speed_factor", None)
    return hook(rotors) if hook is not None else None


@dataclass(frozen=True)
class EffectParameter:
    """Declares one named parameter of an effect: unit, the value that switches the effect
    off, plausible bounds for fitting, and a one-line meaning."""

    name: str
    unit: str
    off: float
    lower: float
    upper: float
    doc: str


@dataclass(frozen=True)
class EffectContext:
    """What an effect may read at one instant, for B simulations.

    position, velocity: world, body origin (B, 3); quat (B, 4) wxyz body-to-world;
    body_rate (B, 3) rad/s; air_velocity (B, 3): vehicle velocity minus wind, world (m/s);
    rotor_speed (B, R) actual (rad/s); rotor_accel (B, R) (rad/s^2); t (B,) (s);
    params: the (possibly modified) vehicle; vbat (B,) battery voltage (V) or NaN;
    effect_state (B, S): the internal state of the effect being evaluated (None without).
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    body_rate: np.ndarray
    air_velocity: np.ndarray
    rotor_speed: np.ndarray
    rotor_accel: np.ndarray
    params: VehicleParams
    vbat: np.ndarray | None = None
    effect_state: np.ndarray | None = None
    #: ``quat_to_rotmat(quat)`` (B, 3, 3) when the caller has it already (the gap fits keep it
    #: per flight); None: computed on first use and kept for this instant
    rotation: np.ndarray | None = None
    #: values that depend only on the logged motion (t, position, velocity, quat,
    #: body_rate), kept across the many model evaluations of one flight by a caller that
    #: evaluates many models on the same samples (the gap fits); None: nothing is kept
    flight_memo: dict | None = None
    #: the vehicle's acceleration (B, 3, world, m/s^2) where the caller knows it but not the
    #: velocity (a log with the IMU and the attitude and no position: the accelerometer
    #: turned to the world, :func:`quadsim.gap.logcheck.posefree_states`); None: an effect
    #: that needs it differentiates ``velocity``
    accel_world: np.ndarray | None = None

    def rotmat(self) -> np.ndarray:
        """Body-to-world rotation matrices (B, 3, 3) of ``quat``, computed once."""
        if self.rotation is None:
            object.__setattr__(self, "rotation", quat_to_rotmat(self.quat))
        return self.rotation

    def to_world(self, v: np.ndarray) -> np.ndarray:
        """Body-frame vectors (B, 3) into the world frame (:func:`quadsim.core.frames.rotate`):
        ``R v`` per sample (:meth:`rotmat`), a stacked matrix product."""
        return np.matmul(self.rotmat(), np.asarray(v)[..., None])[..., 0]

    def to_body(self, v: np.ndarray) -> np.ndarray:
        """World-frame vectors (B, 3) into the body frame
        (:func:`quadsim.core.frames.rotate_inverse`): ``Rᵀ v`` per sample, ``v`` as a row
        times ``R`` (a stacked matrix product, as :meth:`to_world`)."""
        return np.matmul(np.asarray(v)[..., None, :], self.rotmat())[..., 0, :]


@dataclass
class EffectLoads:
    """Contributions of effects at one instant (B simulations, R rotors).

    thrust_scale (B, R): multiplies each rotor's thrust *and* drag torque (1 = nominal), and
    its curve offset.
    thrust_offset (B, R): added thrust along each rotor axis (N), no torque change.
    force_world (B, 3): external force at the CoM, world frame (N).
    torque_body (B, 3): external torque, body frame (N m).
    curve_offset (B, R): thrust along each rotor axis (N) that belongs to the propeller's
    thrust curve (a thrust curve's linear and constant terms): scaled by ``thrust_scale``
    like ``b Omega^2``, since a propeller that gives (1 + e) times the thrust at every speed
    scales its whole curve (a thrust stand's fit c0 + c1 a + c2 a^2 of another propeller
    batch scales every coefficient). No torque change.

    The thrust the rotors' offsets add along their axes is :attr:`rotor_offset`:
    ``thrust_offset + thrust_scale * curve_offset``.
    """

    thrust_scale: np.ndarray
    thrust_offset: np.ndarray
    force_world: np.ndarray
    torque_body: np.ndarray
    curve_offset: np.ndarray | None = None

    def __post_init__(self):
        if self.curve_offset is None:
            self.curve_offset = np.zeros_like(self.thrust_offset)

    @classmethod
    def neutral(cls, batch: int, rotors: int) -> EffectLoads:
        """Loads that change nothing: scale one, offsets and external loads zero. Their
        arrays are shared and read-only (an effect sets a field to a new array, never writes
        into the neutral one), so that :meth:`combine` can pass over the fields an effect
        left neutral."""
        ones, zeros, zeros3 = _blank(int(batch), int(rotors))
        loads = cls.__new__(cls)            # the fields set as __init__ would, without its
        loads.thrust_scale, loads.thrust_offset = ones, zeros   # check of curve_offset
        loads.force_world, loads.torque_body, loads.curve_offset = zeros3, zeros3, zeros
        loads._blank = (ones, zeros, zeros3)
        return loads

    def add(self, other: EffectLoads) -> EffectLoads:
        """Combine: scales multiply, offsets and external loads add."""
        return EffectLoads(self.thrust_scale * other.thrust_scale,
                           self.thrust_offset + other.thrust_offset,
                           self.force_world + other.force_world,
                           self.torque_body + other.torque_body,
                           self.curve_offset + other.curve_offset)

    @classmethod
    def combine(cls, parts: list[EffectLoads], batch: int, rotors: int) -> EffectLoads:
        """``neutral(batch, rotors).add(parts[0]).add(parts[1])...`` without the products
        with one and the sums with zero of the fields a part left neutral (the same numbers:
        ``1 x`` and ``0 + x`` are ``x``, a zero's sign apart). A field that one part sets is
        that part's array, not a copy: the result is read, never written into."""
        blank = _blank(int(batch), int(rotors))

        def fold(name, neutral, op):
            total = None
            for part in parts:
                value = getattr(part, name)
                if value is neutral:
                    continue
                total = value if total is None else op(total, value)
            return neutral if total is None else total

        ones, zeros, zeros3 = blank
        out = cls(fold("thrust_scale", ones, np.multiply),
                  fold("thrust_offset", zeros, np.add),
                  fold("force_world", zeros3, np.add),
                  fold("torque_body", zeros3, np.add),
                  fold("curve_offset", zeros, np.add))
        out._blank = blank
        return out

    def is_neutral(self, name: str) -> bool:
        """Whether field ``name`` is still the shared array of :meth:`neutral` (its value
        then is one for ``thrust_scale``, zero for the others)."""
        value = getattr(self, name)
        if type(value) is np.ndarray and value.flags.writeable:
            return False                    # the shared arrays are read-only
        blank = self.__dict__.get("_blank")     # those this instance was made with
        if blank is not None and value is blank[_BLANK_INDEX.get(name, 1)]:
            return True
        shape = np.shape(value)
        if value is None or len(shape) != 2:
            return False
        ones, zeros, zeros3 = _blank(shape[0], np.shape(self.thrust_scale)[1])
        return value is (ones if name == "thrust_scale" else
                         zeros3 if name in ("force_world", "torque_body") else zeros)

    @property
    def rotor_offset(self) -> np.ndarray:
        """Thrust (B, R) the offsets add along each rotor axis (N): the thrust offset and the
        curve offset scaled with the rotor's thrust."""
        if self.is_neutral("curve_offset"):
            return self.thrust_offset
        return self.thrust_offset + self.thrust_scale * self.curve_offset


#: the index in :func:`_blank`'s arrays of each field's neutral value (the rotor offsets:
#: zeros (B, R), index 1)
_BLANK_INDEX = {"thrust_scale": 0, "force_world": 2, "torque_body": 2}


@lru_cache(maxsize=64)
def _blank(batch: int, rotors: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read-only ones (B, R), zeros (B, R) and zeros (B, 3): the fields of
    :meth:`EffectLoads.neutral`, shared by every neutral load of that shape."""
    arrays = (np.ones((batch, rotors)), np.zeros((batch, rotors)), np.zeros((batch, 3)))
    for a in arrays:
        a.flags.writeable = False
    return arrays


@runtime_checkable
class Effect(Protocol):
    """An unmodelled physical effect (one module per effect in :mod:`quadsim.effects`)."""

    name: ClassVar[str]
    parameters: ClassVar[tuple[EffectParameter, ...]]

    def values(self) -> dict[str, float]: ...
    def apply_to_params(self, params: VehicleParams) -> VehicleParams: ...
    def rotor_speed_rate(self, t: np.ndarray, commanded: np.ndarray,
                         actual: np.ndarray) -> np.ndarray | None: ...
    def air_velocity(self, t: np.ndarray, position: np.ndarray) -> np.ndarray | None: ...
    def loads(self, ctx: EffectContext) -> EffectLoads | None: ...


_OFF: dict[type, tuple[tuple, dict[str, float]]] = {}


def _off_values(cls: type, parameters: tuple) -> dict[str, float]:
    """Parameter name -> its "off" value, in declaration order (kept per class while its
    ``parameters`` are the same tuple: an effect is constructed thousands of times per
    diagnosis)."""
    hit = _OFF.get(cls)
    if hit is None or hit[0] is not parameters:
        hit = _OFF[cls] = (parameters, {p.name: p.off for p in parameters})
    return hit[1]


class EffectBase:
    """Neutral defaults and keyword-checked construction for effects.

    Subclasses set ``name``, ``parameters``, their diagnosis ``facts``
    (:class:`~quadsim.effects.facts.EffectFacts`; the default: not fitted by the diagnosis)
    and override the hooks they need. Parameters are given as keywords; an unknown keyword
    raises (a typo must not silently do nothing)."""

    name: ClassVar[str] = ""
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    facts: ClassVar[EffectFacts] = EffectFacts()
    #: what ``loads`` reads besides the effect's own values and the logged motion (``t``,
    #: ``position``, ``velocity``, ``quat``, ``body_rate``, the rotation) and the shape
    #: (B, R) of ``rotor_speed``: (the :class:`EffectContext` fields among ``air_velocity``,
    #: ``rotor_speed``, ``rotor_accel``, ``vbat``; the :class:`VehicleParams` attributes of
    #: ``ctx.params``). None: anything. A caller that evaluates many models on one flight
    #: (:func:`quadsim.gap.residual.model_wrench`) keeps an effect's loads while these stay
    #: the same; tests/test_effects.py checks each declaration by moving everything else.
    loads_reads: ClassVar[tuple[tuple[str, ...], tuple[str, ...]] | None] = None

    def __init__(self, **values: float):
        known = _off_values(type(self), self.parameters)
        if not values.keys() <= known.keys():
            unknown = set(values) - set(known)
            raise TypeError(f"{self.name}: unknown parameter(s) {sorted(unknown)}; "
                            f"valid: {', '.join(known)}")
        self._values = {name: float(values.get(name, off)) for name, off in known.items()}
        self._given = frozenset(values)

    def given(self) -> frozenset[str]:
        """The parameters set when the effect was made (the others are at their off value;
        an effect unpickled from before this was kept counts every parameter as given)."""
        return self.__dict__.get("_given", frozenset(self._values))

    def __getattr__(self, item: str) -> float:
        values = self.__dict__.get("_values", {})
        if item in values:
            return values[item]
        raise AttributeError(item)

    def values(self) -> dict[str, float]:
        return dict(self._values)

    def is_off(self) -> bool:
        return all(self._values[p.name] == p.off for p in self.parameters)

    def apply_to_params(self, params: VehicleParams) -> VehicleParams:
        return params

    def rotor_speed_rate(self, t, commanded, actual):
        return None

    def air_velocity(self, t, position):
        return None

    def speed_factor(self, t, vbat=None):
        return None

    def rotor_speed_factor(self, rotors: int):
        return None

    def loads(self, ctx: EffectContext) -> EffectLoads | None:
        return None

    def state_size(self) -> int:
        """Number of internal states per simulation (0: the effect has none)."""
        return 0

    def initial_state(self, params: VehicleParams, vehicle: dict) -> np.ndarray:
        """(B, state_size) internal state at the start, from the vehicle snapshot."""
        return np.zeros((len(vehicle["position"]), 0))

    def state_rate(self, ctx: EffectContext) -> np.ndarray:
        """d/dt of ``ctx.effect_state`` (B, state_size)."""
        return np.zeros((len(ctx.t), 0))

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v:g}" for k, v in self._values.items())
        return f"{type(self).__name__}({inner})"


@dataclass
class EffectSet:
    """Several effects acting together, evaluated in a fixed order."""

    effects: tuple[Effect, ...] = field(default_factory=tuple)

    def apply_to_params(self, params: VehicleParams) -> VehicleParams:
        for effect in self.effects:
            params = effect.apply_to_params(params)
        return params

    def has_rotor_dynamics(self) -> bool:
        probe = np.zeros((1, 1))
        return any(e.rotor_speed_rate(np.zeros(1), probe, probe) is not None
                   for e in self.effects) or self.speed_factor(np.zeros(1)) is not None \
            or any(_rotor_factor(e, MAX_ROTORS) is not None for e in self.effects)

    def speed_factor(self, t, vbat=None):
        """Product of the effects' speed factors (B,), or None when none acts."""
        total = None
        for effect in self.effects:
            hook = getattr(effect, "speed_factor", None)
            f = hook(t, vbat) if hook is not None else None
            if f is not None:
                total = f if total is None else total * f
        return total

    def rotor_factor(self, rotors: int):
        """Product of the effects' per-rotor speed factors (R,), or None when none acts."""
        total = None
        for effect in self.effects:
            f = _rotor_factor(effect, rotors)
            if f is not None:
                total = f if total is None else total * f
        return total

    def command_factor(self, t, vbat=None, rotors: int = 1):
        """The factor (B, R) on the speed each rotor's command gives: :meth:`speed_factor`
        (B,) times :meth:`rotor_factor` (R,); None when neither acts."""
        uniform, per_rotor = self.speed_factor(t, vbat), self.rotor_factor(rotors)
        if uniform is None and per_rotor is None:
            return None
        n = len(np.atleast_1d(t))
        out = np.ones((n, rotors))
        if uniform is not None:
            out = out * np.asarray(uniform, dtype=float).reshape(-1, 1)
        if per_rotor is not None:
            out = out * np.asarray(per_rotor, dtype=float)[None, :]
        return out

    def rotor_speed_rate(self, t, commanded, actual, vbat=None):
        """dOmega/dt (B, R); the first effect that defines rotor dynamics owns it. Speed
        factors (battery, one propeller's load) scale the command first; with a factor but
        no dynamics effect the rotor follows with :data:`SPEED_RESPONSE_S`."""
        factor = self.command_factor(t, vbat, np.shape(commanded)[1])
        if factor is not None:
            commanded = np.asarray(commanded, dtype=float) * factor
        for effect in self.effects:
            rate = effect.rotor_speed_rate(t, commanded, actual)
            if rate is not None:
                return rate
        if factor is not None:
            return (commanded - np.asarray(actual, dtype=float)) / SPEED_RESPONSE_S
        return None

    def air_velocity(self, t, position) -> np.ndarray:
        wind = np.zeros_like(np.asarray(position, dtype=float))
        for effect in self.effects:
            w = effect.air_velocity(t, position)
            if w is not None:
                wind = wind + w
        return wind

    def _sized(self) -> list[tuple[Effect, int, int]]:
        """(effect, first state column, state count) for every effect, in order."""
        out, start = [], 0
        for effect in self.effects:
            size = effect.state_size() if hasattr(effect, "state_size") else 0
            out.append((effect, start, size))
            start += size
        return out

    def state_size(self) -> int:
        """Total internal states per simulation (the effects' slices, concatenated)."""
        return sum(size for _, _, size in self._sized())

    def initial_state(self, params: VehicleParams, vehicle: dict) -> np.ndarray:
        batch = len(vehicle["position"])
        parts = [effect.initial_state(params, vehicle).reshape(batch, size)
                 for effect, _, size in self._sized() if size]
        return np.concatenate(parts, axis=1) if parts else np.zeros((batch, 0))

    def _own(self, ctx: EffectContext, start: int, size: int) -> EffectContext:
        if ctx.effect_state is None or ctx.effect_state.shape[1] == 0:
            return ctx
        return replace(ctx, effect_state=ctx.effect_state[:, start:start + size])

    def state_rate(self, ctx: EffectContext) -> np.ndarray:
        batch = len(ctx.t)
        parts = [effect.state_rate(self._own(ctx, start, size)).reshape(batch, size)
                 for effect, start, size in self._sized() if size]
        return np.concatenate(parts, axis=1) if parts else np.zeros((batch, 0))

    def loads(self, ctx: EffectContext, kept=None) -> EffectLoads:
        """The effects' loads combined in order (:meth:`EffectLoads.add`). ``kept``: a
        callable ``(effect, compute) -> loads`` that may return an effect's loads kept from an
        earlier call on the same context instead of ``compute()`` (the gap fits evaluate many
        effect sets on one flight, :func:`quadsim.gap.residual.kept`); used for effects without
        internal state only."""
        parts = []
        for effect, start, size in self._sized():
            if not size and type(effect).loads is EffectBase.loads:
                continue                    # the neutral hook: no loads (a motor lag, a mass)
            if kept is not None and not size:
                part = kept(effect, lambda e=effect: e.loads(ctx))
            else:
                part = effect.loads(self._own(ctx, start, size) if size else ctx)
            if part is not None:
                parts.append(part)
        return EffectLoads.combine(parts, ctx.rotor_speed.shape[0], ctx.rotor_speed.shape[1])
