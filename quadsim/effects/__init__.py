"""Unmodelled physical effects, one module each, behind one interface (:mod:`.base`).

The registry maps each effect's name to its class; effects are built from keywords or from
the command-line spec ``name:param=value,param=value``::

    >>> from quadsim.effects import EFFECTS, make_effect, parse_effect_spec, EffectSet
    >>> sorted(EFFECTS)                                   # the library
    >>> ge = parse_effect_spec("ground_effect:gain=1.5")
    >>> lag = make_effect("motor_lag", time_constant=0.03)
    >>> effects = EffectSet((ge, lag))                   # pass to quadsim.sim.engines.simulate

Every effect has named parameters with units (``EFFECTS[name].parameters``); each
parameter's ``off`` value is the default, and with all parameters at ``off`` the effect does
nothing. :func:`make_effect` and :func:`parse_effect_spec` check names and the plausible
bounds and raise :class:`~quadsim.core.errors.InputError` (one line) on a typo or a wild value.
See ``docs/effects.md`` for the formulas and sources (also in each module's docstring).

What the gap diagnosis needs to know of each effect (the parameters it fits, their typical
sizes, plausible ranges with sources, prior spreads, how a reading is worded) is declared by
the effect itself, ``EFFECTS[name].facts`` (:mod:`.facts`); :func:`facts_of` gives one
parameter's.
"""

from __future__ import annotations

from ..core.errors import InputError
from .base import Effect, EffectBase, EffectContext, EffectLoads, EffectParameter, EffectSet
from .battery_sag import BatterySag
from .blade_flapping import BladeFlapping
from .body_drag import BodyDrag
from .cable_payload import CablePayload
from .canted_rotor import CantedRotor
from .com_offset import ComOffset
from .facts import EffectFacts, ParameterFacts, parameter_facts
from .ground_effect import GroundEffect
from .gyroscopic import Gyroscopic
from .inertia_error import InertiaError
from .mass_offset import MassOffset
from .motor_lag import MotorLag
from .rate_damping import RateDamping
from .rotor_drag import RotorDrag
from .thrust_curve import ThrustCurve
from .thrust_factor import ThrustFactor
from .thrust_mismatch import ThrustMismatch
from .translational_lift import TranslationalLift
from .wind import Wind

__all__ = [
    "EFFECTS",
    "TESTBED_EXAMPLES",
    "Effect",
    "EffectBase",
    "EffectContext",
    "EffectFacts",
    "EffectLoads",
    "EffectParameter",
    "EffectSet",
    "ParameterFacts",
    "describe_effects",
    "effect_set_from_specs",
    "facts_of",
    "make_effect",
    "parse_effect_spec",
]

#: name -> effect class, for every effect in the library.
EFFECTS: dict[str, type[EffectBase]] = {cls.name: cls for cls in (
    MotorLag, ThrustCurve, ThrustMismatch, RotorDrag, BodyDrag, GroundEffect, BatterySag,
    ComOffset, MassOffset, InertiaError, Wind, Gyroscopic, ThrustFactor, RateDamping,
    CantedRotor, CablePayload, BladeFlapping, TranslationalLift)}

#: Realistic magnitudes of each effect on the 0.84 kg testbed (specs for
#: :func:`effect_set_from_specs`), shared by the engine-agreement tests and
#: ``scripts/effects_agreement.py``. Wind only acts through drag, so it comes with drag.
TESTBED_EXAMPLES: dict[str, tuple[str, ...]] = {
    "thrust_curve": ("thrust_curve:linear=-2e-4",),
    "thrust_mismatch": ("thrust_mismatch:rotor_1=0.03,rotor_2=-0.02",),
    "rotor_drag": ("rotor_drag:coefficient=1e-5,axial_coefficient=5e-6",),
    "blade_flapping": ("blade_flapping:coefficient=2e-6",),
    "translational_lift": ("translational_lift:k_h=0.01",),
    "body_drag": ("body_drag:cd_area=0.02,cd_area_vertical=0.04",),
    "ground_effect": ("ground_effect:gain=1.5",),
    "battery_sag": ("battery_sag:rate=0.01",),
    "thrust_factor": ("thrust_factor:change=-0.05",),
    "com_offset": ("com_offset:x=0.005,y=-0.003,z=0.01",),
    "mass_offset": ("mass_offset:mass=0.1,x=0.02,z=-0.03",),
    "inertia_error": ("inertia_error:xx=0.2,yy=0.1,zz=0.05",),
    "gyroscopic": ("gyroscopic:rotor_inertia=6e-5",),
    "wind": ("wind:vx=2,vy=-1,gust=0.5,seed=3", "body_drag:cd_area=0.02",
             "rotor_drag:coefficient=1e-5"),
    "motor_lag": ("motor_lag:time_constant=0.03,time_constant_down=0.05",),
    "rate_damping": ("rate_damping:x=0.01,y=0.01,z=0.002",),
    "canted_rotor": ("canted_rotor:rotor=1,angle=0.05,azimuth=1.5708",),
    "cable_payload": ("cable_payload:mass=0.1,length=0.5,z=-0.05",),
}


def make_effect(name: str, **values: float) -> EffectBase:
    """Build effect ``name`` with parameter ``values``; unknown names/parameters and values
    outside the parameter's plausible bounds raise :class:`InputError`."""
    if name not in EFFECTS:
        raise InputError(f"effect {name!r}: unknown effect; valid: {', '.join(sorted(EFFECTS))}")
    cls = EFFECTS[name]
    specs = {p.name: p for p in cls.parameters}
    for key, value in values.items():
        if key not in specs:
            raise InputError(f"effect {name}: unknown parameter {key!r}; valid: "
                             f"{', '.join(specs)}")
        spec = specs[key]
        if not spec.lower <= float(value) <= spec.upper:
            unit = "" if spec.unit == "1" else f" {spec.unit}"    # "1": dimensionless
            raise InputError(f"effect {name}: {key} = {value:g}{unit} outside the "
                             f"plausible range [{spec.lower:g}, {spec.upper:g}]{unit}")
    return cls(**{k: float(v) for k, v in values.items()})


def parse_effect_spec(spec: str) -> EffectBase:
    """``"name"`` or ``"name:param=value,param=value"`` -> effect (see :func:`make_effect`)."""
    name, _, rest = spec.strip().partition(":")
    values: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, eq, text = item.partition("=")
        if not eq:
            raise InputError(f"effect spec {spec!r}: {item!r} is not param=value")
        try:
            values[key.strip()] = float(text)
        except ValueError:
            raise InputError(f"effect spec {spec!r}: {key.strip()}: {text!r} is not a number") \
                from None
    return make_effect(name.strip(), **values)


def effect_set_from_specs(specs: list[str]) -> EffectSet:
    """An :class:`EffectSet` from command-line specs; one effect may appear only once."""
    effects = [parse_effect_spec(s) for s in specs]
    names = [e.name for e in effects]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise InputError(f"effect {repeated[0]!r} given more than once; merge its parameters")
    return EffectSet(tuple(effects))


def describe_effects(effects: EffectSet) -> list[dict]:
    """JSON-ready description (name, values, units) of each effect, for truth sidecars."""
    out = []
    for effect in effects.effects:
        units = {p.name: p.unit for p in effect.parameters}
        out.append({"name": effect.name, "values": effect.values(), "units": units})
    return out


def facts_of(parameter: str) -> ParameterFacts:
    """The facts of library parameter ``effect.parameter`` (``"body_drag.cd_area"``): unit,
    meaning, typical scale, plausible range, and how a reading is worded (label, display unit
    and scale): :class:`~quadsim.effects.facts.ParameterFacts`. Raises :class:`InputError`
    for an unknown effect or parameter."""
    name, _, key = parameter.partition(".")
    if name not in EFFECTS:
        raise InputError(f"effect {name!r}: unknown effect; valid: {', '.join(sorted(EFFECTS))}")
    try:
        return parameter_facts(EFFECTS[name], key)
    except KeyError:
        raise InputError(f"effect {name}: unknown parameter {key!r}") from None
