"""Effects outside quadsim's library, for benchmark cases the diagnosis cannot name.

``RateDamping``: aerodynamic torque opposing the body rate, ``tau = -k w`` (k in N m s/rad).
``CantedRotor``: rotor 1's thrust tilted by ``angle`` (rad) about body x, giving a side force
``-sin(angle) b Omega_1^2`` on body y and the roll torque of that force at rotor 1's hub.
Both act through quadsim's effect hooks (they are used only by the benchmark's
quadsim-flown sources, never by the diagnosis).
"""

from __future__ import annotations

import numpy as np

from ..effects import EffectBase, EffectLoads, EffectParameter
from ..frames import rotate

__all__ = ["CantedRotor", "RateDamping"]


class RateDamping(EffectBase):
    """Out of the library: aerodynamic torque opposing the body rate, -k w (N m s/rad)."""

    name = "rate_damping"
    parameters = (EffectParameter("k", "N m s/rad", 0.0, 0.0, 1.0, "damping"),)

    def loads(self, ctx):
        loads = EffectLoads.neutral(*ctx.rotor_speed.shape)
        loads.torque_body = -self.k * ctx.body_rate
        return loads


class CantedRotor(EffectBase):
    """Out of the library: rotor 1's thrust tilted by `angle` (rad) about body x."""

    name = "canted_rotor"
    parameters = (EffectParameter("angle", "rad", 0.0, -0.5, 0.5, "tilt of rotor 1"),)

    def loads(self, ctx):
        loads = EffectLoads.neutral(*ctx.rotor_speed.shape)
        p = ctx.params
        thrust = p.thrust_factor * ctx.rotor_speed[:, 0] ** 2
        side = np.zeros((len(thrust), 3))
        side[:, 1] = -np.sin(self.angle) * thrust
        loads.force_world = rotate(ctx.quat, side)
        arm = p.rotor_positions[0] - p.com
        loads.torque_body = np.cross(arm, side)
        return loads
