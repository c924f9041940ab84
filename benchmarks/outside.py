"""An effect outside the diagnosis' readings, for benchmark cases it cannot name.

Real rotors do this; the gap diagnosis does not offer it as a reading of a flight. It acts
through quadsim's effect hooks (``loads``), so the self-generated benchmark
(:mod:`benchmarks.synthetic`) and the sensor-pipeline source (:mod:`.pipeline`, MuJoCo
engine) fly it; the diagnosis never sees this class. (Translational lift was here until the
library gained it, :mod:`quadsim.effects.translational_lift`, on 2026-11-25; the library's
blade flapping, :mod:`quadsim.effects.blade_flapping`, is the same moment, fitted by the
held-out mode but not a per-flight reading: docs/gap.md, Known limits.)

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

from quadsim.core.frames import rotate_inverse
from quadsim.effects import EffectBase, EffectLoads, EffectParameter

__all__ = ["BladeFlapping", "in_plane_air_velocity"]


def in_plane_air_velocity(ctx) -> np.ndarray:
    """Body-frame air velocity of the vehicle (B, 3), m/s, with its body-z part removed."""
    air = rotate_inverse(ctx.quat, ctx.air_velocity)
    air[:, 2] = 0.0
    return air


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
