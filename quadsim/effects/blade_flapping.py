"""blade_flapping: the hub moment of flapping rotors, growing with airspeed and rotor speed.

In edgewise flow the advancing blade lifts more than the retreating one and each rotor disc
tilts away from the relative wind (first-harmonic longitudinal flapping, angle proportional
to the advance ratio). A rotor with stiff or offset hinges -- every small fixed-pitch
propeller -- transmits that tilt to the hub as a moment about the axis ``a_i x v_perp``,
which pitches the vehicle's nose up in forward flight and rolls it away from sideways
flight. To first order in the air speed (Mahony, Kumar & Corke, "Multirotor aerial
vehicles", IEEE RAM 2012, eq. 12-14; Bangura & Mahony, "Nonlinear dynamic modeling for high
performance control of a quadrotor", ACRA 2012)::

    v_perp,i = v - (v . a_i) a_i                       air velocity in rotor i's plane (body)
    tau      = -coefficient * sum_i Omega_i (a_i x v_perp,i)            body frame, N m

``coefficient`` in N m / ((rad/s)(m/s)) = kg m/rad. For rotors along body z the moment is
``coefficient * sum_i Omega_i * (v_y, -v_x, 0)``. It adds to the lever of the rotor-drag
force (:mod:`.rotor_drag`, applied at the hubs): a drag force acting a height h above the
CoM gives the same form with ``coefficient = h * k_drag``, so the two are told apart only
by the rotor-drag force itself.

Example: a 45 g Crazyflie at 1 m/s forward with four rotors at 2250 rad/s and coefficient
3e-8 kg m/rad gets a pitch moment of -2.7e-4 N m (11 rad/s^2 on Iyy = 2.4e-5 kg m^2).
The vehicle's angular rate is not included in the hub velocity, as in :mod:`.rotor_drag`.
"""

from __future__ import annotations

import numpy as np

from ..core.frames import rotate_inverse
from ..vehicle.params import hover_speed
from .base import EffectBase, EffectContext, EffectLoads, EffectParameter
from .facts import EffectFacts, Scale, Words, arm_length, plus_minus
from .rotor_drag import drag_scale

__all__ = ["BladeFlapping", "flapping_moment"]


def flapping_moment(air_velocity_body: np.ndarray, rotor_speed: np.ndarray,
                    rotor_axes: np.ndarray, coefficient: float) -> np.ndarray:
    """Total flapping moment (B, 3), body frame (N m), from the body-frame air velocity
    (B, 3), rotor speeds (B, R) (rad/s) and unit rotor axes (R, 3)."""
    axial = np.einsum("bk,rk->br", air_velocity_body, rotor_axes)          # (B, R)
    in_plane = air_velocity_body[:, None, :] - axial[..., None] * rotor_axes[None]
    tilt_axis = np.cross(rotor_axes[None], in_plane)                       # (B, R, 3)
    return -coefficient * np.einsum("br,brk->bk", np.asarray(rotor_speed, float), tilt_axis)


def _phrase(parameter, value, ci, params) -> str:
    """The nose-up moment per m/s of in-plane air speed at the hover speed."""
    hover, r = hover_speed(params), params.rotor_count
    moment = r * value * hover                       # N m per m/s of in-plane air speed
    cmoment = None if ci is None else r * ci * hover
    accel = moment / float(params.inertia[0, 0])
    return (f"blade flapping {plus_minus(moment, cmoment, 1e3, '.3g')} mN m of nose-up moment "
            f"per m/s of air speed at the hover speed ({accel:.3g} rad/s² of roll/pitch "
            "acceleration at 1 m/s)")


class BladeFlapping(EffectBase):
    """Hub moment of flapping rotors, linear in the in-plane air speed and the rotor speed."""

    name = "blade_flapping"
    parameters = (
        EffectParameter("coefficient", "kg m/rad", 0.0, -1e-4, 1e-4,
                        "hub moment per rotor speed per in-plane air speed, "
                        "N m/((rad/s)(m/s)); positive pitches the nose up in forward flight"),
    )

    #: a flapping moment as if the rotor-drag force acted half an arm above the CoM
    facts = EffectFacts(
        # tilt of the rotor disc with the air velocity in the body frame
        needs_pose=("velocity", "attitude"),
        fitted=("coefficient",),
        scales={"coefficient": Scale(lambda p: 0.5 * arm_length(p) * drag_scale(p),
                                     "the rotor drag's force acting half an arm above the CoM")},
        words={"coefficient": Words("blade flapping", "kg m/rad", 1.0, _phrase)},
    )

    def loads(self, ctx: EffectContext) -> EffectLoads | None:
        if self.is_off():
            return None
        air_body = rotate_inverse(ctx.quat, ctx.air_velocity)
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.torque_body = flapping_moment(air_body, ctx.rotor_speed, ctx.params.rotor_axes,
                                            self.coefficient)
        return loads
