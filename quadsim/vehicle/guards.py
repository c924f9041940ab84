"""Physical feasibility of a vehicle: refuse a parameter set (or a CAD build) that cannot fly.

Loaders check units, shapes and that the inertia is a rigid body's; this layer checks that the
numbers belong to *one flyable vehicle*. A grams-for-kilograms or millimetres-for-metres slip
passes every unit check but breaks a ratio by a factor 1000, so every test here is a
dimensionless ratio of the vehicle's own numbers, never a fixed limit on one number:

* **lift** -- thrust-to-weight ``T/W = b Omega_max^2 sum(a_z) / (m g)`` must lie in
  ``[MIN_THRUST_TO_WEIGHT, MAX_THRUST_TO_WEIGHT]`` = [1.2, 40]: below 1.2 the rotors cannot
  hover with a control margin (the 837.667 kg grams slip gives 0.0027); above 40 no
  multirotor exists (racing quads reach ~15) and a slip is far more likely. Equivalently the
  hover control ``Omega_h^2 = m g / (b sum a_z)`` (rad^2/s^2, the MJCF actuator control)
  must lie inside the actuator's ``ctrlrange`` ``[Omega_min^2, Omega_max^2]`` with that
  margin.
* **size** -- radius of gyration ``k_i = sqrt(I_ii / m)`` against the arm length ``L`` (largest
  hub distance from the CoM): ``MIN_GYRATION_RATIO <= k_i / L <= MAX_GYRATION_RATIO``
  = [0.05, 1.5] (measured: Crazyflie 0.47/0.47/0.57, the 0.84 kg testbed 0.43/0.43/0.58; a
  thin ring of radius L gives at most 1). Mass in grams or inertia in g mm^2 moves k/L by
  ~30 or 1000.
* **propellers** -- two neighbouring propellers may not overlap: ``2 r <= 1.2 d_min``
  (nearest hub distance), and the blade tip speed ``Omega_max r`` stays below
  ``MAX_TIP_MACH`` = 0.9 of the speed of sound (343 m/s): an RPM value stored as rad/s
  (x 9.55) pushes a Crazyflie from 76 m/s to 720 m/s.

* **propeller torque** -- the hover figure of merit ``FM = b^1.5 / (d sqrt(2 rho pi r^2))``
  that b, d and the radius imply must lie in [``MIN_FIGURE_OF_MERIT``, 1] = [0.05, 1]: momentum
  theory allows no propeller above 1, real ones reach 0.3-0.7, and the report's published
  pair (d = b/4) gives 0.088; a drag factor d stored x1000 (or a torque/thrust ratio in mm)
  gives FM x 0.001, one stored /1000 FM x 1000.

Every refusal is one :func:`quadsim.core.errors.field_error` line naming the file, the field and
the numbers that disagree. Example::

    >>> from quadsim.vehicle.params import load_params
    >>> from quadsim.vehicle.guards import check_vehicle
    >>> check_vehicle(load_params("crazyflie21"))     # passes silently
    >>> feasibility(load_params("crazyflie21"))["thrust_to_weight"]   # ~3.1
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import ModelError, field_error

__all__ = ["MAX_THRUST_TO_WEIGHT", "MIN_THRUST_TO_WEIGHT", "check_figure_of_merit",
           "figure_of_merit",
           "check_hover_control",
           "check_vehicle", "feasibility"]

MIN_THRUST_TO_WEIGHT = 1.2
MAX_THRUST_TO_WEIGHT = 40.0
MIN_GYRATION_RATIO = 0.05
MAX_GYRATION_RATIO = 1.5
SPEED_OF_SOUND = 343.0  # m/s, air at 20 C
MAX_TIP_MACH = 0.9
PROP_OVERLAP = 1.2
MIN_FIGURE_OF_MERIT = 0.05


def feasibility(params) -> dict:
    """The dimensionless numbers the checks use (see the module docstring), for reports."""
    lift_axis = float(np.sum(params.rotor_axes[:, 2]))
    max_thrust = params.thrust_factor * params.max_speed ** 2 * lift_axis
    rel = params.rotor_positions - params.com
    arm = float(np.max(np.linalg.norm(rel, axis=1))) if len(rel) else 0.0
    pos = params.rotor_positions
    d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=-1)
    d[np.eye(len(pos), dtype=bool)] = np.inf
    nearest = float(np.min(d)) if len(pos) > 1 else math.inf
    gyration = np.sqrt(np.clip(np.diag(params.inertia), 0, None) / params.mass)
    return {
        "weight_N": params.weight,
        "max_thrust_N": max_thrust,
        "thrust_to_weight": max_thrust / params.weight if params.weight > 0 else math.inf,
        "hover_control": (params.weight / (params.thrust_factor * lift_axis)
                          if lift_axis > 0 else math.inf),
        "arm_m": arm,
        "gyration_m": gyration,
        "nearest_hub_m": nearest,
        "tip_speed_m_s": params.max_speed * params.rotor_radius,
    }


def _where(params) -> object:
    return params.path or params.name


def check_hover_control(params, *, where=None, mass_field="body.mass",
                        speed_field="rotors.max_speed") -> None:
    """Refuse when the hover control ``Omega_h^2`` (rad^2/s^2) is not inside the actuator's
    ``ctrlrange`` ``[Omega_min^2, Omega_max^2]`` with the thrust-to-weight margin."""
    where = where or _where(params)
    f = feasibility(params)
    if not math.isfinite(f["hover_control"]):
        raise ModelError(f"{where}: rotor: the rotors give no upward thrust")
    tw = f["thrust_to_weight"]
    ctrl_max = params.max_speed ** 2
    if tw < MIN_THRUST_TO_WEIGHT:
        raise field_error(
            where, mass_field,
            f"the rotors cannot lift the vehicle: hover needs {f['weight_N']:.4g} N "
            f"(mass {params.mass:.6g} kg) but {params.rotor_count} rotors give at most "
            f"{f['max_thrust_N']:.4g} N at {speed_field} {params.max_speed:.6g} rad/s "
            f"(thrust/weight {tw:.3g} < {MIN_THRUST_TO_WEIGHT}); hover control "
            f"{f['hover_control']:.4g} rad^2/s^2 vs ctrlrange [{params.min_speed ** 2:.4g}, "
            f"{ctrl_max:.4g}] (grams for kilograms? RPM for rad/s?)")
    if tw > MAX_THRUST_TO_WEIGHT:
        raise field_error(
            where, mass_field,
            f"thrust/weight {tw:.4g} > {MAX_THRUST_TO_WEIGHT}: {params.rotor_count} rotors "
            f"give {f['max_thrust_N']:.4g} N for a weight of {f['weight_N']:.4g} N "
            f"(mass {params.mass:.6g} kg); no multirotor is this over-powered "
            "(kilograms for grams? rad/s for RPM?)")
    if params.min_speed ** 2 >= f["hover_control"]:
        raise field_error(
            where, "rotors.min_speed",
            f"the slowest rotor speed {params.min_speed:.6g} rad/s already lifts more than the "
            f"weight (hover control {f['hover_control']:.4g} <= ctrlrange minimum "
            f"{params.min_speed ** 2:.4g} rad^2/s^2)")


def figure_of_merit(thrust_factor: float, drag_factor: float, air_density: float,
                    rotor_radius: float) -> float:
    """Hover figure of merit implied by b and d: FM = b^1.5 / (d sqrt(2 rho pi R^2)).

    Ideal (momentum-theory) power over actual power at any speed; real propellers give
    about 0.3-0.7. (b in N s^2/rad^2, d in N m s^2/rad^2, rho kg/m^3, R m.)"""
    disc_area = math.pi * rotor_radius**2
    return thrust_factor**1.5 / (drag_factor * math.sqrt(2.0 * air_density * disc_area))


def check_figure_of_merit(params, *, where=None) -> None:
    """b, d and the radius belong to a propeller: hover figure of merit in [0.05, 1]."""
    r, b, d = params.rotor_radius, params.thrust_factor, params.drag_factor
    if not (r > 0 and b > 0 and d > 0):
        return
    merit = figure_of_merit(b, d, params.air_density, r)
    if not MIN_FIGURE_OF_MERIT <= merit <= 1.0:
        raise field_error(
            where or _where(params), "rotors.drag_factor",
            f"d = {d:.4g} N m s^2/rad^2 with b = {b:.4g} N s^2/rad^2 (d/b = {d / b:.4g} m) "
            f"and radius {r:.4g} m gives a hover figure of merit {merit:.3g}, outside "
            f"{MIN_FIGURE_OF_MERIT}-1 (propellers 0.3-0.7): d off by a factor 1000?")


def check_vehicle(params, *, where=None) -> None:
    """Raise a one-line :class:`~quadsim.core.errors.InputError` if ``params`` cannot be one
    flyable vehicle (lift, size ratios, propeller overlap and tip speed)."""
    where = where or _where(params)
    f = feasibility(params)
    r = params.rotor_radius
    tip = f["tip_speed_m_s"]
    if r > 0 and tip > MAX_TIP_MACH * SPEED_OF_SOUND:
        raise field_error(
            where, "rotors.max_speed",
            f"blade tip speed {params.max_speed:.6g} rad/s x radius {r:.4g} m = {tip:.4g} m/s "
            f"is Mach {tip / SPEED_OF_SOUND:.2f} (> {MAX_TIP_MACH}): RPM stored as rad/s?")
    check_hover_control(params, where=where)
    arm = f["arm_m"]
    if arm > 0:
        for axis, k in zip("xyz", f["gyration_m"]):
            ratio = k / arm
            if not MIN_GYRATION_RATIO <= ratio <= MAX_GYRATION_RATIO:
                raise field_error(
                    where, "body.inertia",
                    f"radius of gyration about {axis} sqrt(I{axis}{axis}/m) = {k:.4g} m is "
                    f"{ratio:.3g} x the arm length {arm:.4g} m (plausible "
                    f"{MIN_GYRATION_RATIO}-{MAX_GYRATION_RATIO}); mass {params.mass:.6g} kg, "
                    f"I{axis}{axis} = {params.inertia['xyz'.index(axis)]['xyz'.index(axis)]:.4g}"
                    " kg m^2: a grams, millimetres or g mm^2 slip?")
    check_figure_of_merit(params, where=where)
    if r > 0 and math.isfinite(f["nearest_hub_m"]) and 2 * r > PROP_OVERLAP * f["nearest_hub_m"]:
        raise field_error(
            where, "rotors.radius",
            f"propellers of radius {r:.4g} m overlap: neighbouring hubs are "
            f"{f['nearest_hub_m']:.4g} m apart (2 r must be <= {PROP_OVERLAP} x that)")
