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
    tau      = -k sum_i Omega_i (a_i x v_perp,i)         body frame, N m (one k, both axes)

Per axis (``roll``, ``pitch``; kg m/rad = N m / ((rad/s)(m/s)))::

    tau = -diag(roll, pitch, (roll + pitch)/2) sum_i Omega_i (a_i x v_perp,i)   body frame, N m

For rotors along body z the moment is ``sum_i Omega_i * (roll v_y, -pitch v_x, 0)``: ``roll``
rolls the vehicle away from sideways air speed, ``pitch`` pitches the nose up in forward air
speed. The z row (non-zero only for canted rotors) takes the mean of the two. A symmetric
rotor gives one value for both axes; a real frame need not (the nano-drone logs read pitch
1.3-1.7 times roll, docs/nanodrone.md). ``coefficient`` is the single-coefficient form of
older effect files: it acts on both axes, added to ``roll`` and ``pitch`` (a file that gives
only ``coefficient = k`` is ``roll = pitch = k``, the same numbers as before the split).

The moment adds to the lever of the rotor-drag force (:mod:`.rotor_drag`, applied at the
hubs): a drag force acting a height h above the CoM gives the same form with both axes equal
to ``h * k_drag``, so the two are told apart only by the rotor-drag force itself.

Example: a 45 g Crazyflie at 1 m/s forward with four rotors at 2250 rad/s and pitch
3e-8 kg m/rad gets a pitch moment of -2.7e-4 N m (11 rad/s^2 on Iyy = 2.4e-5 kg m^2).
The vehicle's angular rate is not included in the hub velocity, as in :mod:`.rotor_drag`.
"""

from __future__ import annotations

import numpy as np

from ..core.frames import cross, rotate_inverse
from ..vehicle.params import hover_speed
from .base import EffectBase, EffectContext, EffectLoads, EffectParameter
from .facts import (
    EffectFacts,
    PlausibleRange,
    Reading,
    Scale,
    Spread,
    Words,
    arm_length,
    plus_minus,
)
from .rotor_drag import drag_scale

__all__ = ["BladeFlapping", "flapping_moment"]


def flapping_moment(air_velocity_body: np.ndarray, rotor_speed: np.ndarray,
                    rotor_axes: np.ndarray, roll: float,
                    pitch: float | None = None) -> np.ndarray:
    """Total flapping moment (B, 3), body frame (N m), from the body-frame air velocity
    (B, 3), rotor speeds (B, R) (rad/s), unit rotor axes (R, 3) and the roll and pitch
    coefficients (kg m/rad; ``pitch`` None: equal to ``roll``, the one-coefficient form):
    ``-diag(roll, pitch, (roll + pitch)/2) sum_i Omega_i (a_i x v_perp,i)`` (module doc)."""
    pitch = roll if pitch is None else pitch
    axial = np.einsum("bk,rk->br", air_velocity_body, rotor_axes)          # (B, R)
    in_plane = air_velocity_body[:, None, :] - axial[..., None] * rotor_axes[None]
    tilt_axis = cross(rotor_axes[None], in_plane)                          # (B, R, 3)
    gains = np.array([roll, pitch, 0.5 * (roll + pitch)])
    return -gains * np.einsum("br,brk->bk", np.asarray(rotor_speed, float), tilt_axis)


def _per_unit_air_speed(value, ci, params, axis: int = 0) -> tuple[float, float | None, float]:
    """The moment (N m) per m/s of in-plane air speed at the hover speed, its 95 % half-width
    and the angular acceleration it gives on the inertia of body ``axis`` (rad/s^2)."""
    hover, r = hover_speed(params), params.rotor_count
    moment = r * value * hover
    cmoment = None if ci is None else r * ci * hover
    return moment, cmoment, moment / float(params.inertia[axis, axis])


#: what a reading of each parameter moves, and the body axis of its inertia
_WHAT = {"roll": ("roll moment away from sideways", 0), "pitch": ("nose-up moment per forward", 1),
         "coefficient": ("roll and pitch moment per in-plane", 0)}


def _phrase(parameter, value, ci, params) -> str:
    """The roll-away or nose-up moment per m/s of in-plane air speed at the hover speed."""
    what, axis = _WHAT[parameter]
    moment, cmoment, accel = _per_unit_air_speed(value, ci, params, axis)
    return (f"blade flapping {plus_minus(moment, cmoment, 1e3, '.3g')} mN m of {what} air "
            f"speed per m/s at the hover speed ({accel:.3g} rad/s² at 1 m/s)")


def _scale(params) -> float:
    """A flapping coefficient (kg m/rad) as if the rotor drag's force
    (:func:`.rotor_drag.drag_scale`) acted half an arm above the CoM."""
    return 0.5 * arm_length(params) * drag_scale(params)


_SCALE = Scale(_scale, "the rotor drag's force acting half an arm above the CoM")
#: coefficient / (b Omega_hover) is the lever (m) at which one rotor's hover thrust gives its
#: flapping moment per m/s of air speed: a fraction f of the weight x arm per m/s is f x arm.
_RANGE = PlausibleRange(
    0.0, 0.03, "hover",
    "0-10 % of the weight x arm per m/s of air speed for arms up to 0.3 m: the outside "
    "simulators' flapping draws 2-4 % (benchmarks/draws.py, after Mahony et al., IEEE RAM "
    "2012), two Crazyflie 2.1 Brushless logs 3-5 % (docs/nanodrone.md); a negative "
    "coefficient tilts the discs into the wind")
_SPREAD = Spread(_scale, "the rotor drag's force half an arm above the CoM: about 2-3 % of "
                         "the weight x arm per m/s, the size real small rotors show")


class BladeFlapping(EffectBase):
    """Hub moment of flapping rotors, linear in the in-plane air speed and the rotor speed,
    with its own coefficient per body axis (roll, pitch; module doc)."""

    name = "blade_flapping"
    parameters = (
        EffectParameter("roll", "kg m/rad", 0.0, -1e-4, 1e-4,
                        "roll moment per rotor speed per in-plane air speed, "
                        "N m/((rad/s)(m/s)); positive rolls away from sideways flight"),
        EffectParameter("pitch", "kg m/rad", 0.0, -1e-4, 1e-4,
                        "pitch moment per rotor speed per in-plane air speed, "
                        "N m/((rad/s)(m/s)); positive pitches the nose up in forward flight"),
        EffectParameter("coefficient", "kg m/rad", 0.0, -1e-4, 1e-4,
                        "the single-coefficient form of older files: added to roll and "
                        "pitch alike"),
    )

    facts = EffectFacts(
        # tilt of the rotor disc with the air velocity in the body frame
        needs_pose=("velocity", "attitude"),
        fitted=("roll", "pitch"),
        # one per-flight reading, both axes free (quadsim.gap.explanations)
        readings=(Reading(("roll", "pitch")),),
        scales={"roll": _SCALE, "pitch": _SCALE, "coefficient": _SCALE},
        ranges={"roll": _RANGE, "pitch": _RANGE},
        spreads={"roll": _SPREAD, "pitch": _SPREAD},
        words={"roll": Words("blade flapping (roll)", "kg m/rad", 1.0, _phrase),
               "pitch": Words("blade flapping (pitch)", "kg m/rad", 1.0, _phrase),
               "coefficient": Words("blade flapping", "kg m/rad", 1.0, _phrase)},
    )

    @property
    def axes(self) -> tuple[float, float]:
        """The (roll, pitch) coefficients that act (kg m/rad): each axis' own plus the
        single-coefficient form's ``coefficient``."""
        return (self.roll + self.coefficient, self.pitch + self.coefficient)

    def loads(self, ctx: EffectContext) -> EffectLoads | None:
        if self.is_off():
            return None
        air_body = rotate_inverse(ctx.quat, ctx.air_velocity)
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        roll, pitch = self.axes
        loads.torque_body = flapping_moment(air_body, ctx.rotor_speed, ctx.params.rotor_axes,
                                            roll, pitch)
        return loads
