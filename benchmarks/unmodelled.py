"""Physical effects no reading of the diagnosis covers: the out-of-library cases of issue 47.

Since blade flapping and translational lift became readings of the library, the
out-of-library cases of the self-generated benchmark and of the sensor-pipeline source had
none left (:mod:`.outside` still holds the flapping moment those cases flew). The effects here
are real, act through quadsim's effect hooks (``loads``), and are not offered by any module
of :mod:`quadsim.effects` as a reading; the diagnosis never sees these classes. They live
apart from :mod:`.outside` because that file's bytes are part of the code hash that keys
every cached pipeline flight (:func:`benchmarks.cases._code_hash`): editing it would
invalidate the flown cases; this file keys only the cases that fly its effects.

``RotorWake`` (``rotor_wake``): rotor-rotor interference in forward flight. A rotor's wake
is swept back by the relative wind; the rotors downstream of the vehicle's centre ingest the
upstream rotors' downwash, see a larger inflow and give less thrust at the same speed
(Diaz & Yoon, "High-fidelity computational aerodynamics of multi-rotor unmanned aerial
vehicles", AIAA SciTech 2018, AIAA 2018-1266: the rear rotors of a quadcopter in forward
flight give markedly less thrust than the front pair; Throneberry, Takeshita, Hocut, Shu &
Abdelkefi, "Wake propagation and characteristics of a multi-rotor unmanned vehicle in
forward flight", Drones 6(5):130, 2022: PIV of the front wake reaching the rear rotors). To
first order in the air speed, per rotor i (body frame, z up)::

    v_h      = air velocity with its body-z part removed                          (m/s)
    u_i      = unit horizontal direction of hub i from the CoM
    s_i      = max(0, -(v_h . u_i))                  how far downstream hub i sits (m/s)
    T_i, Q_i = (1 - k_wake s_i) (b, d) Omega_i^2     thrust and drag torque (thrust_scale)

``k_wake`` in s/m (fraction of the rotor's thrust lost per m/s). Flying along body +x an X
quad's rear pair each lose ``k_wake |v| / sqrt(2)``, the front pair nothing; flying
backwards the front pair loses it. What no reading has: a thrust loss proportional to
``|v|`` (on four hubs 90 deg apart, summed over rotors ``k_wake |v| (|cos psi| + |sin psi|)``
of one rotor's thrust, psi the angle of v_h from a hub direction) and a per-rotor loss that
follows the direction of flight. Its pitch/roll moment, ``-k_wake b Omega^2 L (e_z x v_h)``
for equal rotor speeds Omega and hub distance L on four hubs 90 deg apart, has the form of
the library's blade-flapping moment (linear in the air speed, about the axis e_z x v): the
case tests whether that part is named confidently while the thrust loss stays unexplained.

Size (:func:`draw_unmodelled`): ``k_wake`` 0.02-0.04 s/m, a downstream rotor 2-4 % weaker
per m/s (Diaz & Yoon's 20-30 % rear-pair deficit at 10 m/s, taken linear in the speed).

``FrameMoment`` (``frame_moment``): the moment of the airframe's drag about the CoM. A
frame's drag acts at its centre of pressure, which sits a height ``height`` above (a
canopy, a GPS mast) or below (a slung battery, a camera) the CoM; the library's
``body_drag`` acts at the CoM. Drag equation (Hoerner, "Fluid-dynamic drag", 1965, ch. 1;
Mahony, Kumar & Corke, IEEE RAM 2012, sec. "Drag") with the lever arm ``height e_z``::

    F   = -0.5 rho cd_area |v| v                    (N, body frame, v the air velocity)
    tau = height e_z x F = -0.5 rho cd_area height |v| (e_z x v)          (N m, body frame)

Only the moment is here (the force is the library's ``body_drag``, which every reference of
the vehicle shares): a case of this effect changes nothing the library reads except through
a moment quadratic in the air speed (weathervaning: a centre of pressure above the CoM
pitches the nose up in forward flight, below it down).

Size (:func:`draw_unmodelled`): a drag of 1-4 % of the weight at 1.5 m/s (the benchmark's
``body_drag`` sizes, :func:`benchmarks.draws.draw`) on a lever of 25-50 % of the arm, above
or below: 0.25-2 % of weight x arm at 1.5 m/s.
"""

from __future__ import annotations

import numpy as np

from quadsim.core.frames import rotate_inverse
from quadsim.effects import EffectBase, EffectLoads, EffectParameter
from quadsim.vehicle.params import VehicleParams

from .outside import in_plane_air_velocity

__all__ = ["UNMODELLED", "FrameMoment", "RotorWake", "draw_unmodelled", "hub_directions"]


def hub_directions(params: VehicleParams) -> np.ndarray:
    """Unit horizontal direction (R, 3) of each hub from the CoM, body frame (z part 0)."""
    hubs = np.asarray(params.rotor_positions, dtype=float) - np.asarray(params.com, dtype=float)
    hubs[:, 2] = 0.0
    return hubs / np.linalg.norm(hubs, axis=1, keepdims=True)


class RotorWake(EffectBase):
    """Out of the library: T_i = (1 - k_wake max(0, -v_h . u_i)) b Omega_i^2 (module doc)."""

    name = "rotor_wake"
    parameters = (EffectParameter("k_wake", "s/m", 0.0, 0.0, 0.2,
                                  "thrust fraction a downstream rotor loses per m/s"),)

    def loads(self, ctx):
        loads = EffectLoads.neutral(*ctx.rotor_speed.shape)
        downstream = np.maximum(0.0, -(in_plane_air_velocity(ctx) @ hub_directions(ctx.params).T))
        loads.thrust_scale = 1.0 - self.k_wake * downstream
        return loads


class FrameMoment(EffectBase):
    """Out of the library: tau = -0.5 rho cd_area height |v| (e_z x v), N m (module doc)."""

    name = "frame_moment"
    parameters = (EffectParameter("cd_area", "m^2", 0.0, 0.0, 1.0,
                                  "drag area C_d A of the frame"),
                  EffectParameter("height", "m", 0.0, -0.5, 0.5,
                                  "centre of pressure above the CoM along body z"))

    def loads(self, ctx):
        loads = EffectLoads.neutral(*ctx.rotor_speed.shape)
        v = rotate_inverse(ctx.quat, ctx.air_velocity)
        ez_cross_v = np.stack([-v[:, 1], v[:, 0], np.zeros(len(v))], axis=1)
        scale = 0.5 * ctx.params.air_density * self.cd_area * self.height
        loads.torque_body = -scale * np.linalg.norm(v, axis=1)[:, None] * ez_cross_v
        return loads


#: the effects of this module, by case name
UNMODELLED = {"rotor_wake": RotorWake, "frame_moment": FrameMoment}


def draw_unmodelled(name: str, params: VehicleParams, rng: np.random.Generator) -> list:
    """The effect ``name`` of :data:`UNMODELLED` at a random size a real vehicle shows (module
    doc: ``rotor_wake`` 0.02-0.04 s/m; ``frame_moment`` a drag of 1-4 % of the weight at
    1.5 m/s on a lever of +-(25-50) % of the arm), as a one-element list of effects."""
    if name == "rotor_wake":
        return [RotorWake(k_wake=rng.uniform(0.02, 0.04))]
    if name == "frame_moment":
        arm = float(np.max(np.linalg.norm(np.asarray(params.rotor_positions)[:, :2], axis=1)))
        cd_area = 2.0 * rng.uniform(0.01, 0.04) * params.weight / (params.air_density * 1.5 ** 2)
        height = rng.choice((-1.0, 1.0)) * rng.uniform(0.25, 0.5) * arm
        return [FrameMoment(cd_area=cd_area, height=height)]
    raise ValueError(f"no out-of-library effect {name!r}; known: {sorted(UNMODELLED)}")
