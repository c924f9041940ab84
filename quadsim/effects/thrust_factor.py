"""thrust_factor: the propellers give a different thrust (and drag torque) per Omega^2.

Formula (all rotors alike, relative change ``change``)::

    T_i = (1 + change) b Omega_i^2,     Q_i = (1 + change) d Omega_i^2
    Omega_ss = (1 + change)^-alpha Omega_command        (the speed a command gives)

A propeller/air effect, acting *at the measured rotor speed*: momentum/blade-element theory
gives b, d proportional to the air density rho and to the blade geometry (e.g. Leishman,
"Principles of Helicopter Aerodynamics", 2nd ed., 2006, ch. 2-3: C_T = T / (rho A (Omega
R)^2)). Causes: air density (altitude, temperature: rho falls about 1 % per 85 m of altitude
or per 3 K), a different or worn/chipped propeller batch, a propeller guard or a body below
the rotors blocking the wake. A battery cannot do this (it changes the speed a command
gives, :mod:`quadsim.effects.battery_sag`).

The speed a command gives. The drag torque per Omega^2 is the motor's load, so a motor
driven at a fixed duty cycle spins faster under a lighter propeller: a DC motor in steady
state, k_t (u V - k_e W) / R = k_Q W^2, gives ``d ln W / d ln k_Q = -(1 - eta) / (2 - eta)``
with eta = k_e W / (u V) the motor's voltage efficiency: alpha = 0.2 at eta = 0.75, 0.33 at
0.5. ``alpha = 0`` (the default) is a motor whose controller holds the commanded speed
(RotorPy's rotors; an ESC with speed control). Like a battery (hook ``speed_factor``) this
acts upstream of the measured rotor speed.

In the force balance a uniform ``change`` is collinear with an added mass
(:mod:`quadsim.effects.mass_offset`): at hover ``change = -dm / (m + dm)``; the yaw channel
separates them (a thrust-per-Omega^2 change from the air also scales the drag torque d),
weighing the vehicle or a thrust-stand test settles it.

Example: ``make_effect("thrust_factor", change=-0.1)``: 10 % less thrust per Omega^2 on all
four rotors (hover needs 5.4 % more speed); with ``alpha=0.2`` a command also gives 2.1 %
less speed (the heavier load).
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectLoads, EffectParameter
from .facts import EffectFacts, PlausibleRange, Reading, Scale, Spread, Words, plus_minus

__all__ = ["ThrustFactor"]


def _phrase(parameter, value, ci, params) -> str:
    return f"{plus_minus(value, ci, 100)} % thrust per Ω² on all {params.rotor_count} rotors"


class ThrustFactor(EffectBase):
    """Uniform relative change of the thrust and drag-torque factors of all rotors."""

    name = "thrust_factor"
    parameters = (
        EffectParameter("change", "1", 0.0, -0.5, 0.5,
                        "relative change of propeller thrust (and drag torque) per Omega^2"),
        EffectParameter("alpha", "1", 0.0, 0.0, 0.5,
                        "speed-per-command exponent: a command gives (1 + change)^-alpha of "
                        "its speed (0: speed-controlled motors; 0.2: a DC motor at 75 % "
                        "voltage efficiency)"),
    )

    facts = EffectFacts(
        fitted=("change",),
        load_exponent="alpha",
        # with rotor speeds logged the propeller's load moves the speed per command too;
        # alpha acts only through change (no load change, no speed change: speed_factor)
        readings=(Reading(("change",), kin=("mass_offset", "thrust_curve"), rotor_speeds=False),
                  Reading(("change", "alpha"), coupled=True, kin=("mass_offset", "thrust_curve"),
                          rotor_speeds=True, through=(("alpha", "change"),))),
        scales={"change": Scale(lambda p: 0.05, "5 %: a propeller batch or the air's density"),
                "alpha": Scale(lambda p: 1.0, "the exponent's unit (its range is 0 .. 0.5)")},
        ranges={"change": PlausibleRange(
            -0.15, 0.05, "relative",
            "prop-to-prop C_T spread 2-5 % (UIUC prop data), air density +-5 % (0-30 C) or "
            "-13 % at 1500 m (ISA), wear")},
        spreads={"change": Spread(),
                 "alpha": Spread(lambda p: 0.1, "DC-motor efficiency 0.6-0.9 (module doc)")},
        separate_from={
            "thrust_curve": "fly over a wider range of rotor speeds (climbs and descents at "
                            "several rates)",
            "cable_payload": "look under the vehicle; weigh it; sharp stops and turns show a "
                             "swinging load"},
        words={"change": Words("thrust per Omega^2 on every rotor", "%", 100.0, _phrase),
               "alpha": Words("speed-per-command exponent", "1", 1.0)},
    )

    def speed_gain(self) -> float:
        """The factor (1 + change)^-alpha on the speed a command gives."""
        return float((1.0 + self.change) ** (-self.alpha))

    def speed_factor(self, t, vbat=None):
        if self.change == 0.0 or self.alpha == 0.0:
            return None
        return np.full(len(np.atleast_1d(t)), self.speed_gain())

    def loads(self, ctx):
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.thrust_scale = np.full((batch, rotors), 1.0 + self.change)
        return loads
