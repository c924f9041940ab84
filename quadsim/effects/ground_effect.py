"""ground_effect: more thrust near the ground (Cheeseman–Bennett form with a fitted gain).

Formula (rotor i, hub height above the ground z_i, rotor radius R)::

    T_i / T_inf = 1 / (1 - gain * (R / (4 z_i))^2)

Cheeseman & Bennett, "The effect of the ground on a helicopter rotor in forward flight",
ARC R&M 3021 (1955), from the method of images (gain = 1). For multirotors a gain above 1
fits better (Sanchez-Cuevas, Heredia & Ollero, "Characterization of the aerodynamic ground
effect and its influence in multirotor control", IJAE 2017). Examples: at z = R the thrust
rises by 1/(1 - gain/16) - 1 = 6.7 % for gain 1, 10.3 % for gain 1.5.

z_i is measured at each hub (attitude included), above the plane ``z = ground_height``
(world). The correction grows without bound as z -> 0, so ``gain (R/4z)^2`` is capped at
``MAX_TERM`` = 0.5 (a factor of at most 2, reached at z = R sqrt(gain/8)); the formula is
not valid that low anyway. R is ``radius`` if given, else the parameter set's rotor radius.
The scale multiplies thrust and drag torque (the induced power falls in ground effect; the
rotor is modelled as running at a better thrust coefficient).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ModelError
from ..core.frames import rotate
from .base import EffectBase, EffectLoads, EffectParameter
from .facts import EffectFacts, Reading, Scale, Spread, Words, plus_minus

__all__ = ["MAX_TERM", "GroundEffect", "ground_effect_ratio"]

MAX_TERM = 0.5


def ground_effect_ratio(height: np.ndarray, radius: float, gain: float) -> np.ndarray:
    """T / T_inf at hub heights ``height`` (m) above the ground, rotor radius (m)."""
    height = np.maximum(np.asarray(height, dtype=float), 1e-9)
    term = np.minimum(gain * np.square(radius / (4.0 * height)), MAX_TERM)
    return 1.0 / (1.0 - term)


def _phrase(parameter, value, ci, params) -> str:
    rise = 100 * (1 / (1 - min(0.5, value / 16)) - 1)
    return (f"ground effect {plus_minus(value, ci, 1.0)} x the Cheeseman–Bennett model "
            f"(+{rise:.2g} % thrust with the rotors one radius above the ground)")


class GroundEffect(EffectBase):
    """Thrust increase near the ground, per rotor, from the hub height."""

    name = "ground_effect"
    parameters = (
        EffectParameter("gain", "1", 0.0, 0.0, 5.0,
                        "Cheeseman-Bennett gain (1 = method of images; 0 = off)"),
        EffectParameter("ground_height", "m", 0.0, -100.0, 100.0, "world z of the ground"),
        EffectParameter("radius", "m", 0.0, 0.0, 1.0,
                        "rotor radius (0 = the parameter set's rotor_radius)"),
    )

    facts = EffectFacts(
        needs_pose=("height", "attitude"),   # the rotor hubs' height above the ground
        fitted=("gain",),
        readings=(Reading(("gain",)),),
        scales={"gain": Scale(lambda p: 1.0, "the textbook curve")},
        spreads={"gain": Spread(lambda p: 1.0, "Cheeseman & Bennett (1955) ground effect: gain "
                                               "1 is the textbook curve")},
        separate_from={"thrust_curve": "hover at several heights at the same speed"},
        words={"gain": Words("ground effect, x the Cheeseman-Bennett model", "1", 1.0, _phrase)},
    )

    def loads(self, ctx):
        params = ctx.params
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        if self.gain == 0.0:
            return loads
        radius = self.radius or params.rotor_radius
        if radius <= 0.0:
            raise ModelError(f"ground_effect: {params.path or params.name} has no rotor_radius;"
                             " give radius=...")
        hubs = ctx.position[:, None, :] + rotate(ctx.quat[:, None, :], params.rotor_positions[None])
        loads.thrust_scale = ground_effect_ratio(hubs[..., 2] - self.ground_height, radius,
                                                 self.gain)
        return loads
