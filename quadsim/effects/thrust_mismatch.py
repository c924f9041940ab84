"""thrust_mismatch: per-rotor deviations of the thrust (and drag) factor.

Formula (rotor i, relative deviation e_i)::

    T_i = (1 + e_i) b Omega_i^2,     Q_i = (1 + e_i) d Omega_i^2

Motors and propellers of one vehicle differ by a few per cent (manufacturing tolerance,
a chipped blade, a bent shaft); e.g. the 2015 report's per-motor fits of b differ between
the four motors, and Förster (ETH 2015) measures per-motor differences on the Crazyflie. A
mismatch shows as a constant torque that a controller must trim out.

Parameters ``rotor_1 .. rotor_8`` are the relative deviations e_i (fraction; 0.05 = 5 %
more thrust) in the parameter set's rotor numbering; rotors beyond the vehicle's count must
stay 0. Example: ``parse_effect_spec("thrust_mismatch:rotor_2=-0.05")``.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ModelError
from .base import EffectBase, EffectLoads, EffectParameter

__all__ = ["MAX_ROTORS", "ThrustMismatch"]

MAX_ROTORS = 8


class ThrustMismatch(EffectBase):
    """Per-rotor relative thrust/drag factor deviations."""

    name = "thrust_mismatch"
    parameters = tuple(
        EffectParameter(f"rotor_{i}", "1", 0.0, -0.5, 0.5,
                        f"relative thrust factor deviation of rotor {i} (fraction)")
        for i in range(1, MAX_ROTORS + 1)
    )

    def deviations(self, rotors: int) -> np.ndarray:
        """(R,) relative deviations for a vehicle with ``rotors`` rotors."""
        values = np.array([self._values[f"rotor_{i}"] for i in range(1, MAX_ROTORS + 1)])
        if np.any(values[rotors:] != 0.0):
            raise ModelError(f"thrust_mismatch: deviation given for a rotor beyond the "
                             f"vehicle's {rotors} rotors")
        return values[:rotors]

    def loads(self, ctx):
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.thrust_scale = np.broadcast_to(1.0 + self.deviations(rotors), (batch, rotors)).copy()
        return loads
