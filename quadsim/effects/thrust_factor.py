"""thrust_factor: the propellers give a different thrust (and drag torque) per Omega^2.

Formula (all rotors alike, relative change ``change``)::

    T_i = (1 + change) b Omega_i^2,     Q_i = (1 + change) d Omega_i^2

A propeller/air effect, acting *at the measured rotor speed*: momentum/blade-element theory
gives b, d proportional to the air density rho and to the blade geometry (e.g. Leishman,
"Principles of Helicopter Aerodynamics", 2nd ed., 2006, ch. 2-3: C_T = T / (rho A (Omega
R)^2)). Causes: air density (altitude, temperature: rho falls about 1 % per 85 m of altitude
or per 3 K), a different or worn/chipped propeller batch, a propeller guard or a body below
the rotors blocking the wake. A battery cannot do this (it changes the speed a command
gives, :mod:`quadsim.effects.battery_sag`).

In the force balance a uniform ``change`` is collinear with an added mass
(:mod:`quadsim.effects.mass_offset`): at hover ``change = -dm / (m + dm)``; the yaw channel
separates them (a thrust-per-Omega^2 change from the air also scales the drag torque d),
weighing the vehicle or a thrust-stand test settles it.

Example: ``make_effect("thrust_factor", change=-0.1)``: 10 % less thrust per Omega^2 on all
four rotors (hover needs 5.4 % more speed).
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectLoads, EffectParameter

__all__ = ["ThrustFactor"]


class ThrustFactor(EffectBase):
    """Uniform relative change of the thrust and drag-torque factors of all rotors."""

    name = "thrust_factor"
    parameters = (
        EffectParameter("change", "1", 0.0, -0.5, 0.5,
                        "relative change of propeller thrust (and drag torque) per Omega^2"),
    )

    def loads(self, ctx):
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.thrust_scale = np.full((batch, rotors), 1.0 + self.change)
        return loads
