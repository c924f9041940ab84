"""thrust_mismatch: per-rotor deviations of the thrust (and drag) factor.

Formula (rotor i, relative deviation e_i)::

    T_i = (1 + e_i) b Omega_i^2,     Q_i = (1 + e_i) d Omega_i^2
    Omega_ss,i = (1 + e_i)^-alpha Omega_command,i       (the speed rotor i's command gives)

Motors and propellers of one vehicle differ by a few per cent (manufacturing tolerance,
a chipped blade, a bent shaft); e.g. the 2015 report's per-motor fits of b differ between
the four motors, and Förster (ETH 2015) measures per-motor differences on the Crazyflie. A
mismatch shows as a constant torque that a controller must trim out.

The speed a command gives: the drag torque per Omega^2 is the motor's load, so a DC motor
driven at a fixed duty cycle spins a lighter propeller faster, by (1 + e_i)^-alpha with the
exponent of :mod:`quadsim.effects.thrust_factor` (0.2 for a DC motor at 75 % voltage
efficiency; 0, the default, for a motor whose controller holds the commanded speed). Why:
without this term a weaker propeller's faster spin is left in the rotor speed channel
(CHANGELOG.md: Docstrings as contracts).
Like a battery it acts upstream of the measured rotor speed (hook ``rotor_speed_factor``).

Parameters ``rotor_1 .. rotor_8`` are the relative deviations e_i (fraction; 0.05 = 5 %
more thrust) in the parameter set's rotor numbering; rotors beyond the vehicle's count must
stay 0; ``alpha`` the speed-per-command exponent. Example:
``parse_effect_spec("thrust_mismatch:rotor_2=-0.05,alpha=0.2")``: rotor 2's propeller gives 5 %
less thrust per Omega^2 and its command 1.03 % more speed.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ModelError
from .base import MAX_ROTORS, EffectBase, EffectLoads, EffectParameter
from .facts import ALL, EffectFacts, PlausibleRange, Reading, Scale, Spread, Words, plus_minus

__all__ = ["MAX_ROTORS", "ThrustMismatch"]


def _phrase(parameter, value, ci, params) -> str:
    return f"{parameter} {plus_minus(value, ci, 100)} % thrust"


class ThrustMismatch(EffectBase):
    """Per-rotor relative thrust/drag factor deviations."""

    name = "thrust_mismatch"
    parameters = tuple(
        EffectParameter(f"rotor_{i}", "1", 0.0, -0.5, 0.5,
                        f"relative thrust factor deviation of rotor {i} (fraction)")
        for i in range(1, MAX_ROTORS + 1)
    ) + (EffectParameter("alpha", "1", 0.0, 0.0, 0.5,
                         "speed-per-command exponent: rotor i's command gives (1 + e_i)^-alpha "
                         "of its speed (0: speed-controlled motors; 0.2: a DC motor at 75 % "
                         "voltage efficiency)"),)

    facts = EffectFacts(
        per_rotor="rotor_{}",
        uniform_as="thrust_factor.change",
        load_exponent="alpha",
        # one propeller: its thrust and drag torque; with rotor speeds logged also as a
        # reading of its own in which the rotor's command gives (1 + e)^-alpha of its speed
        # (the motor's load). That one is coupled (alpha acts through the deviation); its kin
        # is the plain reading of the same rotor. Why two: with alpha in the only reading, a
        # speed-controlled motor (alpha 0, two spreads from the prior's centre) loses its weak
        # rotor to an off-centre mass; without it, a DC motor's weak rotor stays in its speed
        # channel (CHANGELOG.md: Docstrings as contracts)
        readings=(Reading(("rotor_{}",), "rotor {}", per_rotor=True),
                  Reading(("rotor_{}", "alpha"), "rotor {}, with its speed per command",
                          per_rotor=True, coupled=True, kin=("thrust_mismatch",),
                          rotor_speeds=True)),
        scales={"rotor_{}": Scale(lambda p: 0.05, "5 %: one worn or chipped propeller"),
                "alpha": Scale(lambda p: 1.0, "the exponent's unit (its range is 0 .. 0.5)")},
        # each rotor's deviation; the speed exponent its own (the ALL range would judge
        # alpha, a motor's law, as a thrust deviation: 0.2 read as "outside -20 .. 10 %")
        ranges={ALL: PlausibleRange(-0.2, 0.1, "relative",
                                    "one damaged or mismatched prop/motor"),
                "alpha": PlausibleRange(0.0, 0.5, "absolute",
                                        "0 a speed-controlled motor, 0.2 a DC motor at 75 % "
                                        "voltage efficiency, 0.5 a speed set by the "
                                        "propeller's torque alone (Q = d Omega^2 fixed)")},
        spreads={ALL: Spread()},
        words={"rotor_{}": Words("one rotor's thrust per Omega^2", "%", 100.0, _phrase),
               "alpha": Words("speed-per-command exponent", "1", 1.0)},
    )

    def deviations(self, rotors: int) -> np.ndarray:
        """(R,) relative deviations for a vehicle with ``rotors`` rotors."""
        values = np.array([self._values[f"rotor_{i}"] for i in range(1, MAX_ROTORS + 1)])
        if np.any(values[rotors:] != 0.0):
            raise ModelError(f"thrust_mismatch: deviation given for a rotor beyond the "
                             f"vehicle's {rotors} rotors")
        return values[:rotors]

    def rotor_speed_factor(self, rotors: int):
        """(R,) factors (1 + e_i)^-alpha on the speed each rotor's command gives; None when
        alpha or every deviation is 0."""
        if self._values["alpha"] == 0.0:
            return None
        dev = self.deviations(rotors)
        if not np.any(dev):
            return None
        return (1.0 + dev) ** (-self._values["alpha"])

    def loads(self, ctx):
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.thrust_scale = np.broadcast_to(1.0 + self.deviations(rotors), (batch, rotors)).copy()
        return loads
