"""gyroscopic: torques from the spinning rotors' angular momentum (rotor inertia Jr).

Each rotor (spin s_i = +1 ccw, speed Omega_i, unit axis a_i in the body frame) carries the
angular momentum h_i = Jr s_i Omega_i a_i. Euler's equations of the body with its rotors,
I dw/dt + w x I w + sum_i (w x h_i + dh_i/dt) = tau, give the body the extra torque.

Formula (body frame, N m)::

    tau_gyro  = -Jr * sum_i s_i Omega_i (w x a_i)        gyroscopic (precession) torque
    tau_spin  = -Jr * sum_i s_i dOmega_i/dt a_i          reaction to spinning a rotor up

(Bouabdallah, Murrieri & Siegwart, "Design and control of an indoor micro quadrotor",
ICRA 2004, eq. for the rotor gyro effect; Mahony, Kumar & Corke, IEEE RAM 2012, sec. on
rotor dynamics). The spin-up term needs rotor-speed dynamics (e.g. ``motor_lag``); with
rotors that follow their commands at once dOmega/dt is zero inside each hold interval.

Example::

    >>> from quadsim.effects.gyroscopic import Gyroscopic
    >>> gyro = Gyroscopic(rotor_inertia=6e-5)          # kg m^2, rotor + motor bell
    >>> gyro = Gyroscopic.from_params(params)          # Jr from params.rotor_inertia

``rotor_inertia = 0`` (the default) switches the effect off.
"""

from __future__ import annotations

import numpy as np

from ..core.frames import cross_rolled, rolled
from ..vehicle.params import VehicleParams
from .base import EffectBase, EffectContext, EffectLoads, EffectParameter
from .facts import EffectFacts, Scale, Spread, Words, plus_minus

__all__ = ["Gyroscopic", "gyroscopic_torque"]


def gyroscopic_torque(rotor_inertia: float, body_rate: np.ndarray, rotor_speed: np.ndarray,
                      rotor_accel: np.ndarray, axes: np.ndarray, spins: np.ndarray
                      ) -> np.ndarray:
    """Body-frame torque (B, 3) (N m) for body rates (B, 3), rotor speeds and accelerations
    (B, R), rotor axes (R, 3) and spin signs (R,)."""
    signed = np.asarray(spins, dtype=float)[:, None] * np.asarray(axes, dtype=float)  # s_i a_i
    momentum_axis = rotor_speed @ signed                                # sum s_i Omega_i a_i
    spin_up = rotor_accel @ signed
    gyro = cross_rolled(rolled(np.asarray(body_rate, dtype=float)),
                        rolled(momentum_axis))                          # w x h
    return -rotor_inertia * (gyro + spin_up)


def _phrase(parameter, value, ci, params) -> str:
    return f"rotor spin inertia {plus_minus(value, ci, 1e7)} g cm² per rotor (gyroscopic torque)"


class Gyroscopic(EffectBase):
    """Rotor gyroscopic and spin-up reaction torques."""

    name = "gyroscopic"
    parameters = (
        EffectParameter("rotor_inertia", "kg m^2", 0.0, 0.0, 1e-3,
                        "spin inertia Jr of one rotor + motor bell about its axis (0 = off)"),
    )

    facts = EffectFacts(
        fitted=("rotor_inertia",),
        scales={"rotor_inertia": Scale(lambda p: 1e-6 * (p.mass / 0.04) ** 1.7,
                                       "rotor and motor bell: 0.01 g cm^2 x (m / 40 g)^1.7")},
        spreads={"rotor_inertia": Spread(lambda p: 1e-6 * (p.mass / 0.04) ** 1.7,
                                         "rotor+motor inertia: the fit's typical size")},
        words={"rotor_inertia": Words("rotor spin inertia", "g cm^2", 1e7, _phrase)},
    )

    @classmethod
    def from_params(cls, params: VehicleParams) -> Gyroscopic:
        """The effect with Jr taken from the parameter set (``[rotors] inertia``)."""
        return cls(rotor_inertia=params.rotor_inertia)

    #: (context fields, vehicle attributes) ``loads`` reads (:attr:`EffectBase.loads_reads`)
    loads_reads = (("rotor_speed", "rotor_accel"), ("rotor_axes", "rotor_spins"))

    def loads(self, ctx: EffectContext) -> EffectLoads | None:
        if self.rotor_inertia == 0.0:
            return None
        batch, rotors = ctx.rotor_speed.shape
        loads = EffectLoads.neutral(batch, rotors)
        loads.torque_body = gyroscopic_torque(self.rotor_inertia, ctx.body_rate,
                                              ctx.rotor_speed, ctx.rotor_accel,
                                              ctx.params.rotor_axes, ctx.params.rotor_spins)
        return loads
