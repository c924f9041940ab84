"""Flights of an independent simulator: l2f 2.0.18, the "Learning to Fly" simulator of
RLtools (Eschmann, Albani & Loianno, "Learning to Fly in Seconds", IEEE RA-L 2024;
github.com/rl-tools/l2f), a C++ multirotor model with Python bindings: its own rigid body
(RK4 in single precision), its own first-order rotor model and its own identified vehicles.

l2f's model (``rl_tools/rl/environments/l2f/operations_generic/60_dynamics.h``), per rotor
i with normalised rotor state a_i in [0, 1] and normalised command u_i::

    T_i = c0 + c1 a_i + c2 a_i^2          thrust along the rotor axis (N)
    Q_i = k_Q T_i                           reaction torque about the rotor axis (N m)
    da_i/dt = (u_i - a_i) / tau             tau_rising where u_i >= a_i, else tau_falling

and the rigid body ``m dv/dt = R sum T_i + m g``, ``dw/dt = J^-1 (tau - w x J w)`` with J
and J^-1 given separately. No air drag, no wind, no battery.

Vehicle (:data:`MODEL`): l2f's identified Holybro X500 (``parameters/dynamics/x500_real.h``):
2.0 kg, rotors at (+-0.1768, +-0.1768) m (0.25 m arms, X), thrust 15.93 a^2 N per rotor
(c0 = c1 = 0), k_Q = 0.1085 m, tau 54 ms rising and falling. Its J as shipped is not its
J^-1's inverse (J_xx written ``2.1705-2``, i.e. 0.1705, against J^-1_xx = 46.07 -> 0.0217):
these flights use the inverse of its J^-1 for both, diag(0.021705, 0.021304, 0.039396)
kg m^2, since a J that enters only the gyroscopic term is no rigid body. l2f's rotor state
is normalised; the physical speed is ``Omega = a OMEGA_MAX`` with OMEGA_MAX = 1150 rad/s
(chosen: the X500 V2's 920 KV motors on 4S turn about 11 000 rpm under load), so quadsim's
b = c2 / OMEGA_MAX^2 and d = k_Q b.

What this module adds (l2f has no parameter for it), as a velocity and body-rate increment
after each l2f step (first-order operator splitting at 1 kHz): an air drag on each body axis
``-1/2 rho C_dA_i |v_i| v_i`` of the air-relative velocity (C_dA (0.02, 0.02, 0.05) m^2: a
0.2 m x 0.1 m body and battery seen from the side, arms and plates from above, C_d ~ 1;
without it a wind acts through nothing), and the case effects l2f has no parameter for
(rate damping, a periodic torque or force). Everything else is an l2f parameter (l2f's JSON
parameter set: mass, J, rotor positions about the CoM, thrust coefficients, time constants).

The controller (:class:`Cascade`, 500 Hz, zero-order hold; l2f has none: its own flights are
flown by learned policies): position P with velocity feed-forward, velocity PI with
acceleration feed-forward, the thrust vector's attitude (tilt at most 0.5 rad), attitude P,
body-rate PI with the nominal inertia, and allocation of the nominal X500 (thrusts from
the wrench, commands sqrt(T / c2)).

The log (:func:`to_flight_log`, 500 Hz: every second 1 kHz step; :mod:`.simlog`): motion of
the body origin (the CoM moved by ``com`` is not where the markers sit) with motion-capture
noise, gyro and accelerometer (specific force from the velocity step ``(v_k+1 - v_k) / dt``)
with IMU noise, rotor speeds (``a OMEGA_MAX`` after each step: the speed that made that
step's thrust) with telemetry noise, delayed by ``rotor_delay`` s when asked, and the
commands u (0..1: l2f's action mapped from [-1, 1]). No battery voltage.

Units and frames at the boundary: l2f's world is z up (gravity -9.81 on z), body x forward,
y left, z up, quaternions w, x, y, z body -> world (as quadsim), linear velocity in the
world and angular velocity in the body frame, single precision. Rotor i (l2f index i - 1)
with reaction torque direction s_i (l2f's ``rotor_torque_directions`` z) is quadsim's spin
-s_i.

Example::

    >>> log, truth = l2f_flights([FlightSpec(seed=1, effects={"mass": 0.2})])[0]
"""

from __future__ import annotations

import importlib.util
import json
from dataclasses import dataclass, field

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.core.frames import quat_to_rotmat
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, fly_all, mass_properties, rotor_scales
from .simlog import Sensors, SimStates, body_origin_log, truth_json

__all__ = [
    "ARPL",
    "EFFECTS",
    "FLIGHTMARE",
    "FS",
    "LOG_HZ",
    "MODEL",
    "OMEGA_MAX",
    "PHYSICS_HZ",
    "SOFT",
    "STAND",
    "VEHICLES",
    "Cascade",
    "FlightSpec",
    "Sensors",
    "command_for",
    "hover_command",
    "l2f_available",
    "l2f_flights",
    "path",
    "stand_b",
    "thrust_of",
    "to_flight_log",
    "truth_json",
    "vehicle_params",
]

PHYSICS_HZ = 1000
CONTROL_HZ = 500
LOG_HZ = 500
#: s flown before the log starts (the controller's integrators settle)
LEAD_IN = 2.0
#: rad/s at a normalised rotor state of 1 (module doc: chosen)
OMEGA_MAX = 1150.0
#: the vehicle in SI units: l2f 2.0.18 parameters/dynamics/x500_real.h (J from its J^-1,
#: module doc); the body drag is this module's (module doc)
MODEL = {"name": "l2f-x500", "header": "x500_real.h", "mass": 2.0,
         "rotor_xy": ((0.176776695296636, -0.176776695296636),
                      (-0.176776695296636, 0.176776695296636),
                      (0.176776695296636, 0.176776695296636),
                      (-0.176776695296636, -0.176776695296636)),
         "torque_dir": (-1.0, -1.0, 1.0, 1.0), "c0": 0.0, "c1": 0.0, "c2": 15.926119900619797,
         "k_torque": 1.0847e-1, "tau": 0.054,
         "inertia": (1 / 46.072333563695004, 1 / 46.939541870071345, 1 / 25.38313043243412),
         "gravity": 9.81, "rho": 1.225, "cd_area": (0.02, 0.02, 0.05),
         "rotor_radius": 0.127, "omega_max": OMEGA_MAX,
         "description": "l2f's identified Holybro X500 (2.0 kg) as quadsim sees it",
         "omega_source": "chosen: 920 KV on 4S, ~11 000 rpm loaded (rad/s)",
         "radius_source": "Holybro X500 V2: 10-inch propellers (m)"}
#: l2f's "fs" vehicle (``parameters/dynamics/fs.h``): 3.35 kg, rotors at (+-0.209, +-0.241)
#: m (a rectangle), a thrust curve with constant and linear terms (0.785 + 9.155 a + 18.006
#: a^2 N), k_Q 0.01492 m, 65.3 ms rotors; its J and J^-1 agree (Izz = 1.879 Iyy). The rotor
#: speed at a = 1 (1000 rad/s: 12-inch propellers at ~9 500 rpm), the propeller radius and
#: the body drag (a 3.35 kg frame: 1.5x the X500's areas) are this module's choice.
FS = {"name": "l2f-fs", "header": "fs.h", "mass": 3.35,
      "rotor_xy": ((0.20895, -0.240666), (-0.20895, 0.240666), (0.20895, 0.240666),
                   (-0.20895, -0.240666)),
      "torque_dir": (-1.0, -1.0, 1.0, 1.0), "c0": 0.7846629595902934,
      "c1": 9.15540123440728, "c2": 18.005569363583604, "k_torque": 0.01492, "tau": 0.06532,
      "inertia": (7.56e-2, 7.296e-2, 7.296e-2 * 1.879), "gravity": 9.81, "rho": 1.225,
      "cd_area": (0.03, 0.03, 0.075), "rotor_radius": 0.1524, "omega_max": 1000.0,
      "description": "l2f's fs vehicle (3.35 kg, thrust 0.785 + 9.16 a + 18.0 a^2 N) as "
                     "quadsim sees it",
      "omega_source": "chosen: 12-inch propellers, ~9 500 rpm at full command (rad/s)",
      "radius_source": "chosen: 12-inch propellers (m)"}
#: l2f's "flightmare" vehicle (``parameters/dynamics/flightmare.h``: the quadrotor of UZH's
#: Flightmare simulator, Song et al., CoRL 2020): 0.73 kg, rotors at 0.17 m on the diagonals
#: (X), a thrust curve with a negative constant and a linear term (-1.769 + 11.508 a + 11.968
#: a^2 N: l2f's normalisation of Flightmare's 1.33e-6 w^2 + 3.84e-3 w - 1.769 at w = 3000 a
#: rad/s), k_Q 0.016 m, 20 ms rotors, J diag(0.00791, 0.00791, 0.0123) kg m^2. The rotor
#: speed at a = 1 (3000 rad/s) is l2f's own normalisation; the propeller radius (5 inch) and
#: the body drag (a 0.73 kg racer-sized frame) are this module's choice.
FLIGHTMARE = {"name": "l2f-flightmare", "header": "flightmare.h", "mass": 0.73,
              "rotor_xy": ((0.12020815280171307, -0.12020815280171307),
                           (-0.12020815280171307, 0.12020815280171307),
                           (0.12020815280171307, 0.12020815280171307),
                           (-0.12020815280171307, -0.12020815280171307)),
              "torque_dir": (-1.0, -1.0, 1.0, 1.0), "c0": -1.7689986848125325,
              "c1": 11.50824315802381, "c2": 11.968428150335603, "k_torque": 0.016,
              "tau": 0.02, "inertia": (0.00791, 0.00791, 0.0123), "gravity": 9.81,
              "rho": 1.225, "cd_area": (0.01, 0.01, 0.025), "rotor_radius": 0.0635,
              "omega_max": 3000.0,
              "description": "l2f's flightmare vehicle (0.73 kg, thrust -1.77 + 11.5 a + 12.0 "
                             "a^2 N) as quadsim sees it",
              "omega_source": "l2f 2.0.18 flightmare.h: its thrust curve normalised at "
                              "3000 rad/s (rad/s)",
              "radius_source": "chosen: 5-inch propellers (m)"}
#: l2f's "mrs" vehicle (``parameters/dynamics/mrs.h``: a quadrotor of the MRS UAV system, CTU
#: Prague): 1.7 kg on the flightmare vehicle's rotors, arms and J (0.17 m diagonals,
#: Flightmare's 1.33e-6 w^2 + 3.84e-3 w - 1.769 N per rotor, k_Q 0.016 m), 40 ms rotors; its
#: rotor state is in rad/s up to 2000 (l2f's action limit), so a = w / 2000 here: -1.769 +
#: 7.672 a + 5.319 a^2 N, hover at a = 0.558 (slope 0.91x the quadratic model's 2 T / Omega).
#: The propeller radius (10 inch) and the body drag (a 1.7 kg frame) are this module's choice.
MRS = {"name": "l2f-mrs", "header": "mrs.h", "mass": 1.7,
       "rotor_xy": FLIGHTMARE["rotor_xy"], "torque_dir": (-1.0, -1.0, 1.0, 1.0),
       "c0": -1.7689986848125325, "c1": 0.0038360810526746032 * 2000.0,
       "c2": 0.0000013298253500372891 * 2000.0 ** 2, "k_torque": 0.016, "tau": 0.04,
       "inertia": (0.007911375, 0.007911375, 0.012306583333333334), "gravity": 9.81,
       "rho": 1.225, "cd_area": (0.015, 0.015, 0.04), "rotor_radius": 0.127,
       "omega_max": 2000.0,
       "description": "l2f's mrs vehicle (1.7 kg, thrust -1.77 + 7.67 a + 5.32 a^2 N) as "
                      "quadsim sees it",
       "omega_source": "l2f 2.0.18 mrs.h: its action limit, 2000 rad/s",
       "radius_source": "chosen: 10-inch propellers (m)"}
#: l2f's "arpl" vehicle (``parameters/dynamics/arpl.h``: a quadrotor of NYU's Agile Robotics
#: and Perception Lab): 0.782 kg, rotors on a 155 x 196 mm rectangle, a thrust curve that
#: bends down, -0.530 + 8.971 a - 0.891 a^2 N per rotor (c2 < 0: it flattens towards full
#: throttle), k_Q 0.00596 m, 33 ms rotors, J diag(1.7665e-3, 1.3766e-3, 2.953e-3) kg m^2.
#: Its rotor state is normalised (action limit 0..1); the speed at a = 1 (3000 rad/s), the
#: propeller radius (5 inch) and the body drag (a 0.78 kg frame, as flightmare's) are this
#: module's choice, and so is its stand sweep (``stand_top``: a = 0.1..0.5, the band it flies;
#: over 0.1..1.0 the curve's flattening top leaves b 2.7x low at hover, beyond the
#: diagnosis' vehicle check, which refused the first run; over 0.1..0.5 it is 1.4x low).
ARPL = {"name": "l2f-arpl", "header": "arpl.h", "mass": 0.782,
        "rotor_xy": ((0.0775, -0.0981), (-0.0775, 0.0981), (0.0775, 0.0981),
                     (-0.0775, -0.0981)),
        "torque_dir": (-1.0, -1.0, 1.0, 1.0), "c0": -0.5300192490953086,
        "c1": 8.971435376396558, "c2": -0.8911788522090669, "k_torque": 0.005964552,
        "tau": 0.033, "inertia": (1.7665e-3, 1.3766e-3, (1.7665e-3 + 1.3766e-3) / 2 * 1.879),
        "gravity": 9.81, "rho": 1.225, "cd_area": (0.01, 0.01, 0.025),
        "rotor_radius": 0.0635, "omega_max": 3000.0, "stand_top": 0.5,
        "description": "l2f's arpl vehicle (0.782 kg, thrust -0.53 + 8.97 a - 0.89 a^2 N) as "
                       "quadsim sees it",
        "omega_source": "chosen: l2f 2.0.18 arpl.h normalises its rotor state to 0..1; "
                        "3000 rad/s at 1 (rad/s)",
        "radius_source": "chosen: 5-inch propellers (m)"}
#: l2f's "soft_rigid" vehicle (``parameters/dynamics/soft_rigid.h``): 0.804 kg, rotors on a
#: 284 x 338 mm rectangle, -0.334 + 6.091 a + 0.782 a^2 N per rotor (hover at a = 0.362,
#: where the slope is 0.61x the quadratic model's and c2 is 0.05 of the b that carries the
#: hover), k_Q 0.0176 m, 46 ms rotors, J diag(6.584e-3, 4.957e-3, 1.057e-2) kg m^2. Its rotor
#: state is normalised (action limit 0..1); the speed at a = 1 (2500 rad/s), the propeller
#: radius (8 inch), the body drag (flightmare's) and the stand sweep (a = 0.1..0.6, the band
#: it flies: b 1.31x low at hover; over 0.1..1.0 it is 2.0x low, at the vehicle check's
#: limit) are this module's choice, made before any verdict.
SOFT = {"name": "l2f-soft", "header": "soft_rigid.h", "mass": 0.804,
        "rotor_xy": ((0.142, -0.169), (-0.142, 0.169), (0.142, 0.169), (-0.142, -0.169)),
        "torque_dir": (-1.0, -1.0, 1.0, 1.0), "c0": -0.33379755540556755,
        "c1": 6.090995069311198, "c2": 0.7818335456716792, "k_torque": 1.7602e-2,
        "tau": 0.046, "inertia": (6.5842e-3, 4.9571e-3, 0.010571830800000001),
        "gravity": 9.81, "rho": 1.225, "cd_area": (0.01, 0.01, 0.025),
        "rotor_radius": 0.1016, "omega_max": 2500.0, "stand_top": 0.6,
        "description": "l2f's soft_rigid vehicle (0.804 kg, thrust -0.33 + 6.09 a + 0.78 a^2 "
                       "N) as quadsim sees it",
        "omega_source": "chosen: l2f 2.0.18 soft_rigid.h normalises its rotor state to 0..1; "
                        "2500 rad/s at 1 (rad/s)",
        "radius_source": "chosen: 8-inch propellers (m)"}
#: the vehicles by name (``--source l2f`` flies the X500, ``--source l2f-fs`` the fs,
#: ``--source l2f-flightmare`` the flightmare, ``--source l2f-mrs`` the mrs vehicle,
#: ``--source l2f-arpl`` the arpl vehicle, ``--source l2f-soft`` the soft_rigid vehicle)
VEHICLES = {"x500": MODEL, "fs": FS, "flightmare": FLIGHTMARE, "mrs": MRS, "arpl": ARPL,
            "soft": SOFT}
#: case-side effects (:class:`FlightSpec.effects`), SI: mass (kg at the CoM); payload (kg, x,
#: y, z m: a point mass; mass, CoM and inertia change together); com (x, y m); inertia
#: (relative change of Ixx Iyy Izz); weak_rotor (rotor 1..4, relative change of its thrust
#: coefficients: its reaction torque follows, k_Q T); thrust_scale (relative change of every
#: rotor's); thrust_linear (c1 in N: a thrust curve with a linear term); motor_slow (factor on
#: both time constants); rate_damping (N m s/rad on x, y, z); wind (m/s world x, y); torque
#: (N m body x, y, z amplitude) with torque_hz; force (N body z amplitude) with force_hz;
#: rotor_delay (s, the log only).
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "thrust_linear",
           "motor_slow", "rate_damping", "wind", "torque", "torque_hz", "force", "force_hz",
           "rotor_delay")


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, sensor noise), speed factor of the path, duration (s,
    logged), case-side effects (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def l2f_available() -> bool:
    """l2f importable (checked without importing it)."""
    return importlib.util.find_spec("l2f") is not None


def thrust_of(a, vehicle: dict = MODEL):
    """One rotor's thrust (N) at normalised rotor state ``a``: c0 + c1 a + c2 a^2."""
    return vehicle["c0"] + vehicle["c1"] * a + vehicle["c2"] * np.square(a)


def command_for(thrust, vehicle: dict = MODEL):
    """The rotor state (0..1) whose steady thrust is ``thrust`` (N; below c0: 0), the root
    of c0 + c1 a + c2 a^2 = T (sqrt(T / c2) where c0 = c1 = 0)."""
    c0, c1, c2 = vehicle["c0"], vehicle["c1"], vehicle["c2"]
    t = np.maximum(np.asarray(thrust, dtype=float) - c0, 0.0)
    if c1 == 0.0:
        return np.clip(np.sqrt(t / c2), 0.0, 1.0)
    return np.clip((np.sqrt(c1 * c1 + 4.0 * c2 * t) - c1) / (2.0 * c2), 0.0, 1.0)


def hover_command(mass: float | None = None, vehicle: dict = MODEL) -> float:
    """Normalised rotor state at which the four rotors carry ``mass`` (kg; default the
    vehicle's): the root of c0 + c1 a + c2 a^2 = m g / 4."""
    mass = vehicle["mass"] if mass is None else mass
    if vehicle["c0"] == 0.0 and vehicle["c1"] == 0.0:
        return float(np.sqrt(mass * vehicle["gravity"] / (4 * vehicle["c2"])))
    return float(command_for(mass * vehicle["gravity"] / 4.0, vehicle))


#: normalised rotor states of the thrust-stand sweep behind a nominal b (:func:`stand_b`)
STAND = np.linspace(0.1, 1.0, 10)


def stand_b(vehicle: dict = MODEL) -> float:
    """quadsim's b (N s^2/rad^2) of a vehicle: c2 / omega_max^2 where l2f's thrust is purely
    quadratic; else the least-squares fit of b Omega^2 to its thrust curve over a stand sweep
    a = 0.1..1.0 (:data:`STAND`), as ``python -m quadsim.identify`` fits a thrust-stand
    sweep (least squares through the origin over every point). For the fs vehicle that is
    30.1 a^2 N: at hover (a = 0.437) 5.75 N against l2f's 8.22 (30 % low: the constant and
    linear terms carry most of the thrust there), its slope 26.3 against 24.9 N per unit
    state (6 % steep); the form error its references share."""
    w = vehicle["omega_max"]
    if vehicle["c0"] == 0.0 and vehicle["c1"] == 0.0:
        return vehicle["c2"] / w ** 2
    stand = np.linspace(0.1, vehicle["stand_top"], STAND.size) if "stand_top" in vehicle \
        else STAND
    a2 = stand ** 2
    return float(np.sum(thrust_of(stand, vehicle) * a2) / np.sum(a2 * a2)) / w ** 2


def _rotor_positions(vehicle: dict = MODEL) -> np.ndarray:
    return np.array([[x, y, 0.0] for x, y in vehicle["rotor_xy"]])


def vehicle_params(vehicle: dict = MODEL) -> VehicleParams:
    """quadsim's parameter set of the nominal vehicle (module doc)."""
    m = vehicle
    w = m["omega_max"]
    b = stand_b(m)
    rotors = tuple(Rotor(str(i + 1), p, np.array([0.0, 0.0, 1.0]), -float(s))
                   for i, (p, s) in enumerate(zip(_rotor_positions(m), m["torque_dir"])))
    grid = np.linspace(0.0, 1.0, 11)
    src = f"l2f 2.0.18 parameters/dynamics/{m['header']}"
    quadratic = m["c0"] == 0.0 and m["c1"] == 0.0
    params = VehicleParams(
        name=m["name"], mass=m["mass"], com=np.zeros(3), inertia=np.diag(m["inertia"]),
        rotors=rotors, thrust_factor=b, drag_factor=m["k_torque"] * b,
        max_speed=w, min_speed=0.0, rotor_radius=m["rotor_radius"],
        rotor_inertia=0.0, gravity=m["gravity"], air_density=m["rho"],
        motor_map=MotorMap("1", grid, np.tile(grid * w, (4, 1)),
                           "l2f's rotor state in steady state equals its command: normalised "
                           "command -> command x OMEGA_MAX rad/s"),
        description=m["description"],
        sources={"mass": f"{src}: mass (kg)",
                 "inertia": (f"{src}: the inverse of its J_inv (kg m^2; its J has a typo)"
                             if m is MODEL else f"{src}: J (kg m^2)"),
                 "rotors": f"{src}: rotor positions (m), spins from its torque directions",
                 "thrust_factor": (f"{src}: {m['c2']:.2f} N at a = 1, over OMEGA_MAX^2 "
                                   "(N s^2/rad^2)" if quadratic else
                                   f"{src}: its thrust curve fitted as b Omega^2 over a "
                                   "stand sweep a = 0.1..1 (N s^2/rad^2)"),
                 "drag_factor": f"{src}: torque constant {m['k_torque']:.4g} m x b "
                                "(N m s^2/rad^2)",
                 "max_speed": m["omega_source"],
                 "min_speed": "l2f's action limit 0 (rad/s)",
                 "rotor_radius": m["radius_source"],
                 "rotor_inertia": "l2f leaves the spin-up torque out (kg m^2)",
                 "gravity": f"{src}: gravity (m/s^2)",
                 "air_density": "this module's body drag: ISA sea level (kg/m^3)"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path(t: np.ndarray, seed: int, speed: float) -> tuple[np.ndarray, np.ndarray,
                                                          np.ndarray, np.ndarray]:
    """Setpoints of a figure-8 with climbs, a yaw sweep and a small fast weave (roll/pitch
    excitation): position, velocity, acceleration (T, 3) (m, m/s, m/s^2) and yaw (T,) (rad).
    x = 2.5 sin(w t) + a sin(5 w t), y = 1.0 sin(2 w t + phi) + a sin(6 w t + phi),
    z = 1.5 + 0.25 sin(1.7 w t), yaw = 0.5 sin(1.1 w t), a = 0.08 m / max(speed, 0.5)^2,
    w = 0.5 speed rad/s, phase phi from the seed."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.5 * speed
    weave = 0.08 / max(speed, 0.5) ** 2
    terms = ((0, 2.5, w, 0.0), (1, 1.0, 2 * w, phi), (2, 0.25, 1.7 * w, 0.0),
             (0, weave, 5 * w, 0.0), (1, weave, 6 * w, phi))
    pos, vel, acc = np.zeros((len(t), 3)), np.zeros((len(t), 3)), np.zeros((len(t), 3))
    pos[:, 2] = 1.5
    for column, amp, freq, phase in terms:
        arg = freq * t + phase
        pos[:, column] += amp * np.sin(arg)
        vel[:, column] += amp * freq * np.cos(arg)
        acc[:, column] -= amp * freq ** 2 * np.sin(arg)
    return pos, vel, acc, 0.5 * np.sin(1.1 * w * t)


# ----------------------------------------------------------------------------- the controller


class Cascade:
    """The flights' controller (module doc), tuned for the nominal X500 and blind to every
    case effect: it knows the nominal vehicle's mass, inertia, rotor positions and thrust
    curve (``vehicle``).
    :meth:`step` takes the state (CoM position, world velocity, quaternion w-first, body
    rate) and the setpoints, and returns the normalised commands u (4,) in [0, 1]."""

    # gains (1/s; integrals 1/s^2) that fly every case: the 2.5x slower rotors (135 ms) too,
    # whose rate loop the first choice (attitude 8, rate 20 1/s) lost within 3 s
    KP_POS, KP_VEL, KI_VEL = 1.2, 2.5, 0.6
    KP_ATT = np.array([5.0, 5.0, 2.5])
    KP_RATE, KI_RATE = np.array([12.0, 12.0, 6.0]), np.array([3.0, 3.0, 1.5])
    MAX_TILT = 0.5                                       # rad
    HOLD_ARM = 0.15             # the cases' CoM offsets reach 10 % of the arm

    def __init__(self, dt: float, vehicle: dict = MODEL):
        m = self.vehicle = vehicle
        self.dt = dt
        self.mass = m["mass"]
        self.inertia = np.diag(m["inertia"])
        pos = _rotor_positions(m)
        # rows: total thrust, roll, pitch and yaw torque per unit rotor thrust
        self.mix = np.array([np.ones(4), pos[:, 1], -pos[:, 0],
                             m["k_torque"] * np.asarray(m["torque_dir"])])
        self.unmix = np.linalg.inv(self.mix)
        self.i_vel = np.zeros(3)
        self.i_rate = np.zeros(3)
        # the rate integral holds up to the torque of a CoM offset at HOLD_ARM of the arm (a
        # torque, so its angle clip follows the vehicle): at 0.5 rad, the arpl vehicle's
        # (J 12x below the X500's) held 2.7 mN m against 44 mN m of a 5.7 mm offset, and its
        # CoM flights drifted 40-70 m
        arm = float(np.max(np.hypot(pos[:, 0], pos[:, 1])))
        hold = self.HOLD_ARM * m["mass"] * m["gravity"] * arm
        self.i_rate_max = np.maximum(0.5, hold / (np.diag(self.inertia) * self.KI_RATE))

    def step(self, pos, vel, quat, rate, sp_pos, sp_vel, sp_acc, sp_yaw) -> np.ndarray:
        g = self.vehicle["gravity"]
        v_sp = sp_vel + self.KP_POS * (sp_pos - pos)
        err_v = v_sp - vel
        self.i_vel = np.clip(self.i_vel + err_v * self.dt, -2.0, 2.0)
        acc = sp_acc + self.KP_VEL * err_v + self.KI_VEL * self.i_vel + np.array([0, 0, g])
        horizontal = np.hypot(acc[0], acc[1])
        limit = acc[2] * np.tan(self.MAX_TILT)
        if horizontal > limit:
            acc[:2] *= limit / horizontal
        rot = quat_to_rotmat(quat)
        thrust = self.mass * float(acc @ rot[:, 2])
        z_d = acc / np.linalg.norm(acc)
        x_c = np.array([np.cos(sp_yaw), np.sin(sp_yaw), 0.0])
        y_d = np.cross(z_d, x_c)
        y_d /= np.linalg.norm(y_d)
        r_d = np.column_stack([np.cross(y_d, z_d), y_d, z_d])
        e = r_d.T @ rot - rot.T @ r_d                    # attitude error (vee of the skew part)
        err_att = -0.5 * np.array([e[2, 1], e[0, 2], e[1, 0]])
        err_rate = self.KP_ATT * err_att - rate
        self.i_rate = np.clip(self.i_rate + err_rate * self.dt, -self.i_rate_max,
                              self.i_rate_max)
        torque = self.inertia @ (self.KP_RATE * err_rate + self.KI_RATE * self.i_rate) \
            + np.cross(rate, self.inertia @ rate)
        per_rotor = np.clip(self.unmix @ np.concatenate([[thrust], torque]), 0.0, None)
        return command_for(per_rotor, self.vehicle)


# ----------------------------------------------------------------------------- the job


def _flight_job(spec: FlightSpec, vehicle: dict = MODEL) -> dict:
    """l2f parameters and this module's disturbances of one flight (SI); the X500's job
    names no vehicle (its cached flights' truth as before), another's carries it."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown l2f effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    m = vehicle
    mass, com, inertia = mass_properties(e, m["mass"], m["inertia"])
    scale = rotor_scales(e)
    job = {"mass": mass, "com": com, "inertia": inertia, "thrust_scale": scale,
           "thrust_linear": float(e.get("thrust_linear", 0.0)),
           "tau": m["tau"] * float(e.get("motor_slow", 1.0)),
           **disturbances(e)}
    if vehicle is not MODEL:        # its numbers (the job goes into the truth sidecar)
        job["vehicle"] = {k: v for k, v in vehicle.items() if not isinstance(v, str)}
    return job


def _vehicle(job: dict) -> dict:
    return job.get("vehicle", MODEL)


def _parameters_json(job: dict, template: str) -> str:
    """l2f's JSON parameter set of a job: the template's (l2f's default parameters, so that
    every field l2f reads is present) with the vehicle's dynamics and a 1 kHz step."""
    p = json.loads(template)
    d = p["dynamics"]
    m = _vehicle(job)
    rel = _rotor_positions(m) - job["com"]
    d["rotor_positions"] = rel.tolist()
    d["rotor_thrust_directions"] = [[0.0, 0.0, 1.0]] * 4
    d["rotor_torque_directions"] = [[0.0, 0.0, s] for s in m["torque_dir"]]
    d["rotor_thrust_coefficients"] = [[m["c0"] * s, (m["c1"] + job["thrust_linear"]) * s,
                                       m["c2"] * s] for s in job["thrust_scale"]]
    d["rotor_torque_constants"] = [m["k_torque"]] * 4
    d["rotor_time_constants_rising"] = [job["tau"]] * 4
    d["rotor_time_constants_falling"] = [job["tau"]] * 4
    d["mass"] = job["mass"]
    d["gravity"] = [0.0, 0.0, -m["gravity"]]
    d["J"] = np.asarray(job["inertia"]).tolist()
    d["J_inv"] = np.linalg.inv(job["inertia"]).tolist()
    d["hovering_throttle_relative"] = hover_command(job["mass"], m)
    d["action_limit"] = {"min": 0.0, "max": 1.0}
    p["integration"]["dt"] = 1.0 / PHYSICS_HZ
    return json.dumps(p)


def _disturbance(job: dict, rot: np.ndarray, vel: np.ndarray, rate: np.ndarray, t: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame force and torque this module adds over one step (module doc)."""
    m = _vehicle(job)
    air = rot.T @ (vel - job["wind"])
    force = -0.5 * m["rho"] * np.asarray(m["cd_area"]) * np.abs(air) * air
    force[2] += job["force"] * np.sin(2 * np.pi * job["force_hz"] * t)
    torque = -job["rate_damping"] * rate \
        + job["torque"] * np.sin(2 * np.pi * job["torque_hz"] * t)
    return force, torque


def _fly(args) -> dict:
    """One flight in l2f: true states at :data:`PHYSICS_HZ` after the lead-in."""
    spec, job = args
    import l2f

    device, env, rng = l2f.Device(), l2f.Environment(), l2f.Rng()
    params = l2f.Parameters()
    l2f.initialize_environment(device, env)
    l2f.initialize_rng(device, rng, int(spec.seed))
    l2f.initial_parameters(device, env, params)
    template = l2f.parameters_to_json(device, env, params)
    l2f.parameters_from_json(device, env, _parameters_json(job, template), params)
    state, following = l2f.State(), l2f.State()
    l2f.initial_state(device, env, params, state)
    dt = 1.0 / PHYSICS_HZ
    every = PHYSICS_HZ // CONTROL_HZ
    lead, n = round(LEAD_IN * PHYSICS_HZ), round(spec.duration * PHYSICS_HZ)
    t = np.arange(lead + n + 1) * dt
    sp_pos, sp_vel, sp_acc, sp_yaw = path(t, spec.seed, spec.speed)
    vehicle = _vehicle(job)
    omega_max = vehicle["omega_max"]
    hover = hover_command(job["mass"], vehicle)
    state.position = sp_pos[0].tolist()
    state.orientation = [1.0, 0.0, 0.0, 0.0]
    state.linear_velocity = sp_vel[0].tolist()
    state.angular_velocity = [0.0, 0.0, 0.0]
    state.rpm = [hover] * 4
    ctrl = Cascade(every * dt, vehicle)
    inv_inertia = np.linalg.inv(job["inertia"])
    out = np.empty((lead + n + 1, 17))
    u = np.full(4, hover)

    def read(s):
        return (np.array(s.position, dtype=float), np.array(s.linear_velocity, dtype=float),
                np.array(s.orientation, dtype=float), np.array(s.angular_velocity, dtype=float),
                np.array(s.rpm, dtype=float))

    pos, vel, quat, rate, rpm = read(state)
    out[0] = np.concatenate([pos, vel, quat, rate, rpm * omega_max])
    commands = np.empty((lead + n + 1, 4))
    commands[0] = u
    for k in range(lead + n):
        if k % every == 0:
            u = ctrl.step(pos, vel, quat, rate, sp_pos[k], sp_vel[k], sp_acc[k], sp_yaw[k])
        l2f.step(device, env, params, state, (2.0 * u - 1.0).tolist(), following, rng)
        state.assign(following)
        pos, vel, quat, rate, rpm = read(state)
        rot = quat_to_rotmat(quat)
        force, torque = _disturbance(job, rot, vel, rate, t[k])
        vel = vel + rot @ force / job["mass"] * dt
        rate = rate + inv_inertia @ torque * dt
        state.linear_velocity = vel.tolist()
        state.angular_velocity = rate.tolist()
        pos, vel, quat, rate, rpm = read(state)   # as l2f holds them (single precision)
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(rate))) or quat[0] ** 2 < 0.5:
            raise ModelError(f"l2f flight (seed {spec.seed}) lost control at t = {t[k]:.2f} s")
        out[k + 1] = np.concatenate([pos, vel, quat, rate, rpm * omega_max])
        commands[k + 1] = u
    return {"states": out[lead:], "commands": commands[lead:]}


def l2f_flights(specs: list[FlightSpec], workers: int | None = None, vehicle: str = "x500"
                ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec in l2f with the vehicle :data:`VEHICLES` ``[vehicle]`` (``workers``
    processes, default: the CPU count, at most 4) and return ``(log, truth)`` per spec: the
    log as :func:`to_flight_log` makes it, the truth sidecar (effects, the flight's l2f
    parameters, seed, speed)."""
    if not l2f_available():
        raise ModelError("l2f is not installed (pip install -e '.[l2f]': compiles l2f "
                         "2.0.18: about 11 min)")
    m = VEHICLES[vehicle]
    jobs = [_flight_job(s, m) for s in specs]
    to_log = to_flight_log if m is MODEL else (
        lambda raw, spec, com: to_flight_log(raw, spec, com, m))
    return fly_all(_fly, to_log, specs, jobs, source="l2f", model=m["name"],
                   rates=(PHYSICS_HZ, LOG_HZ), workers=workers)


def to_flight_log(raw: dict, spec: FlightSpec, com: np.ndarray, vehicle: dict = MODEL
                  ) -> FlightLog:
    """l2f's states (CoM position and world velocity, quaternion, body rate, rotor speeds in
    rad/s) at 1 kHz -> a quadsim :class:`FlightLog` of the body origin at :data:`LOG_HZ`
    with the sensor model of ``spec.sensors`` (seeded by ``spec.seed``)."""
    x = raw["states"]
    dt = 1.0 / PHYSICS_HZ
    acc = np.diff(x[:, 3:6], axis=0) / dt
    ang_acc = np.diff(x[:, 10:13], axis=0) / dt
    keep = np.arange(0, len(x) - 1, PHYSICS_HZ // LOG_HZ)
    states = SimStates(rate_hz=LOG_HZ, pos=x[keep, 0:3], vel=x[keep, 3:6], quat=x[keep, 6:10],
                       ang_vel=x[keep, 10:13], ang_acc=ang_acc[keep], acc=acc[keep],
                       rotor_speed=x[keep + 1, 13:17], command=raw["commands"][keep + 1])
    return body_origin_log(states, com, spec.sensors, spec.seed,
                           hover_speed=hover_command(vehicle=vehicle) * vehicle["omega_max"],
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)),
                           gravity=vehicle["gravity"])
