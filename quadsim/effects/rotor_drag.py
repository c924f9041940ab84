"""rotor_drag: induced drag and blade flapping, linear in air velocity, proportional to speed.

Formula (rotor i with unit axis a_i, speed Omega_i, hub at r_i - c from the CoM; v the
vehicle's air velocity in the body frame, i.e. vehicle velocity minus wind, rotated into body
axes; w the body rate)::

    u_i    = v + w x (r_i - c)                      the hub's air velocity
    u_perp = u_i - (u_i . a_i) a_i                  air velocity in the rotor plane
    F_i    = -coefficient * Omega_i * u_perp - axial_coefficient * Omega_i * (u_i . a_i) a_i

acting at the rotor hub (so it also makes a torque (r_i - c) x F_i about the CoM). The sum
over rotors is the well-known linear rotor-drag model ``F = -k (sum_i Omega_i) v_perp``:
Faessler, Franchi & Scaramuzza, "Differential flatness of quadrotor dynamics subject to rotor
drag for accurate tracking of high-speed trajectories" (RA-L 2018), eq. 4, and Kai, Allibert,
Hua & Hamel, "Nonlinear feedback control of quadrotors exploiting first-order drag effects"
(IFAC 2017). Förster (ETH 2015) identifies for the Crazyflie 2.0 ``k_xy = 9.18e-7``,
``k_z = 1.03e-6 kg/rad`` (N per (rad/s)(m/s)).

Units of both coefficients: N / ((rad/s) (m/s)) = kg/rad. Example at 5 m/s forward for the
0.84 kg testbed at hover (4 x 460 rad/s) with coefficient 1e-5: F_x = -0.092 N.
The hub velocity includes the rotation, w x (r_i - c), as in RotorPy's rotor drag (Folk et
al. 2023, ``compute_body_wrench``: local airspeeds ``v + w x r_i``): the published
body-velocity model drops it, which is fair at speed but not while yawing near hover, where
each hub moves at |w| |r| (a Crazyflie yawing at 2 rad/s: 0.09 m/s) and the in-plane drag
then damps the yaw, ``tau_z = -coefficient sum_i Omega_i |r_i - c|^2 w_z`` for arms in the
rotor plane.

Evaluated as sums over the rotors (the same loads, no per-rotor arrays), with
``R_i = r_i - c``, ``S = sum_i Omega_i R_i`` and ``p_i = Omega_i (u_i . a_i)``
(``u_i . a_i = v . a_i + w . (R_i x a_i)``)::

    F   = -coefficient ((sum_i Omega_i) v + w x S) + (coefficient - axial) sum_i p_i a_i
    tau = -coefficient (S x v + w sum_i Omega_i |R_i|^2 - sum_i Omega_i (w . R_i) R_i)
          + (coefficient - axial) sum_i p_i R_i x a_i
"""

from __future__ import annotations

import numpy as np

from ..core.frames import cross_rolled, rolled
from ..vehicle.params import hover_speed
from .base import EffectBase, EffectLoads, EffectParameter
from .facts import ALL, EffectFacts, Scale, Spread, Words, plus_minus

__all__ = ["RotorDrag", "drag_scale", "rotor_drag_forces"]


def rotor_drag_forces(air_velocity_body: np.ndarray, rotor_speed: np.ndarray,
                      rotor_axes: np.ndarray, coefficient: float,
                      axial_coefficient: float, body_rate: np.ndarray | None = None,
                      arms: np.ndarray | None = None) -> np.ndarray:
    """Per-rotor drag forces (B, R, 3), body frame (N), from the body-frame air velocity
    (B, 3), rotor speeds (B, R) (rad/s) and unit axes (R, 3); with ``body_rate`` (B, 3)
    (rad/s) and ``arms`` (R, 3) (hubs from the CoM, m) the hubs' air velocity includes the
    rotation (module doc)."""
    hub = np.repeat(air_velocity_body[:, None, :], len(rotor_axes), axis=1)   # (B, R, 3)
    if body_rate is not None:
        hub = hub + np.cross(body_rate[:, None, :], arms[None])
    axial = np.einsum("brk,rk->br", hub, rotor_axes)                     # (B, R)
    along = axial[..., None] * rotor_axes[None]                          # (B, R, 3)
    in_plane = hub - along
    speed = np.asarray(rotor_speed, dtype=float)[..., None]
    return -speed * (coefficient * in_plane + axial_coefficient * along)


def drag_scale(params) -> float:
    """A rotor-drag coefficient (kg/rad) giving 10 % of the weight at 2 m/s with four hover
    rotors: ``0.1 m g / (R Omega_h 2 m/s)``, Omega_h = sqrt(m g / (R b))."""
    hover = np.sqrt(params.weight / (params.rotor_count * params.thrust_factor))
    return 0.1 * params.weight / (params.rotor_count * hover * 2.0)


def _phrase(parameter, value, ci, params) -> str:
    """The drag force per m/s of air speed at the hover speed, all rotors."""
    where = "in the rotor plane" if parameter == "coefficient" else "along the rotor axes"
    hover, r = hover_speed(params), params.rotor_count
    per = r * value * hover
    cper = None if ci is None else r * ci * hover
    return (f"rotor drag {where} {plus_minus(per, cper, 1e3)} mN per m/s of air speed at the "
            f"hover speed ({100 * per / (params.mass * params.gravity):.2g} % of the weight at "
            "1 m/s)")


class RotorDrag(EffectBase):
    """Linear rotor drag (induced drag + blade flapping), per rotor, at the hubs."""

    name = "rotor_drag"
    parameters = (
        EffectParameter("coefficient", "kg/rad", 0.0, 0.0, 1e-3,
                        "in-plane drag per rotor speed per air speed, N/((rad/s)(m/s))"),
        EffectParameter("axial_coefficient", "kg/rad", 0.0, 0.0, 1e-3,
                        "drag along the rotor axis per rotor speed per air speed"),
    )

    facts = EffectFacts(
        needs_pose=("velocity", "attitude"),   # drag of the air velocity in the rotor plane
        fitted=("coefficient", "axial_coefficient"),
        scales={ALL: Scale(drag_scale, "10 % of the weight at 2 m/s with four hover rotors")},
        spreads={ALL: Spread(drag_scale, "10 % of the weight at 2 m/s: a doubled drag")},
        separate_from={
            "body_drag": "fly at several speeds: rotor drag is linear in speed, body drag "
                         "quadratic",
            "wind": "fly the same path in both directions (wind is fixed in the world frame)"},
        words={"coefficient": Words("rotor drag in the rotor plane", "kg/rad", 1.0, _phrase),
               "axial_coefficient": Words("rotor drag along the rotor axes", "kg/rad", 1.0,
                                          _phrase)},
    )

    #: (context fields, vehicle attributes) ``loads`` reads (:attr:`EffectBase.loads_reads`)
    loads_reads = (("air_velocity", "rotor_speed"),
                   ("rotor_axes", "rotor_positions", "com"))

    #: speed-independent parts kept per flight (:meth:`_geometry`): the air velocities and
    #: vehicles a fit's last evaluations used
    KEPT_GEOMETRY = 8

    def loads(self, ctx):
        """The sums over rotors of :func:`rotor_drag_forces` and of their torques, through
        sums of rotor speeds (module doc): the same loads without the per-rotor (B, R, 3)
        arrays (the gap fits evaluate this thousands of times per flight)."""
        c, k = self.coefficient, self.axial_coefficient
        air_body, axes, arms, lever, along, turn, reach, air_rolled, rate_rolled = \
            self._geometry(ctx)
        speed = np.asarray(ctx.rotor_speed, dtype=float)
        rate = np.asarray(ctx.body_rate, dtype=float)
        axial = speed * along                                 # p_i = Omega_i (u_i . a_i)
        moment = speed @ arms                                 # S, (B, 3)
        moment_rolled = rolled(moment)
        force = (-c * (np.add.reduce(speed, axis=1)[:, None] * air_body    # speed.sum(1)
                       + cross_rolled(rate_rolled, moment_rolled))
                 + (c - k) * (axial @ axes))
        spin = (speed * turn) @ arms                          # sum_i Omega_i (w . R_i) R_i
        torque = (-c * (cross_rolled(moment_rolled, air_rolled)
                        + rate * (speed @ reach)[:, None] - spin)
                  + (c - k) * (axial @ lever))
        batch, rotors = speed.shape
        loads = EffectLoads.neutral(batch, rotors)
        loads.force_world = ctx.to_world(force)
        loads.torque_body = torque
        return loads

    @staticmethod
    def _geometry(ctx) -> tuple:
        """What :meth:`loads` takes from the motion, the air velocity and the vehicle, not
        from the rotor speeds: the body-frame air velocity (B, 3), the rotor axes a_i (R, 3),
        the arms R_i = r_i - c (R, 3), R_i x a_i (R, 3), u_i . a_i = v . a_i + w . (R_i x a_i)
        (B, R), w . R_i (B, R), |R_i|^2 (R,) and the body-frame air velocity and the body
        rate :func:`quadsim.core.frames.rolled` (the factors of their cross products). With
        a ``ctx.flight_memo`` (the gap fits, which read the rotor speeds at many delays on
        one flight's motion) the last
        :data:`KEPT_GEOMETRY` used are kept per air-velocity array, rotors and CoM (what they
        read of the vehicle: a fit that moves its mass or inertia shares them; the same
        numbers, computed once)."""
        memo, params = ctx.flight_memo, ctx.params
        store = None if memo is None else memo.setdefault("rotor_drag.geometry", {})
        key = (id(ctx.air_velocity), id(params.rotors),
               np.asarray(params.com, dtype=float).tobytes())
        hit = None if store is None else store.pop(key, None)
        if hit is not None:
            store[key] = hit                # the most recently used last
            if hit[0][0] is ctx.air_velocity and hit[0][1] is params.rotors:
                return hit[1]
        air_body = ctx.to_body(ctx.air_velocity)
        axes = params.rotor_axes
        arms = params.rotor_positions - params.com
        rate = np.asarray(ctx.body_rate, dtype=float)
        lever = cross_rolled(rolled(arms), rolled(axes))      # R_i x a_i, (R, 3)
        value = (air_body, axes, arms, lever, air_body @ axes.T + rate @ lever.T,
                 rate @ arms.T, np.sum(arms ** 2, axis=1), rolled(air_body), rolled(rate))
        if store is not None:
            if len(store) >= RotorDrag.KEPT_GEOMETRY:
                del store[next(iter(store))]
            store[key] = ((ctx.air_velocity, params.rotors), value)
        return value
