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

from __future__ import annotations

import numpy as np

from ..effects.base import EffectBase, EffectParameter
from ..effects.facts import EffectFacts, Scale, Words, plus_minus

__all__ = ["PART", "SpeedGain"]


def _phrase(parameter, value, ci, params) -> str:
    return f"the rotors spin {plus_minus(value, ci, 1e2)} % faster per command (steady speed)"


class SpeedGain(EffectBase):
    """Steady rotor speed per command scaled by (1 + gain) (module doc)."""

    name = "speed_gain"
    parameters = (
        EffectParameter("gain", "1", 0.0, -0.5, 1.0,
                        "relative change of the steady rotor speed per command"),
    )
    facts = EffectFacts(
        fitted=("gain",),
        upstream_of_speed=True,
        scales={"gain": Scale(lambda p: 0.01, "1 %: the references' own gain stays within a few "
                                             "per cent (module doc)")},
        words={"gain": Words("steady speed per command", "%", 100.0, _phrase)},
    )

    def speed_factor(self, t, vbat=None):
        if self.gain == 0.0:
            return None
        return np.full(len(np.atleast_1d(t)), 1.0 + self.gain)


#: the shared-candidate part (name, fixed, fitted)
PART = ("speed_gain", {}, ("gain",))
