"""translational_lift: a rotor moving edgewise through the air gives more thrust per Omega^2.

At a fixed rotor speed a rotor in edgewise flow makes more thrust than in hover: its wake is
blown away, so the induced inflow through the disc falls, and the advancing blade sees more
dynamic pressure than the retreating one loses. Blade-element / momentum theory in forward
flight gives ``C_T = (sigma a / 2) [theta_0 / 3 (1 + 3/2 mu^2) - lambda / 2]`` with the
inflow ratio lambda falling with the advance ratio mu (Leishman, *Principles of Helicopter
Aerodynamics*, 2nd ed., Cambridge 2006, eqs. 3.93 and 2.122, Glauert's inflow). To second
order in the in-plane air speed, per rotor i with unit axis a_i::

    v_perp,i = v - (v . a_i) a_i          air velocity in rotor i's plane (body frame, m/s)
    T_i      = b Omega_i^2 + k_h |v_perp,i|^2                                         N

the quadratic form of RotorPy (Folk, Paulos & Kumar, "RotorPy: a Python-based multirotor
simulator with aerodynamics", arXiv:2306.04485, 2023: thrust ``k_eta Omega^2 + k_h |v_h|^2``
with v_h the body x-y air velocity; the same for rotors along body z). ``k_h`` in
N/(m/s)^2 = kg/m, per rotor; the extra thrust acts along each rotor axis at its hub (so an
uneven lift would also make a moment) and leaves the drag torque unchanged (EffectLoads
``thrust_offset``). v is the vehicle's air velocity (velocity minus wind) in body axes; the
body rate is not included in the hub velocity (second order, as in RotorPy's lift term).

Against a rotor-speed dependence of the thrust (:mod:`.thrust_curve`) it differs in what
drives it: the lift grows with airspeed at any rotor speed, the thrust curve with rotor speed
at any airspeed. On a figure-8 flown at near constant speed the two move together and a
flight cannot tell them apart; a straight level pass at two speeds (the same thrust, twice
the airspeed) separates them.

Example: the 0.84 kg testbed (hover thrust 2.06 N per rotor) at 2 m/s with k_h = 0.01 kg/m
gets +0.04 N per rotor, +1.9 % of the hover thrust.
"""

from __future__ import annotations

import numpy as np

from ..core.frames import rotate_inverse
from .base import EffectBase, EffectContext, EffectLoads, EffectParameter
from .facts import EffectFacts, PlausibleRange, Reading, Scale, Spread, Words, plus_minus
from .scales import momentum_translational_lift

__all__ = ["TranslationalLift", "momentum_translational_lift", "translational_lift_thrust"]


def translational_lift_thrust(air_velocity_body: np.ndarray, rotor_axes: np.ndarray,
                              k_h: float) -> np.ndarray:
    """Extra thrust per rotor (B, R), N, from the body-frame air velocity (B, 3), m/s, the
    unit rotor axes (R, 3) and ``k_h`` (N/(m/s)^2): ``k_h |v - (v . a_i) a_i|^2``."""
    v = np.asarray(air_velocity_body, dtype=float)
    axial = v @ np.asarray(rotor_axes, dtype=float).T                     # (B, R)
    return k_h * (np.sum(v * v, axis=1)[:, None] - axial ** 2)


def _phrase(parameter, value, ci, params) -> str:
    """The extra thrust at 2 m/s of in-plane air speed, all rotors."""
    r = params.rotor_count
    lift = r * value * 4.0                           # N at 2 m/s in-plane air speed
    clift = None if ci is None else r * ci * 4.0
    return (f"translational lift {plus_minus(lift, clift, 1e3, '.3g')} mN of extra thrust at "
            f"2 m/s of in-plane air speed ({100 * lift / (params.mass * params.gravity):+.2g} % "
            f"of the weight; k_h {value:.3g} kg/m per rotor)")


class TranslationalLift(EffectBase):
    """Thrust gain k_h |v_perp|^2 per rotor (N), v_perp the rotor-plane air velocity."""

    name = "translational_lift"
    # bounds: 16x the momentum-theory lift of the 0.84 kg testbed (rho pi R^2 / 2 = 0.031
    # kg/m for its 127 mm rotors; quadsim.gap.fitting), negative for a fit's difference
    parameters = (
        EffectParameter("k_h", "kg/m", 0.0, -0.5, 0.5,
                        "extra thrust per rotor per in-plane air speed squared, "
                        "N/(m/s)^2; positive: more thrust in edgewise flight"),
    )

    facts = EffectFacts(
        needs_pose=("velocity", "attitude"),   # thrust gain with the air velocity across the rotor
        fitted=("k_h",),
        readings=(Reading(("k_h",)),),
        scales={"k_h": Scale(momentum_translational_lift, "the momentum-theory lift")},
        ranges={"k_h": PlausibleRange(
            0.0, 2.0, "lift",
            "momentum theory k = T_hover / (4 v_i^2) per rotor (Glauert inflow, Leishman 2006) "
            "x 2 for the blade-element factor")},
        spreads={"k_h": Spread()},
        words={"k_h": Words("translational lift", "kg/m", 1.0, _phrase)},
    )

    def loads(self, ctx: EffectContext) -> EffectLoads | None:
        if self.is_off():
            return None
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.thrust_offset = translational_lift_thrust(
            rotate_inverse(ctx.quat, ctx.air_velocity), ctx.params.rotor_axes, self.k_h)
        return loads
