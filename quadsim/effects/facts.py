"""What the gap diagnosis knows about an effect, declared by the effect beside its parameters.

Every effect class carries ``facts: ClassVar[EffectFacts]`` (:class:`EffectFacts`): which of
its parameters a fit frees, how large each typically is for a given vehicle, the range real
vehicles show (with its source), the prior spread of a difference, the effects it must be
fitted with, whether it acts upstream of the measured rotor speed, its discrete variants,
what separates it from the effects it is confused with, and how a reading is worded. The
diagnosis (:mod:`quadsim.gap`) reads these through the registry
(``quadsim.effects.EFFECTS[name].facts``), never from tables keyed by effect names, so a new
effect is one module (plus its docs; ``docs/effects.md``, "Adding an effect").

All numbers are SI in the parameter's declared unit; a function of the vehicle takes a
:class:`~quadsim.vehicle.params.VehicleParams` and returns a float. A key ``"*"`` in a
per-parameter mapping stands for every parameter of the effect.

Example::

    >>> from quadsim.effects import EFFECTS, facts_of
    >>> EFFECTS["mass_offset"].facts.fitted          # ('mass',)
    >>> facts_of("body_drag.cd_area").words          # Words('C_d A sideways', 'cm^2', 10000.0)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from ..vehicle.params import VehicleParams
from .scales import (  # re-exported
    arm_length,
    hover_thrust_per_speed,
    momentum_rate_damping,
    momentum_translational_lift,
)

__all__ = ["ALL", "POSE_PARTS", "Companion", "EffectFacts", "ParameterFacts", "PlausibleRange",
           "Reading", "Scale", "Spread", "Together", "Window", "Words", "arm_length",
           "missing_facts", "number", "plus_minus", "range_unit", "without_pose"]

#: the key of a per-parameter mapping that applies to every parameter of the effect
ALL = "*"

#: the parts of the pose an effect may need (:attr:`EffectFacts.needs_pose`), each with the
#: flight-log columns that give it (:mod:`quadsim.logs.flightlog`)
POSE_PARTS = {"velocity": "vx..vz or x..z",
              "height": "z",
              "attitude": "qw..qz or roll, pitch, yaw"}


@dataclass(frozen=True)
class Scale:
    """The typical size of a fitted parameter (its unit): ``size(params)``; the fits step in
    units of it and call an interval narrower than 1e-6 of it absurd. ``reason``: one line."""

    size: Callable[[VehicleParams], float]
    reason: str


@dataclass(frozen=True)
class Window:
    """A fit window narrower than the parameter's declared bounds, for this vehicle:
    ``[max(lower, low(params)), min(upper, high(params))]``. ``reason``: one line."""

    low: Callable[[VehicleParams], float]
    high: Callable[[VehicleParams], float]
    reason: str


#: the kinds of a plausible range: the unit its ends are in (:func:`range_unit`)
RANGE_KINDS = ("relative", "absolute", "mass", "arm", "hover", "momentum", "lift")


@dataclass(frozen=True)
class PlausibleRange:
    """What real vehicles show: ``lower .. upper`` in units of ``kind`` (:func:`range_unit`:
    "relative" a fraction of 1, "absolute" the parameter's unit, "mass" of the vehicle's mass,
    "arm" of its arm, "hover" of the hover thrust per rad/s, "momentum" of the momentum-theory
    rate damping, "lift" of the momentum-theory translational lift), and its ``source``. A
    fit outside it is ``implausible`` (:mod:`quadsim.gap.fitting`)."""

    lower: float
    upper: float
    kind: str
    source: str


@dataclass(frozen=True)
class Spread:
    """The prior spread (the parameter's unit) of a difference from "off": ``size(params)``,
    or, with ``size`` None, half the larger end of the plausible range
    (:meth:`EffectFacts.spread_of`; that range is then about two spreads). ``reason``:
    one line (the source where the range does not give it)."""

    size: Callable[[VehicleParams], float] | None = None
    reason: str = "half the larger end of the plausible range"


@dataclass(frozen=True)
class Words:
    """How a reading of the parameter is shown: ``label``, the display ``unit`` and the
    ``scale`` from SI to it (shown = value x scale; 1e3 for grams from kg); ``phrase``: the
    reading as a physical statement, ``phrase(parameter, value, ci, params) -> str`` (``ci``
    the 95 % half-width, None or NaN where not known; :func:`plus_minus` writes the pair)."""

    label: str
    unit: str
    scale: float = 1.0
    phrase: Callable[[str, float, float | None, VehicleParams], str] | None = None


@dataclass(frozen=True)
class Together:
    """Parameters worded together (a canted rotor's two lean components as one lean and its
    direction): ``phrase(values, ci, params, fixed) -> str`` over the readings' dicts
    (``effect.parameter`` keys; ``fixed`` the values held fixed, e.g. the rotor index)."""

    parameters: tuple[str, ...]
    phrase: Callable[[dict, dict, VehicleParams, dict], str]


def number(x: float, digits: str, sign: str = "") -> str:
    """``x`` formatted with ``digits``; a value of 100 up to a million that this would write
    with an exponent ("1e+02") as a whole number instead ("100")."""
    text = f"{x:{sign}{digits}}"
    if "e" in text and 100 <= abs(x) < 1e6:
        text = f"{x:{sign}.0f}"
    return text


def plus_minus(value: float, ci: float | None, scale: float, digits: str = ".2g") -> str:
    """``value x scale`` signed, with `` ± |ci| x scale`` where ``ci`` is known (finite)."""
    if ci is None or not np.isfinite(ci):
        return number(value * scale, digits, "+")
    return f"{number(value * scale, digits, '+')} ± {number(abs(ci) * scale, digits)}"


@dataclass(frozen=True)
class Reading:
    """One way a single flight may differ by this effect: an explanation the per-flight
    evidence weighs (:func:`quadsim.gap.explanations.explanations_for`). ``fitted``: the
    parameters it frees, centred on "off" with the effect's prior spreads (``spreads``);
    ``variant``: its name beside the effect's; ``odds``: the readings of the effect sharing
    its prior odds (each gets 1 / odds); ``coupled``: a parameter acts only through another
    one's value (a payload's position through its mass), so it is fitted to convergence
    after the others; ``kin``: the effects whose readings it extends or mimics (a coupled
    reading is fitted where one of them can matter); ``per_rotor``: one reading per rotor k,
    "{}" in ``fitted`` and ``variant`` standing for k (the effect's ``one_per_rotor`` index
    fixed at k), the rotors sharing the effect's prior odds; ``rotor_speeds``: only where
    the references log rotor speeds (True), only where they do not (False), always (None);
    ``through``: (parameter, parent) pairs of a coupled reading, a parameter that acts only
    through its parent's value (none at the parent's "off" value 0): not identified while the
    data do not tell the parent from 0 (:func:`quadsim.gap.evidence.laplace`); ``fixed``:
    (parameter, value) pairs the reading holds at a value of its own instead of the
    parameter's default (one rotor's thrust change with the drag torque's share at 0): a
    *form* of the reading with the same ``fitted``; a per-rotor form has the prior of the
    effect's other per-rotor readings, not a share of it (it is not counted among them)."""

    fitted: tuple[str, ...]
    variant: str = ""
    odds: int = 1
    coupled: bool = False
    kin: tuple[str, ...] = ()
    per_rotor: bool = False
    rotor_speeds: bool | None = None
    through: tuple[tuple[str, str], ...] = ()
    fixed: tuple[tuple[str, float], ...] = ()


@dataclass(frozen=True)
class Companion:
    """An effect fitted together with this one (``effect``, its ``fitted`` parameters): wind
    exerts no force of its own, so it is fitted with the rotor-drag coefficient."""

    effect: str
    fitted: tuple[str, ...]


@dataclass(frozen=True)
class EffectFacts:
    """An effect's diagnosis facts (module doc). The defaults declare an effect the
    diagnosis does not fit on its own (no ``fitted`` parameters)."""

    #: parameters the effect's candidate frees (the others stay at their ``off`` value)
    fitted: tuple[str, ...] = ()
    #: a per-rotor name pattern ("rotor_{}"): the candidate frees rotor_1 .. rotor_R instead
    per_rotor: str = ""
    #: the motor's speed-per-command exponent under a propeller's load: a reading's prior of
    #: it is what the references' command -> speed map implies
    #: (:func:`quadsim.gap.explanations.explanations_for`)
    load_exponent: str = ""
    #: for a per-rotor effect, the uniform parameter (``effect.parameter``) the rotors' mean
    #: is judged as: every rotor equally weak is a uniform change, not R damaged ones
    uniform_as: str = ""
    #: values held fixed in the candidate (parameter -> value)
    fixed: Mapping[str, float] = field(default_factory=dict)
    #: the fitted parameters' typical sizes (a parameter without one steps in units of 1)
    scales: Mapping[str, Scale] = field(default_factory=dict)
    #: fit windows narrower than the declared bounds
    windows: Mapping[str, Window] = field(default_factory=dict)
    #: plausible ranges with their sources (a parameter without one has no prior check)
    ranges: Mapping[str, PlausibleRange] = field(default_factory=dict)
    #: prior spreads of a difference (a parameter without one: the evidence's own default)
    spreads: Mapping[str, Spread] = field(default_factory=dict)
    #: the per-flight readings of the effect (:class:`Reading`)
    readings: tuple[Reading, ...] = ()
    #: effects fitted with this one (:class:`Companion`)
    companions: tuple[Companion, ...] = ()
    #: acts upstream of the measured rotor speed (on the command -> speed map only), so it
    #: needs logged commands to be seen
    upstream_of_speed: bool = False
    #: a discrete index parameter ("rotor"): one candidate per rotor, that index fixed
    one_per_rotor: str = ""
    #: fitted instead of ``fitted`` when a battery voltage is logged
    with_voltage_log: tuple[str, ...] = ()
    #: fitted parameters whose "off" value does not switch the effect off (so "away from
    #: off" is no test of it)
    no_off_value: tuple[str, ...] = ()
    #: time constants of the rotor channel: at least one of its sub-steps in a fit
    #: (:func:`quadsim.gap.residual.min_time_constant`)
    rotor_time_constants: tuple[str, ...] = ()
    #: fitted parameters a fit starts at the highest logged battery voltage (where a
    #: voltage-following sag is neutral on average)
    starts_at_logged_voltage: tuple[str, ...] = ()
    #: fitted parameters refitted by instrumental variables on the commanded speeds, when
    #: commands are logged (least squares on measured speeds is attenuated by their noise:
    #: :func:`quadsim.gap.fitting.drag_refit_iv`)
    instrumented: tuple[str, ...] = ()
    #: parameters of the fit's own parametrisation (the diagnosis' fit form of the effect,
    #: :mod:`quadsim.gap.fitting`) that the library form does not have
    fit_parameters: tuple = ()
    #: other effect -> what measurement or manoeuvre tells the two apart
    separate_from: Mapping[str, str] = field(default_factory=dict)
    #: how a reading of each parameter is worded (:class:`Words`)
    words: Mapping[str, Words] = field(default_factory=dict)
    #: parameters worded together (:class:`Together`)
    together: Together | None = None
    #: fitted parameters that are no part of an answer (a payload's swing at the first
    #: sample): never worded
    nuisance: tuple[str, ...] = ()
    #: what of the pose (:data:`POSE_PARTS`) the effect's loads read beyond the IMU, the
    #: rotors and the battery: "velocity" (the air velocity, from the logged motion),
    #: "height" (the position's z, the distance to the ground), "attitude" (the world's
    #: directions in the body frame). On a log without a pose (IMU and motors only) the
    #: diagnosis cannot weigh the effect (:func:`without_pose`); empty: the body-frame force
    #: and torque balance alone shows it, with the IMU's own frame where the loads need one
    #: (a payload's swing: :func:`quadsim.gap.logcheck.posefree_states`)
    needs_pose: tuple[str, ...] = ()
    #: parameters read through the gravity balance (a mass the rotors weigh): measured in
    #: units of the references' thrust per Omega^2, so their stated size carries the
    #: between-session spread of that factor
    #: (:data:`quadsim.effects.thrust_factor.SESSION_SPREAD`,
    #: :func:`quadsim.gap.words.across_sessions`)
    weighed: tuple[str, ...] = ()

    def fitted_for(self, rotors: int) -> tuple[str, ...]:
        """The parameters the candidate frees on a vehicle with ``rotors`` rotors."""
        if self.per_rotor:
            return tuple(self.per_rotor.format(i + 1) for i in range(rotors))
        return tuple(self.fitted)

    def _lookup(self, table: Mapping, parameter: str):
        if parameter in table:
            return table[parameter]
        if self.per_rotor and _is_rotor(self.per_rotor, parameter) and self.per_rotor in table:
            return table[self.per_rotor]
        return table.get(ALL)

    def scale_of(self, parameter: str) -> Scale | None:
        return self._lookup(self.scales, parameter)

    def window_of(self, parameter: str) -> Window | None:
        return self._lookup(self.windows, parameter)

    def range_of(self, parameter: str) -> PlausibleRange | None:
        return self._lookup(self.ranges, parameter)

    def words_of(self, parameter: str) -> Words | None:
        return self._lookup(self.words, parameter)

    def spread_of(self, key: str, params: VehicleParams) -> float:
        """The prior spread of ``spreads[key]`` for ``params`` (:class:`Spread`)."""
        spread = self.spreads[key]
        if spread.size is not None:
            return spread.size(params)
        plausible = self.ranges[key]
        half = 0.5 * max(abs(plausible.lower), abs(plausible.upper))
        return half * range_unit(plausible.kind, params) if plausible.kind not in (
            "relative", "absolute") else half


def _is_rotor(pattern: str, parameter: str) -> bool:
    head, _, tail = pattern.partition("{}")
    middle = parameter[len(head):len(parameter) - len(tail)]
    return parameter.startswith(head) and parameter.endswith(tail) and middle.isdigit()


def range_unit(kind: str, params: VehicleParams) -> float:
    """The unit (SI) of a plausible range of ``kind`` (:class:`PlausibleRange`) for
    ``params``: 1 for "relative" and "absolute"."""
    if kind in ("relative", "absolute"):
        return 1.0
    if kind == "mass":
        return params.mass
    if kind == "arm":
        return arm_length(params)
    return {"hover": hover_thrust_per_speed, "momentum": momentum_rate_damping,
            "lift": momentum_translational_lift}[kind](params)


@dataclass(frozen=True)
class ParameterFacts:
    """One parameter's facts (:func:`quadsim.effects.facts_of`): unit, declared meaning,
    typical scale, plausible range and wording; None where the effect declares none."""

    effect: str
    parameter: str
    unit: str
    doc: str
    scale: Scale | None
    plausible: PlausibleRange | None
    words: Words | None


def parameter_facts(cls: type, parameter: str) -> ParameterFacts:
    """:class:`ParameterFacts` of ``parameter`` of effect class ``cls`` (KeyError if the
    effect has no such parameter, in its library or its fit form)."""
    facts = cls.facts
    specs = {p.name: p for p in tuple(cls.parameters) + tuple(facts.fit_parameters)}
    spec = specs[parameter]
    return ParameterFacts(cls.name, parameter, spec.unit, spec.doc, facts.scale_of(parameter),
                          facts.range_of(parameter), facts.words_of(parameter))


def missing_facts(cls: type, params_sets: tuple = ()) -> list[str]:
    """What effect class ``cls`` lacks for the diagnosis (empty: complete and consistent):
    its own ``facts``; every fitted, fixed, per-rotor, voltage-log, no-off and weighed
    parameter and every key of its tables among its parameters (or its fit form's); a
    typical scale and words with a unit for each fitted parameter; scales positive and
    finite on every set in ``params_sets`` (and a phrase, where declared, stating a number
    at that scale); ranges ordered (lower < upper) of a known kind with a source; spreads
    on a range where they take theirs from it."""
    out = []
    if "facts" not in vars(cls) or not isinstance(vars(cls)["facts"], EffectFacts):
        return [f"{cls.__name__}: no facts of its own (a ClassVar facts = EffectFacts(...))"]
    facts: EffectFacts = cls.facts
    known = {p.name for p in tuple(cls.parameters) + tuple(facts.fit_parameters)}
    pattern = facts.per_rotor
    fitted = facts.fitted_for(1) if pattern else tuple(facts.fitted)

    def exists(p):
        return p == ALL or p in known or (pattern and p == pattern)

    names = (list(fitted) + [p for r in facts.readings for p in r.fitted] + list(facts.fixed)
             + [p for r in facts.readings for p, _ in r.fixed]
             + list(facts.with_voltage_log)
             + list(facts.no_off_value) + list(facts.rotor_time_constants)
             + list(facts.starts_at_logged_voltage) + list(facts.instrumented)
             + list(facts.weighed)
             + [facts.one_per_rotor] * bool(facts.one_per_rotor) + list(facts.nuisance)
             + list(facts.together.parameters if facts.together else ())
             + [facts.load_exponent] * bool(facts.load_exponent))
    for table in (facts.scales, facts.windows, facts.ranges, facts.spreads, facts.words):
        names += list(table)
    out += [f"{cls.name}.{p}: not a parameter" for p in dict.fromkeys(names) if not exists(p)]
    for p in tuple(fitted) + tuple(facts.with_voltage_log):
        if facts.scale_of(p) is None:
            out.append(f"{cls.name}.{p}: fitted without a typical scale")
        words = facts.words_of(p)
        if words is None or not words.unit or not words.label:
            out.append(f"{cls.name}.{p}: fitted without words (label and unit)")
        for params in params_sets:
            scale = facts.scale_of(p)
            value = scale.size(params) if scale is not None else 1.0
            if not (np.isfinite(value) and value > 0):
                out.append(f"{cls.name}.{p}: typical scale {value!r} on {params.name}")
            elif words is not None and words.phrase is not None:
                text = words.phrase(p, value, 0.1 * value, params)
                if not (isinstance(text, str) and any(ch.isdigit() for ch in text)):
                    out.append(f"{cls.name}.{p}: phrase {text!r} states no number")
    for key, plausible in facts.ranges.items():
        if not plausible.lower < plausible.upper or plausible.kind not in RANGE_KINDS \
                or not plausible.source.strip():
            out.append(f"{cls.name}.{key}: plausible range unordered, of unknown kind or "
                       "without a source")
    for key, spread in facts.spreads.items():
        if spread.size is None and key not in facts.ranges:
            out.append(f"{cls.name}.{key}: spread from a plausible range it does not have")
        if not spread.reason.strip():
            out.append(f"{cls.name}.{key}: spread without a reason")
    for key, scale in facts.scales.items():
        if not scale.reason.strip():
            out.append(f"{cls.name}.{key}: scale without a reason")
    for r in facts.readings:
        if not r.fitted or r.odds < 1:
            out.append(f"{cls.name}: reading {r.variant!r} frees nothing or has odds < 1")
        out += [f"{cls.name}.{p}: read without a prior spread" for p in r.fitted
                if p != facts.load_exponent
                and facts.spreads.get(p, facts.spreads.get(ALL)) is None]
    for c in facts.companions:
        if not c.fitted:
            out.append(f"{cls.name}: companion {c.effect} frees nothing")
    return out


def without_pose(effects) -> dict[str, tuple[str, ...]]:
    """The effects (name -> class, e.g. :data:`quadsim.effects.EFFECTS`) a log without a
    pose cannot weigh, each with the pose parts it needs (:attr:`EffectFacts.needs_pose`)."""
    return {name: tuple(cls.facts.needs_pose) for name, cls in sorted(effects.items())
            if cls.facts.needs_pose}
