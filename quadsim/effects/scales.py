"""Sizes of a vehicle that effects' diagnosis facts are stated in (:mod:`.facts`): its arm,
its hover thrust per rad/s, and the momentum-theory rate damping and translational lift.
Each takes a :class:`~quadsim.vehicle.params.VehicleParams` and returns SI units."""

from __future__ import annotations

import math

import numpy as np

from ..vehicle.params import VehicleParams, hover_speed

__all__ = ["arm_length", "hover_thrust_per_speed", "momentum_rate_damping",
           "momentum_translational_lift"]


def arm_length(params: VehicleParams) -> float:
    """The largest horizontal hub distance from the body origin (m): the vehicle's arm."""
    return float(np.max(np.linalg.norm(params.rotor_positions[:, :2], axis=1)))


def hover_thrust_per_speed(params: VehicleParams) -> float:
    """The hover thrust per rad/s of hover speed, ``b Omega_h`` (N s/rad): the unit of a
    thrust curve's linear term (plausible-range kind ``hover``)."""
    return params.thrust_factor * hover_speed(params)


def momentum_rate_damping(params: VehicleParams) -> float:
    """k_mt = r^2 T_h / v_i (N m s/rad): roll/pitch damping of the rotor discs' inflow change
    by momentum theory (r the largest hub distance from the centre, m; T_h = m g / R the hover
    thrust per rotor, N; v_i = sqrt(T_h / (2 rho pi R_p^2)) the hover induced velocity, m/s)."""
    arm = float(np.max(np.linalg.norm(params.rotor_positions[:, :2], axis=1)))
    thrust = params.mass * params.gravity / params.rotor_count
    induced = np.sqrt(thrust / (2 * params.air_density * np.pi * params.rotor_radius ** 2))
    return arm ** 2 * thrust / float(induced)


def momentum_translational_lift(params: VehicleParams) -> float:
    """k_tl = T_h / (4 v_i^2) (kg/m): the translational-lift coefficient of momentum theory
    (T_h the hover thrust per rotor, N; v_i^2 = T_h / (2 rho pi R_p^2) the hover induced
    velocity squared), which is k_tl = rho pi R_p^2 / 2 (rho the air density, kg/m^3; R_p
    the rotor radius, m)."""
    return 0.5 * params.air_density * math.pi * params.rotor_radius ** 2
