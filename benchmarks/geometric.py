"""The flights' controller and motors of the simulator sources whose simulator has none of
its own (:mod:`.qcsim_source`, :mod:`.genesis_source`): a geometric tracking controller on
SE(3) with integral terms, and a DC motor driven by a duty cycle.

DC motor (:class:`DCMotor`): ``J dOmega/dt = k_t (c V - k_e Omega) / R - d Omega^2`` with the
duty cycle c in 0..1 of the battery voltage V, k_t = k_e (SI: V s/rad = N m/A), the winding
resistance R (ohm), the rotor and propeller's spin inertia J (kg m^2) and the propeller's
drag torque factor d (N m s^2/rad^2). The current may turn negative (an ESC with active
braking): spin-up and spin-down alike. In steady state ``k_t (c V - k_e W) / R = d W^2``;
linearised about W the time constant is ``J / (k_t k_e / R + 2 d W)``; a propeller with d x
(1 + x) spins (1 + x)^-alpha as fast at the same duty (its lighter load).

Controller (:class:`Geometric`): Lee, Leok & McClamroch, "Geometric tracking control of a
quadrotor UAV on SE(3)", CDC 2010, with integral terms on the position and attitude errors
(Goodarzi, Lee & Lee, "Geometric nonlinear PID control of a quadrotor UAV on SE(3)", ECC
2013); tuned by natural frequencies on the nominal vehicle's mass and inertia, blind to
every case effect. Force and moments are allocated to the rotors by the nominal layout's
mixer (:func:`quadsim.vehicle.rotors.mixer`), each rotor's speed to a command by the
source's ``command_for`` (the nominal motor's steady map).

Example::

    >>> motor = DCMotor(battery=11.1, k_emf=0.0251, resistance=0.12, inertia=1.2e-4)
    >>> motor.duty_for(221.5, k_drag=7.5e-7)        # 0.517
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from quadsim.core.frames import quat_to_rotmat
from quadsim.vehicle.params import VehicleParams
from quadsim.vehicle.rotors import mixer

__all__ = ["DCMotor", "Geometric"]


@dataclass(frozen=True)
class DCMotor:
    """A DC motor (module doc): battery (V), k_emf (V s/rad = N m/A), resistance (ohm),
    inertia (kg m^2, rotor and propeller)."""

    battery: float
    k_emf: float
    resistance: float
    inertia: float

    def steady_speed(self, duty, k_drag: float) -> np.ndarray:
        """Steady speed (rad/s) at duty cycle ``duty`` (0..1): the root W >= 0 of ``k_t (c V
        - k_e W) / R = d W^2``."""
        c = np.clip(np.asarray(duty, dtype=float), 0.0, 1.0)
        slope = self.k_emf ** 2 / self.resistance
        drive = self.k_emf * c * self.battery / self.resistance
        return (-slope + np.sqrt(slope * slope + 4 * k_drag * drive)) / (2 * k_drag)

    def duty_for(self, speed, k_drag: float) -> np.ndarray:
        """The duty cycle whose steady speed is ``speed`` (rad/s): ``(k_e W + R d W^2 / k_t) /
        V``, clipped to 0..1."""
        w = np.asarray(speed, dtype=float)
        volts = self.k_emf * w + self.resistance * k_drag * w * w / self.k_emf
        return np.clip(volts / self.battery, 0.0, 1.0)

    def acceleration(self, speed, duty, k_drag, inertia: float | None = None) -> np.ndarray:
        """dOmega/dt (rad/s^2): ``(k_t (c V - k_e W) / R - d W^2) / J``; ``k_drag`` per rotor,
        ``inertia`` J (default: the motor's)."""
        current = (duty * self.battery - self.k_emf * speed) / self.resistance
        j = self.inertia if inertia is None else inertia
        return (self.k_emf * current - k_drag * speed * speed) / j

    def time_constant(self, speed: float, k_drag: float, slow: float = 1.0) -> float:
        """The time constant (s) linearised at ``speed``: ``J / (k_t k_e / R + 2 d W)``, J x
        ``slow``."""
        return float(self.inertia * slow / (self.k_emf ** 2 / self.resistance
                                             + 2 * k_drag * speed))

    def alpha(self, speed: float, k_drag: float, change: float) -> float:
        """The speed-per-duty exponent of a propeller change (quadsim's
        ``thrust_factor.alpha``): at the duty whose steady speed is ``speed``, d x (1 +
        change) spins (1 + change)^-alpha as fast."""
        duty = self.duty_for(speed, k_drag)
        ratio = float(self.steady_speed(duty, k_drag * (1 + change))
                      / self.steady_speed(duty, k_drag))
        return float(np.clip(-np.log(ratio) / np.log1p(change), 0.0, 0.5))


def _vee(m: np.ndarray) -> np.ndarray:
    return np.array([m[2, 1], m[0, 2], m[1, 0]])


class Geometric:
    """The controller (module doc) for the nominal ``vehicle``; ``command_for`` maps rotor
    speeds (rad/s) to commands. :meth:`step` takes the CoM position, world velocity,
    quaternion (w-first), body rate and the path's setpoints (position, velocity,
    acceleration, yaw, yaw rate); it returns the commands (R,)."""

    # position: natural frequency 2 rad/s, damping 0.9, integral 0.5 (1/s^3 x m); attitude:
    # 10 rad/s on roll and pitch, 5 on yaw, damping 0.8, integral 2 (1/s)
    W_POS, Z_POS, KI_POS = 2.0, 0.9, 0.5
    W_ATT, Z_ATT, KI_ATT = np.array([10.0, 10.0, 5.0]), 0.8, 2.0
    MAX_TILT = 0.5                                               # rad
    #: the attitude integral's clip (rad s): holds a CoM offset of 15 % of the arm
    HOLD_ARM = 0.15

    def __init__(self, dt: float, vehicle: VehicleParams,
                 command_for: Callable[[np.ndarray], np.ndarray]):
        self.dt, self.vehicle, self.command_for = dt, vehicle, command_for
        self.mass, self.inertia = vehicle.mass, np.asarray(vehicle.inertia, dtype=float)
        j = np.diag(self.inertia)
        self.k_x = self.mass * self.W_POS ** 2
        self.k_v = self.mass * 2 * self.Z_POS * self.W_POS
        self.k_r = j * self.W_ATT ** 2
        self.k_w = j * 2 * self.Z_ATT * self.W_ATT
        # [thrust, roll, pitch, yaw torque] -> squared rotor speeds, from the layout
        self.unmix = mixer(vehicle)
        self.i_pos = np.zeros(3)
        self.i_att = np.zeros(3)
        arm = float(np.max(np.hypot(vehicle.rotor_positions[:, 0],
                                    vehicle.rotor_positions[:, 1])))
        hold = self.HOLD_ARM * self.mass * vehicle.gravity * arm
        self.i_att_max = np.maximum(0.2, hold / (self.k_r * self.KI_ATT))

    def step(self, pos, vel, quat, rate, sp_pos, sp_vel, sp_acc, sp_yaw, sp_yaw_rate
             ) -> np.ndarray:
        e_x, e_v = pos - sp_pos, vel - sp_vel
        self.i_pos = np.clip(self.i_pos + e_x * self.dt, -1.0, 1.0)
        force = (-self.k_x * e_x - self.k_v * e_v - self.KI_POS * self.mass * self.i_pos
                 + self.mass * (sp_acc + np.array([0.0, 0.0, self.vehicle.gravity])))
        horizontal, limit = np.hypot(*force[:2]), force[2] * np.tan(self.MAX_TILT)
        if horizontal > limit:
            force[:2] *= limit / horizontal
        rot = quat_to_rotmat(quat)
        b3 = force / np.linalg.norm(force)
        b2 = np.cross(b3, [np.cos(sp_yaw), np.sin(sp_yaw), 0.0])
        b2 /= np.linalg.norm(b2)
        r_d = np.column_stack([np.cross(b2, b3), b2, b3])
        e_r = 0.5 * _vee(r_d.T @ rot - rot.T @ r_d)
        e_w = rate - rot.T @ r_d @ np.array([0.0, 0.0, sp_yaw_rate])
        self.i_att = np.clip(self.i_att + e_r * self.dt, -self.i_att_max, self.i_att_max)
        moment = (-self.k_r * e_r - self.k_w * e_w - self.k_r * self.KI_ATT * self.i_att
                  + np.cross(rate, self.inertia @ rate))
        thrust = float(force @ rot[:, 2])
        squared = np.clip(self.unmix @ np.concatenate([[thrust], moment]), 0.0, None)
        return self.command_for(np.sqrt(squared))
