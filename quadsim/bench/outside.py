"""Effects outside quadsim's library, for benchmark cases the diagnosis cannot name.

Real rotors do both of these; quadsim's effect library (and so the gap diagnosis' candidate
list) has neither. They act through quadsim's effect hooks (``loads``), so the
self-generated benchmark (:mod:`quadsim.gap.synthetic`) and the sensor-pipeline source
(:mod:`.pipeline`, MuJoCo engine) fly them; the diagnosis never sees these classes.

``TranslationalLift`` (``translational_lift``): at a fixed rotor speed a rotor moving edgewise
through the air gives more thrust than in hover (the wake is blown away, the induced inflow
drops; the advancing blade sees more dynamic pressure). Per rotor i, with v_h the in-plane
(body x-y) air velocity of the vehicle in m/s::

    T_i = b Omega_i^2 + k_h |v_h|^2            k_h in N / (m/s)^2

the quadratic model of RotorPy (Folk, Paulos, Kumar, "RotorPy: a Python-based multirotor
simulator with aerodynamics", arXiv:2306.04485, 2023, eq. for the rotor thrust with k_h);
physics: blade-element / momentum theory in forward flight, C_T = (sigma a / 2)
[theta_0 / 3 (1 + 3/2 mu^2) - lambda / 2] with the inflow lambda falling with advance ratio mu
(Leishman, *Principles of Helicopter Aerodynamics*, 2nd ed., Cambridge 2006, eqs. 3.93 and
2.122 (Glauert)). Added along each rotor's axis (``thrust_offset``), no drag-torque change.

``BladeFlapping`` (``blade_flapping``): in edgewise flight the advancing blade lifts more
than the retreating one; the blades flap up in front and the disc tilts back, and through the
hub stiffness this is a moment on the body that pitches the nose away from the relative wind.
Summed over rotors, body frame (z up), Omega_i in rad/s::

    tau = -k_flap (sum_i Omega_i) (e_z x v_h)  k_flap in N m s^2 / (m rad)

(Mahony, Kumar & Corke, "Multirotor aerial vehicles", IEEE Robotics & Automation Magazine
19(3), 2012, section "Blade flapping": flap angle proportional to in-plane speed, moment
k_beta times flap angle; the same form as RotorPy's k_flap term). Only the moment: the force
part of flapping (the thrust tilting back) is the library's ``rotor_drag``.
"""

from __future__ import annotations

import numpy as np

from ..core.frames import rotate_inverse
from ..effects import EffectBase, EffectLoads, EffectParameter

__all__ = ["BladeFlapping", "TranslationalLift", "in_plane_air_velocity"]


def in_plane_air_velocity(ctx) -> np.ndarray:
    """Body-frame air velocity of the vehicle (B, 3), m/s, with its body-z part removed."""
    air = rotate_inverse(ctx.quat, ctx.air_velocity)
    air[:, 2] = 0.0
    return air


class TranslationalLift(EffectBase):
    """Out of the library: + k_h |v_h|^2 (N) on every rotor's thrust, v_h in-plane airspeed."""

    name = "translational_lift"
    parameters = (EffectParameter("k_h", "N/(m/s)^2", 0.0, 0.0, 1.0,
                                  "thrust gain per rotor per in-plane airspeed squared"),)

    def loads(self, ctx):
        loads = EffectLoads.neutral(*ctx.rotor_speed.shape)
        vh2 = np.sum(in_plane_air_velocity(ctx) ** 2, axis=1)            # (B,) m^2/s^2
        loads.thrust_offset = self.k_h * vh2[:, None] * np.ones(ctx.rotor_speed.shape[1])
        return loads


class BladeFlapping(EffectBase):
    """Out of the library: tau = -k_flap (sum Omega) (e_z x v_h), N m."""

    name = "blade_flapping"
    parameters = (EffectParameter("k_flap", "N m s^2/(m rad)", 0.0, 0.0, 1.0,
                                  "flapping moment per rotor speed per in-plane airspeed"),)

    def loads(self, ctx):
        loads = EffectLoads.neutral(*ctx.rotor_speed.shape)
        v = in_plane_air_velocity(ctx)
        ez_cross_v = np.stack([-v[:, 1], v[:, 0], np.zeros(len(v))], axis=1)
        loads.torque_body = -self.k_flap * np.sum(ctx.rotor_speed, axis=1)[:, None] * ez_cross_v
        return loads
