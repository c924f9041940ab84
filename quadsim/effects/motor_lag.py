"""motor_lag: first-order rotor-speed dynamics (the rotor does not follow its command at once).

Formula (per rotor, commanded speed Omega_c, actual speed Omega)::

    dOmega/dt = (Omega_c - Omega) / tau,   tau = time_constant            when Omega_c >= Omega
                                           tau = time_constant_down       when Omega_c <  Omega
                                                 (0 = same as time_constant)

A first-order motor + propeller model is the standard one for brushless ESC-driven rotors;
see e.g. Bangura & Mahony, "Nonlinear dynamic modeling for high performance control of a
quadrotor" (ACRA 2012), and Faessler et al., "Thrust mixing, saturation, and body-rate
control for accurate aggressive quadrotor flight" (RA-L 2017), which identify spin-up faster
than spin-down (the motor drives up, only air drag brakes down). Typical tau: 20-60 ms.

Example::

    >>> from quadsim.effects import make_effect
    >>> lag = make_effect("motor_lag", time_constant=0.03, time_constant_down=0.05)

With ``time_constant = 0`` the effect is off and the rotor follows its command at once
(``rotor_speed_rate`` returns None, and the engines carry no rotor-speed states).
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectParameter
from .facts import EffectFacts, Scale, Spread, Words, plus_minus

__all__ = ["MotorLag"]


def _phrase(parameter, value, ci, params) -> str:
    return f"the rotors lag their commands by {plus_minus(value, ci, 1e3)} ms (time constant)"


class MotorLag(EffectBase):
    """First-order rotor-speed lag, optionally different up and down."""

    name = "motor_lag"
    parameters = (
        EffectParameter("time_constant", "s", 0.0, 0.0, 0.5,
                        "spin-up time constant (0 = no lag, effect off)"),
        EffectParameter("time_constant_down", "s", 0.0, 0.0, 0.5,
                        "spin-down time constant (0 = same as time_constant)"),
    )

    facts = EffectFacts(
        fitted=("time_constant",),
        upstream_of_speed=True,
        rotor_time_constants=("time_constant", "time_constant_down"),
        scales={"time_constant": Scale(lambda p: 0.03, "30 ms: a micro motor's time constant")},
        spreads={"time_constant": Spread(lambda p: 0.03,
                                         "brushed/brushless micro motors 10-60 ms (Foerster, "
                                         "ETH 2015: Crazyflie 2.0 ~ 15 ms)")},
        separate_from={
            "inertia_error": "fast attitude steps with measured rotor speeds (lag shows between "
                             "command and speed, inertia between speed and rate)"},
        words={"time_constant": Words("motor time constant", "ms", 1e3, _phrase),
               "time_constant_down": Words("motor time constant (slowing)", "ms", 1e3)},
    )

    def rotor_speed_rate(self, t, commanded, actual):
        if self.time_constant <= 0.0:
            return None
        down = self.time_constant_down if self.time_constant_down > 0.0 else self.time_constant
        commanded = np.asarray(commanded, dtype=float)
        actual = np.asarray(actual, dtype=float)
        tau = np.where(commanded >= actual, self.time_constant, down)
        return (commanded - actual) / tau
