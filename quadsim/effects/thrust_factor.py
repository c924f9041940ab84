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

Between sessions (:data:`SESSION_SPREAD`). Reference flights flown in one session fix b
and d at that session's air; their flight-to-flight scatter (0.14 % in b on the Crazyflie
2.1 set, ``models/crazyflie21.toml``) cannot show how far another day's air moves them. The
ideal gas gives rho = p / (R_specific T), so ``d ln b = d ln p - d ln T``: 0.34 % per K at
293 K, and a weather swing of 20 hPa is 2 % of the ISA sea-level 1013.25 hPa.
:func:`air_density_spread` turns a stated room-temperature range and pressure swing into
the 95 % half-width of the relative thrust change between two sessions; a mass read through
the gravity balance (:attr:`~quadsim.effects.facts.EffectFacts.weighed`) is measured in
units of the references' b and carries it (:func:`quadsim.gap.words.across_sessions`).

Example: ``make_effect("thrust_factor", change=-0.1)``: 10 % less thrust per Omega^2 on all
four rotors (hover needs 5.4 % more speed); with ``alpha=0.2`` a command also gives 2.1 %
less speed (the heavier load).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import EffectBase, EffectLoads, EffectParameter
from .facts import EffectFacts, PlausibleRange, Reading, Scale, Spread, Words, plus_minus

__all__ = ["SESSION_SPREAD", "SessionSpread", "ThrustFactor", "air_density_spread"]


def air_density_spread(temperature_k: tuple[float, float], pressure_swing: float) -> float:
    """The 95 % half-width (relative, 1 = 100 %) of the change of thrust per Omega^2 between
    two flight sessions from the air's density alone.

    b is proportional to rho = p / (R_specific T) (ideal gas; module doc), so the relative
    change between two sessions is ln(rho_1 / rho_2) = ln(p_1 / p_2) - ln(T_1 / T_2).
    ``temperature_k`` (low, high), K: the room's temperature in both sessions lies within
    it, so |ln(T_1 / T_2)| <= ln(high / low). ``pressure_swing`` (relative): the largest
    |ln(p_1 / p_2)| between the two sessions' station pressures (weather). Each bound is
    taken as the 95 % half-width of an independent error and the two combine in
    quadrature: sqrt(ln(high / low)^2 + pressure_swing^2). Raises ValueError on
    temperatures that are not 0 < low <= high or a negative swing."""
    low, high = (float(t) for t in temperature_k)
    if not 0.0 < low <= high or not pressure_swing >= 0.0:
        raise ValueError(f"air_density_spread: temperature_k {temperature_k!r} must be "
                         f"0 < low <= high (K), pressure_swing {pressure_swing!r} >= 0")
    return float(np.hypot(np.log(high / low), pressure_swing))


@dataclass(frozen=True)
class SessionSpread:
    """The between-session spread of the thrust (and drag torque) per Omega^2: ``relative``
    the 95 % half-width of the relative change (1 = 100 %) between the references' session
    and a judged flight's, ``temperature_k`` and ``pressure_swing`` what it was computed
    from (:func:`air_density_spread`), ``source`` one line: where the numbers come from and
    what is left out."""

    temperature_k: tuple[float, float]
    pressure_swing: float
    source: str

    @property
    def relative(self) -> float:
        return air_density_spread(self.temperature_k, self.pressure_swing)


#: the between-session spread of b and d declared for every vehicle: an indoor flight room
#: held at 20-26 C (293.15-299.15 K) in both sessions, ln(299.15 / 293.15) = 2.03 %, and
#: weather moving the station pressure by up to 20 hPa between the two days, 1.97 % of
#: 1013.25 hPa; in quadrature 2.83 %
SESSION_SPREAD = SessionSpread(
    temperature_k=(293.15, 299.15),
    pressure_swing=20.0 / 1013.25,     # 20 hPa of the ISA sea-level pressure
    source=("ideal-gas air density rho = p / (R T) (b, d proportional to rho: Leishman 2006, "
            "ch. 2-3) over an indoor room at 20-26 C in both sessions (the ASHRAE 55 / "
            "ISO 7730 comfort range of operative temperature) and a weather swing of the "
            "station pressure up to 20 hPa of the ISA 1013.25 hPa between the two days; a "
            "swapped or worn propeller set (C_T 2-5 % prop to prop, UIUC propeller data) "
            "is not included: after a swap, fly new references"))


def _phrase(parameter, value, ci, params) -> str:
    """The change in words, with how far another session's air alone moves it
    (:data:`SESSION_SPREAD`: the change is measured against the references' session, so
    one within it need not be the propellers)."""
    return (f"{plus_minus(value, ci, 100)} % thrust per Ω² on all {params.rotor_count} rotors "
            f"(another session's air alone: ± {100 * SESSION_SPREAD.relative:.2g} %)")


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
