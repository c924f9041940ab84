"""rate_damping: aerodynamic damping torque proportional to the body rates.

Formula (body frame, per axis, N m)::

    tau = -(k_x w_x, k_y w_y, k_z w_z)

A rolling or pitching vehicle moves each rotor disc up or down through the air: the
advancing side sees less inflow and more thrust, the retreating side the opposite, and the
thrust difference times the arm opposes the rate (plus blade-flapping and frame drag
moments); yawing adds a profile-drag moment. To first order all are linear in the rate
(Bristeau, Martin, Salaün & Petit, "The role of propeller aerodynamics in the model of a
quadrotor UAV", ECC 2009, sec. 4; Mahony, Kumar & Corke, "Multirotor aerial vehicles",
IEEE RAM 2012, sec. "rotor dynamics"). Order of magnitude from momentum theory: with
dT/dv_z ~ T/(2 v_i) per rotor (v_i the hover induced velocity) and arm r, a "+" vehicle's
roll damping is k ~ 2 r^2 dT/dv_z; for the 0.84 kg testbed (T = 2.06 N, v_i = 4.1 m/s,
r = 0.198 m) k_x ~ 0.02 N m s/rad.

Parameters ``x, y, z`` are the damping coefficients k (N m s/rad) about body x, y, z; 0 = off;
at most 10 N m s/rad: the momentum-theory value grows with arm^2 x thrust, 0.47 N m s/rad for
a 5.5 kg quadrotor on 0.45 m arms with 18-inch propellers (:mod:`benchmarks.multirotor_source`)
whose plausible range reaches 3x that (:mod:`quadsim.gap.fitting`); the former 1 N m s/rad cut
that range off.
Example: ``rate_damping:x=0.01,y=0.01,z=0.002`` gives a roll rate of 1 rad/s a torque of
-0.01 N m (the testbed's Ixx = 0.006 kg m^2: a 0.6 s time constant).
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectContext, EffectLoads, EffectParameter
from .facts import ALL, EffectFacts, PlausibleRange, Scale, Spread, Words, plus_minus
from .scales import momentum_rate_damping

__all__ = ["RateDamping", "momentum_rate_damping"]


def _phrase(parameter, value, ci, params) -> str:
    i = "xyz".index(parameter)
    tau = params.inertia[i, i] / value if value > 0 else float("inf")
    return (f"{('roll', 'pitch', 'yaw')[i]} rate damping {plus_minus(value, ci, 1.0, '.3g')} "
            f"N m per rad/s (decay time I/k {tau:.3g} s)")


class RateDamping(EffectBase):
    """Linear aerodynamic damping torque -k w per body axis."""

    name = "rate_damping"
    parameters = (
        EffectParameter("x", "N m s/rad", 0.0, 0.0, 10.0, "roll damping coefficient k_x"),
        EffectParameter("y", "N m s/rad", 0.0, 0.0, 10.0, "pitch damping coefficient k_y"),
        EffectParameter("z", "N m s/rad", 0.0, 0.0, 10.0, "yaw damping coefficient k_z"),
    )

    facts = EffectFacts(
        fitted=("x", "y", "z"),
        scales={axis: Scale(lambda p, i=i: p.inertia[i, i],
                            "a damping time constant I/k of about 1 s")
                for i, axis in enumerate("xyz")},
        ranges={ALL: PlausibleRange(
            0.0, 3.0, "momentum",
            "momentum theory k = r^2 T_hover / v_i (Bristeau et al. 2009) x 3 for blade "
            "flapping and frame drag (Mahony et al. 2012)")},
        spreads={ALL: Spread()},
        words={ALL: Words("rate damping", "N m s/rad", 1.0, _phrase)},
    )

    #: (context fields, vehicle attributes) ``loads`` reads (:attr:`EffectBase.loads_reads`)
    loads_reads = ((), ())

    def loads(self, ctx: EffectContext) -> EffectLoads | None:
        if self.is_off():
            return None
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.torque_body = -np.asarray(ctx.body_rate, dtype=float) \
            * np.array([self.x, self.y, self.z])
        return loads
