"""thrust_mismatch: per-rotor deviations of the thrust (and drag) factor.

Formula (rotor i, relative deviation e_i, torque share s)::

    T_i = (1 + e_i) b Omega_i^2,     Q_i = (1 + s e_i) d Omega_i^2
    Omega_ss,i = (1 + s e_i)^-alpha Omega_command,i     (the speed rotor i's command gives)

The torque share s (``torque_share``) is the fraction of the thrust change that the drag
torque per Omega^2 takes: 1 (the default) scales both alike (a propeller of another batch:
same blade, same air; Leishman 2006 ch. 2-3); 0 changes the thrust alone. Why a share:
real propellers lie between -- a chipped or bent blade, a blade partly blocked by a payload
or an arm below it, a mismatched propeller change thrust and torque by different fractions;
JSBSim's F450 with one propeller's thrust table scaled and its power table not (the
benchmark's eighteenth source, cases 13 and 14) is s = 0 (CHANGELOG.md, "Thrust alone").
At s = 1 the loads are the thrust scale alone (bit for bit as before the share existed); at
any other s the thrust scale is still 1 + e_i (the propeller's whole thrust curve, with the
references' linear and constant terms, scales with its thrust) and a body torque of
``(1 - s) e_i d Omega_i^2`` along the rotor's spin takes back the part of the drag torque
change that does not follow (exact with no other effect scaling that rotor; with another
scale k on it, the drag torque is off by (k - 1)(1 - s) e_i d Omega_i^2, a product of two
small fractions). The motor's load is its drag torque, so the speed a command gives follows
the torque's change, (1 + s e_i)^-alpha: a thrust-alone change leaves it.

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
stay 0; ``alpha`` the speed-per-command exponent; ``torque_share`` s (1, 0 .. 2: above 1 the
torque changes more than the thrust, a propeller of higher pitch). Examples:
``parse_effect_spec("thrust_mismatch:rotor_2=-0.05,alpha=0.2")``: rotor 2's propeller gives 5 %
less thrust per Omega^2 and its command 1.03 % more speed;
``parse_effect_spec("thrust_mismatch:rotor_3=-0.1,torque_share=0")``: rotor 3 gives 10 % less
thrust per Omega^2 at an unchanged drag torque.
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
                         "voltage efficiency)"),
         EffectParameter("torque_share", "1", 1.0, 0.0, 2.0,
                         "share of the thrust change the drag torque per Omega^2 takes "
                         "(1: both alike; 0: thrust alone)"))

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
                          rotor_speeds=True),
                  # its thrust alone: the drag torque per Omega^2 (and so the motor's load and
                  # its speed per command) unchanged. Why: the reading above predicts a yaw
                  # torque d e Omega^2 that a blade chipped at its tip or blocked below (thrust
                  # lost, drag kept) does not make, and lost JSBSim's weak propeller to an
                  # off-centre mass (CHANGELOG.md, "Thrust alone"). Fixed at 0, not fitted:
                  # the share acts only through e (a coupled reading, fitted to convergence on
                  # every flight, and an Occam factor for a yaw torque a few per cent of the
                  # hover drag torque); the two ends bracket a real propeller's share
                  Reading(("rotor_{}",), "rotor {}, its thrust alone (drag torque unchanged)",
                          per_rotor=True, fixed=(("torque_share", 0.0),))),
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

    def torque_changes(self, rotors: int) -> np.ndarray:
        """(R,) relative changes s e_i of each rotor's drag torque per Omega^2."""
        dev = self.deviations(rotors)
        share = self._values["torque_share"]
        return dev if share == 1.0 else share * dev

    def rotor_speed_factor(self, rotors: int):
        """(R,) factors (1 + s e_i)^-alpha on the speed each rotor's command gives (the
        motor's load is the drag torque); None when alpha or every torque change is 0."""
        if self._values["alpha"] == 0.0:
            return None
        change = self.torque_changes(rotors)
        if not np.any(change):
            return None
        return (1.0 + change) ** (-self._values["alpha"])

    def loads(self, ctx):
        """Thrust scale 1 + e_i per rotor; at a torque share s other than 1 also the body
        torque (N m) ``sum_i (1 - s) e_i spin_i d Omega_i^2 a_i`` that takes back the drag
        torque change ``-(1 - s) e_i spin_i d Omega_i^2 a_i`` the scale makes (module doc)."""
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        dev = self.deviations(rotors)
        loads.thrust_scale = np.broadcast_to(1.0 + dev, (batch, rotors)).copy()
        share = self._values["torque_share"]
        if share != 1.0 and np.any(dev):
            params = ctx.params
            back = (1.0 - share) * dev * params.rotor_spins * params.drag_factor   # (R,)
            loads.torque_body = (np.square(ctx.rotor_speed) * back) @ params.rotor_axes
        return loads
