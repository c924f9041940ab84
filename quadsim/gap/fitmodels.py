"""The effects the diagnosis fits beyond the library, declared in one place.

:data:`FIT_FORMS`: library effects the diagnosis fits in a form of its own (a canted rotor by
its axis' horizontal lean, a cable payload with its swing driven by the logged motion);
:data:`PSEUDO_EFFECTS`: effects of the diagnosis that the library does not have (the nominal
refit of b and d, the motor map's gain, the references' drag under a quadratic law). Both are
static: built here from explicit imports, never filled by other modules, so what the
diagnosis can fit does not depend on what was imported. :data:`FIT_EFFECTS` is the library
with these; :func:`effect_class`, :func:`build_effect` and :func:`facts_for` read it.

Every class declares its diagnosis facts (:class:`quadsim.effects.facts.EffectFacts`); a
fit form inherits its library effect's.

Example::

    >>> build_effect("canted_rotor", {"rotor": 1.0, "tilt_x": 0.02})   # a CantedRotorFit
    >>> facts_for("nominal_refit").fitted                                # ('thrust', 'drag')
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

from ..effects import EFFECTS, make_effect
from ..effects.base import EffectBase, EffectParameter
from ..effects.body_drag import BodyDrag
from ..effects.canted_rotor import CantedRotor
from ..effects.facts import (
    EffectFacts,
    ParameterFacts,
    PlausibleRange,
    Scale,
    Words,
    parameter_facts,
    plus_minus,
)
from .cable import CableSwing

__all__ = ["FIT_EFFECTS", "FIT_FORMS", "LOCAL_EFFECTS", "PSEUDO_EFFECTS", "SPEED_GAIN_PART",
           "CantedRotorFit", "DragLaw", "NominalRefit", "SpeedGain", "build_effect",
           "effect_class", "facts_for", "parameter_facts_for"]


class CantedRotorFit(CantedRotor):
    """``canted_rotor`` as the diagnosis fits it: the tilted axis' horizontal components
    ``tilt_x``, ``tilt_y`` (rad, small angles: the axis leans by them towards body +x, +y)
    instead of angle and azimuth, which are singular at angle 0 (every azimuth gives the
    same untilted rotor, so a fit starting there cannot move). ``angle = hypot(tilt_x,
    tilt_y)``, ``azimuth = atan2(tilt_x, -tilt_y)`` (then Rodrigues tilts z by angle about
    (cos azimuth, sin azimuth, 0) towards (sin azimuth, -cos azimuth) = (tilt_x, tilt_y) /
    angle). The rotor index is fixed per candidate: one candidate per rotor
    (``facts.one_per_rotor``), the one that fits the training flights best is kept."""

    parameters = CantedRotor.parameters + CantedRotor.facts.fit_parameters

    def apply_to_params(self, params):
        angle = float(np.hypot(self.tilt_x, self.tilt_y))
        if angle == 0.0:
            return CantedRotor(rotor=self.rotor, angle=self.angle,
                               azimuth=self.azimuth).apply_to_params(params)
        return CantedRotor(rotor=self.rotor, angle=angle,
                           azimuth=float(np.arctan2(self.tilt_x, -self.tilt_y))
                           ).apply_to_params(params)


def _refit_phrase(parameter, value, ci, params) -> str:
    if parameter == "thrust":
        return (f"{plus_minus(value, ci, 100)} % thrust per Ω² on all {params.rotor_count} "
                "rotors")
    return f"{plus_minus(value, ci, 100)} % drag torque per Ω²"


class NominalRefit(EffectBase):
    """Baseline: the parameter set's thrust and drag factors b and d refitted (relative
    changes); the reference model's shared group and the held-out reading "b and d are off"
    (:data:`quadsim.gap.fitting.BASELINE`)."""

    name = "nominal_refit"
    parameters = (
        EffectParameter("thrust", "1", 0.0, -0.9, 3.0, "relative change of b"),
        EffectParameter("drag", "1", 0.0, -0.9, 3.0, "relative change of d"),
    )
    facts = EffectFacts(
        fitted=("thrust", "drag"),
        # d from the yaw torque on measured speeds is regression-diluted to -1 near hover
        instrumented=("drag",),
        scales={"thrust": Scale(lambda p: 0.05, "5 %: as a propeller change (thrust_factor)"),
                "drag": Scale(lambda p: 0.2, "20 %: d is known less well than b")},
        ranges={"thrust": PlausibleRange(-0.15, 0.05, "relative", "as thrust_factor.change")},
        separate_from={
            "mass_offset": "weigh the vehicle, or measure b on a thrust stand",
            "thrust_factor": "the same effect (b refitted); a thrust stand tells b and d apart",
            "thrust_curve": "fly over a wider range of rotor speeds"},
        words={"thrust": Words("thrust per Omega^2 on every rotor", "%", 100.0, _refit_phrase),
               "drag": Words("drag torque per Omega^2", "%", 100.0, _refit_phrase)},
    )

    def apply_to_params(self, params):
        return params.replace(thrust_factor=params.thrust_factor * (1 + self.thrust),
                              drag_factor=params.drag_factor * (1 + self.drag))


def _speed_gain_phrase(parameter, value, ci, params) -> str:
    return f"the rotors spin {plus_minus(value, ci, 1e2)} % faster per command (steady speed)"


class SpeedGain(EffectBase):
    """The motor map's gain: the steady rotor speed per command scaled by (1 + gain), as a
    pseudo-effect the reference model shares (:mod:`.calibrate`) when commands are logged and
    no battery voltage is.

    Why. The static command -> speed map (:func:`quadsim.gap.fitting.fit_motor_map`) is fitted
    once on all reference flights pooled; a single flight's mean speed per command still differs
    from it, and by how it was flown: on the 8 Crazyflow references (path speed 0.8-1.25) the
    rotor channel's mean residual runs from -0.07 % of the hover speed on the slowest to +0.05 %
    on the fastest (Crazyflow's rotor dynamics are not first order at one time constant, so the
    mean speed a varying command gives depends on how much it varies). Without a shared
    parameter for it, that offset had no place in the reference model's uncertainty, and a
    nominal flight's own offset was read as ``thrust_factor`` (whose propeller coupling moves
    the speed per command) or ``battery_sag``. With a battery-voltage log the shared
    ``battery_sag.full_voltage`` (speed per command ~ vbat / V_full) already is this gain.

    Physics: ``Omega_ss = (1 + gain) Omega_map(command)`` (:meth:`SpeedGain.speed_factor`,
    upstream of the measured speed like a battery: the thrust at a measured speed is unchanged).
    Typical size (fit step unit) 1 %; bounds -50 % to +100 %: the references' own gain stays
    within a few per cent (a map off by more is refused by the motor map's own checks), but a
    flight's reading of another motor or ESC
    (:func:`quadsim.gap.explanations.explanations_for`, ``MOTOR_CHANGE``) takes the gain of its
    own, and on PyFlyt a 2.5x slower motor spins +45 % per command.

    Example::

        >>> SpeedGain(gain=0.01).speed_factor(np.zeros(3))     # array([1.01, 1.01, 1.01])
    """

    name = "speed_gain"
    parameters = (
        EffectParameter("gain", "1", 0.0, -0.5, 1.0,
                        "relative change of the steady rotor speed per command"),
    )
    facts = EffectFacts(
        fitted=("gain",),
        upstream_of_speed=True,
        scales={"gain": Scale(lambda p: 0.01, "1 %: the references' own gain stays within a few "
                                             "per cent (class doc)")},
        words={"gain": Words("steady speed per command", "%", 100.0, _speed_gain_phrase)},
    )

    def speed_factor(self, t, vbat=None):
        if self.gain == 0.0:
            return None
        return np.full(len(np.atleast_1d(t)), 1.0 + self.gain)


#: the shared-candidate part (name, fixed, fitted) of the motor map's gain
SPEED_GAIN_PART = ("speed_gain", {}, ("gain",))


class DragLaw(BodyDrag):
    """The references' horizontal drag under a quadratic law, held fixed in every reading
    of a flight (:mod:`quadsim.gap.drag_law`): :class:`quadsim.effects.body_drag.BodyDrag`
    under its own name, so that a reading's own body drag stays apart from it. Never fitted
    (its C_d A is the references' equivalent)."""

    name = "drag_law"
    facts = EffectFacts()


#: library effect -> the class the diagnosis fits in its place (module doc)
FIT_FORMS = MappingProxyType({cls.name: cls for cls in (CantedRotorFit, CableSwing)})
#: the diagnosis' own effects, not in the library (module doc)
PSEUDO_EFFECTS = MappingProxyType({cls.name: cls for cls in (NominalRefit, SpeedGain, DragLaw)})
#: every class the diagnosis fits in place of a name that is not the library's own
LOCAL_EFFECTS = MappingProxyType({**FIT_FORMS, **PSEUDO_EFFECTS})
#: name -> the class the diagnosis builds for it (the library, with :data:`LOCAL_EFFECTS`)
FIT_EFFECTS = MappingProxyType({**EFFECTS, **LOCAL_EFFECTS})


def effect_class(name: str) -> type:
    """The class the diagnosis builds for effect ``name`` (KeyError for an unknown one)."""
    return FIT_EFFECTS[name]


def facts_for(name: str) -> EffectFacts:
    """The diagnosis facts of effect ``name`` (library or pseudo-effect)."""
    return FIT_EFFECTS[name].facts


def parameter_facts_for(parameter: str) -> ParameterFacts:
    """The facts of ``effect.parameter`` (``"speed_gain.gain"``) of any effect the diagnosis
    fits, library or its own: unit, meaning, typical scale, plausible range, words
    (:class:`quadsim.effects.facts.ParameterFacts`; :func:`quadsim.effects.facts_of` for
    the library alone). KeyError for an unknown effect or parameter."""
    name, _, key = parameter.partition(".")
    return parameter_facts(FIT_EFFECTS[name], key)


def build_effect(name: str, values: dict):
    """Effect ``name`` with parameter ``values``: a :data:`LOCAL_EFFECTS` class built directly,
    a library effect through :func:`quadsim.effects.make_effect` (its bounds checked)."""
    if name in LOCAL_EFFECTS:
        return LOCAL_EFFECTS[name](**values)
    return make_effect(name, **values)
