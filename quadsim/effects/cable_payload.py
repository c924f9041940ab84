"""cable_payload: a point mass hanging on a cable from the vehicle; it swings.

Model: a point payload of mass m at world position p, velocity v, on a cable of rest length L
from the attachment point r_a (body frame; attachment in the world x_a = x + R r_a, velocity
v_a = v_x + R (w x r_a)). The cable is taut-only and axially elastic (a stiff spring-damper
that cannot push), the standard lumped model of a slung load (Goodarzi & Lee, "Dynamics and
control of quadrotor UAVs transporting a rigid body connected via flexible cables", ACC 2015;
the rigid-link limit is Sreenath, Lee & Kumar, "Geometric control and differential flatness
of a quadrotor UAV with a cable-suspended load", CDC 2013)::

    d = p - x_a,  l = |d|,  u = d / l                    cable direction, payload side
    T = max(0, k (l - L) + c dl/dt)                      tension (N), k = m (2 pi f_a)^2,
                                                         c = 2 zeta m (2 pi f_a)
    m dv/dt = m g - T u                                  payload (world)
    F_world = T u  at x_a;  tau_body = (r_a - c_com) x R^T (T u)    on the vehicle

Internal state (6 per simulation, world frame): payload position p (m) and velocity v (m/s),
integrated by the engines with the vehicle (``state_size`` hook of :mod:`.base`); it starts
hanging still below the attachment (the static stretch m g / k included), moving with it.

Checks (``tests/test_cable_payload.py``):

* static: hanging still, the tension is m g, so the vehicle hovers at the thrust of a rigid
  mass m at the attachment ((M + m) g): identical to ``mass_offset`` at low frequency;
* small swings of a vehicle of mass M holding its thrust (M + m) g, attachment at the CoM:
  horizontally M x'' = T theta ~ m g theta and m (x'' + L theta'') = -m g theta give
  omega^2 = g (M + m) / (M L), i.e. the period 2 pi sqrt(L M / ((M + m) g)), shorter than the
  fixed-pivot pendulum's 2 pi sqrt(L / g) because the vehicle swings back against the payload
  (L here is the stretched length L + m g / k).

Only the engines (:func:`quadsim.sim.engines.simulate`) carry the state; the flight
generator's accelerometer integrates it again along the flown trajectory
(:func:`quadsim.logs.generate.effect_states`), and the per-flight diagnosis integrates the
swing from the logged motion (:mod:`quadsim.gap.fitting`). Anything else that evaluates
``loads`` without it (``benchmarks.synthetic``, the residual wrench) gets a one-line
:class:`~quadsim.core.errors.ModelError` instead of a silent zero.

Parameters: ``mass`` (kg; 0 = off), ``length`` (m, rest length), ``x, y, z`` (m, attachment
in the body frame), ``axial_frequency`` (Hz, bounce frequency f_a of the payload on the cable;
real slings 5-30 Hz), ``damping_ratio`` (1, axial). Example:
``cable_payload:mass=0.1,length=0.5,z=-0.05`` is a 100 g load on a 0.5 m string 5 cm below
the testbed's body origin: it swings with a period of 2 pi sqrt(0.5006 * 0.838 / (0.938 *
9.81)) = 1.34 s.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ModelError
from ..core.frames import cross, quat_to_rotmat
from .base import EffectBase, EffectContext, EffectLoads, EffectParameter
from .facts import EffectFacts, Words, plus_minus

__all__ = ["CablePayload", "swing_period"]


def swing_period(length: float, payload_mass: float, vehicle_mass: float,
                 gravity: float = 9.81) -> float:
    """Small-swing period (s) of a payload below a free-floating vehicle holding its thrust:
    2 pi sqrt(L M / ((M + m) g)) (the fixed-pivot pendulum is the limit M -> infinity)."""
    return 2 * np.pi * np.sqrt(length * vehicle_mass / ((vehicle_mass + payload_mass) * gravity))


def _phrase(parameter, value, ci, params) -> str:
    """A slung payload's mass against the model's, or its cable and swing period."""
    if parameter == "mass":
        return (f"a {plus_minus(value, ci, 1e3)} g payload hanging on a cable "
                f"({100 * value / params.mass:+.1f} % of the model's {1e3 * params.mass:.4g} g)")
    period = 2 * np.pi * np.sqrt(max(value, 0.0) / params.gravity)
    return (f"cable {plus_minus(value, ci, 1.0, '.2g')} m long (the payload swings with a "
            f"period of about {period:.2g} s)")


class CablePayload(EffectBase):
    """Point payload on an elastic, taut-only cable (6 internal states)."""

    name = "cable_payload"
    parameters = (
        EffectParameter("mass", "kg", 0.0, 0.0, 10.0, "payload mass (0 = off)"),
        EffectParameter("length", "m", 1.0, 0.01, 10.0, "cable rest length"),
        EffectParameter("x", "m", 0.0, -1.0, 1.0, "attachment point, body x"),
        EffectParameter("y", "m", 0.0, -1.0, 1.0, "attachment point, body y"),
        EffectParameter("z", "m", 0.0, -1.0, 1.0, "attachment point, body z"),
        EffectParameter("axial_frequency", "Hz", 20.0, 1.0, 200.0,
                        "payload bounce frequency on the cable (sets the stiffness)"),
        EffectParameter("damping_ratio", "1", 0.3, 0.0, 2.0, "axial damping ratio"),
    )

    #: no candidate of its own: the payload's state is not logged; the diagnosis integrates
    #: the swing along the logged motion (its fit form, :mod:`quadsim.gap.fitting`)
    facts = EffectFacts(
        # the payload swings under the effective gravity at its mount, g - a = -R f: the
        # motion differentiated, or the accelerometer turned by the attitude or, with the
        # IMU alone, by the gyro's own frame (quadsim.gap.logcheck.posefree_states): no pose
        needs_pose=(),
        # its weight is read through the rotors' thrust, like a fixed payload's
        weighed=("mass",),
        words={"mass": Words("payload on a cable", "g", 1e3, _phrase),
               "length": Words("cable length", "m", 1.0, _phrase)},
    )

    @property
    def stiffness(self) -> float:
        """k (N/m)."""
        return self.mass * (2 * np.pi * self.axial_frequency) ** 2

    @property
    def damping(self) -> float:
        """c (N s/m)."""
        return 2 * self.damping_ratio * self.mass * 2 * np.pi * self.axial_frequency

    def state_size(self) -> int:
        return 6 if self.mass > 0.0 else 0

    def _attachment(self, position, velocity, quat, body_rate):
        rot = quat_to_rotmat(quat)
        arm = np.array([self.x, self.y, self.z])
        where = position + rot @ arm
        speed = velocity + np.einsum("bij,bj->bi", rot, cross(body_rate, arm[None]))
        return rot, where, speed

    def initial_state(self, params, vehicle: dict) -> np.ndarray:
        _, where, speed = self._attachment(vehicle["position"], vehicle["velocity"],
                                           vehicle["quat"], vehicle["body_rate"])
        drop = self.length + self.mass * params.gravity / self.stiffness
        payload = where - np.array([0.0, 0.0, drop])
        return np.concatenate([payload, speed], axis=1)

    def _tension(self, ctx: EffectContext):
        rot, where, speed = self._attachment(ctx.position, ctx.velocity, ctx.quat,
                                             ctx.body_rate)
        state = ctx.effect_state
        d = state[:, 0:3] - where
        length = np.linalg.norm(d, axis=1)
        u = d / length[:, None]
        stretch_rate = np.einsum("bi,bi->b", u, state[:, 3:6] - speed)
        tension = np.maximum(0.0, self.stiffness * (length - self.length)
                             + self.damping * stretch_rate)
        return rot, tension[:, None] * u      # force on the vehicle, world (N)

    def state_rate(self, ctx: EffectContext) -> np.ndarray:
        _, pull = self._tension(ctx)
        accel = -pull / self.mass
        accel[:, 2] -= ctx.params.gravity
        return np.concatenate([ctx.effect_state[:, 3:6], accel], axis=1)

    def loads(self, ctx: EffectContext) -> EffectLoads | None:
        if self.mass == 0.0:
            return None
        if ctx.effect_state is None or ctx.effect_state.shape[1] < 6:
            raise ModelError("cable_payload: needs its internal state (the swinging payload), "
                             "which only the engines integrate (quadsim.sim.engines.simulate, "
                             "and the flight generator along its flight); the inverse-dynamics "
                             "logs and the residual wrench cannot evaluate it (the per-flight "
                             "diagnosis fits it as quadsim.gap.fitting)")

        rot, pull = self._tension(ctx)
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.force_world = pull
        arm = np.array([self.x, self.y, self.z]) - ctx.params.com
        loads.torque_body = cross(arm[None], np.einsum("bji,bj->bi", rot, pull))
        return loads
