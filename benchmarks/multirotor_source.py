"""Flights of an independent simulator: multirotor 0.5.0 (Ahmed, Quinones-Grueiro & Biswas,
"A high-fidelity simulation test-bed for fault-tolerant octo-rotor control using
reinforcement learning", IEEE/AIAA DASC 2022; github.com/hazrmard/multirotor), its own
rigid-body equations (Euler angles, body-frame velocity, ``scipy.integrate.odeint`` per
step), its own DC motors and its own ArduPilot-style cascaded PID controller.

What multirotor models that quadsim's nominal model does not (the references share it):

* **DC motors** (``multirotor.simulation.Motor``): the speed signal u (rad/s) becomes a
  voltage ``V = k_sv u`` clipped to the battery's 0..22.2 V; the current ``i = (V - k_e
  Omega) / R`` is clipped to 0..38 A (no active braking: a motor slows only by its
  propeller's drag torque), and ``J dOmega/dt = k_t i - k_d Omega^2`` is stepped by a
  trapezoid on the last two accelerations. So spin-up is fast (about 5 ms at hover), spin-down
  slow (about 35 ms), the steady speed per command follows the motor's load (a propeller
  with less drag torque spins faster), and the speed saturates at the current limit.
* The state is rounded to 4 decimals after every step (its ``np.around(state, 4)``) and
  its derivatives to 4 (1 kHz): 0.1 mm, 0.1 mm/s, 1e-4 rad, 1e-4 rad/s steps.

quadsim adds (``disturb_forces`` / ``disturb_torques``, body frame, constant over a step): an
air drag on each body axis ``-1/2 rho C_dA_i |v_i| v_i`` of the air-relative velocity
(multirotor has none; without it a wind would act through nothing), and the case effects
that multirotor has no parameter for (rate damping, a periodic torque or force).

Vehicle (:func:`vehicle_params`, "multirotor-x4"): a 5.5 kg heavy-lift quadrotor X on 0.45 m
arms with multirotor's own Tarot T18 motor and 18-inch propeller
(``multirotor.models.tarott18``: k_thrust 9.8419e-5 N s^2, k_drag 1.8503e-6 N m s^2, motor R
0.081 ohm, k_e = k_t 0.0265, J 5e-5 kg m^2, k_sv 0.0347 V s, 38 A, 6S 22.2 V; gravity
9.81 m/s^2 and air 1.225 kg/m^3 as its SimulationParams); inertia
(0.15, 0.15, 0.28) kg m^2; body drag C_dA (0.05, 0.05, 0.12) m^2 (a 0.3 m x 0.17 m frame and
battery seen from the side, and the arms and frame from above, C_d ~ 1).

The log (:func:`to_flight_log`, 500 Hz: every second 1 kHz step; :mod:`.simlog`): motion of
the body origin (the CoM moved by ``com`` is not where the markers sit) with motion-capture
noise, gyro and accelerometer (specific force from the velocity step ``(v_k+1 - v_k) / dt``)
with IMU noise, rotor speeds (the motors' state after each step, the speed that made that
step's thrust) with telemetry noise, delayed by ``rotor_delay`` s when asked, and commands as
the voltage fraction ``clip(k_sv u / 22.2, 0, 1)`` (a PWM duty cycle). No battery voltage is
logged (multirotor's battery holds 22.2 V).

Units and frames at the boundary: multirotor's world is z up (gravity ``-g`` on world z), its
body x forward, y left, z up (as quadsim); attitude is roll, pitch, yaw (Z-Y-X), turned into
scalar-first quaternions body -> world; its velocity state is in the body frame (rotated to
the world). Rotor i sits at angle ``a_i`` from body +x towards +y at 0.45 m; multirotor's
``clockwise`` +1 (seen from above, reaction torque +z) is quadsim's spin -1.

Example::

    >>> log, truth = multirotor_flights([FlightSpec(seed=1, effects={"mass": 0.5})])[0]
"""

from __future__ import annotations

import importlib.util
from copy import deepcopy
from dataclasses import dataclass, field

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.core.frames import euler_to_quat, quat_to_rotmat
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, fly_all, mass_properties, rotor_scales
from .simlog import Sensors, SimStates, body_origin_log, truth_json

__all__ = ["EFFECTS", "LOG_HZ", "MODEL", "PHYSICS_HZ", "FlightSpec", "Sensors",
           "hover_speed_of",
           "multirotor_available", "multirotor_flights", "path_setpoints", "steady_speed",
           "to_flight_log", "truth_json", "vehicle_params"]

PHYSICS_HZ = 1000
LOG_HZ = 500
#: s flown before the log starts (the controller's integrators settle)
LEAD_IN = 2.0
#: the vehicle in SI units (module doc); motor and propeller: multirotor.models.tarott18
MODEL = {"mass": 5.5, "inertia": (0.15, 0.15, 0.28), "arm": 0.45,
         "angles": (0.25 * np.pi, 0.75 * np.pi, 1.25 * np.pi, 1.75 * np.pi),
         "clockwise": (-1, 1, -1, 1), "k_thrust": 9.8419e-05, "k_drag": 1.8503e-06,
         "prop_inertia": 1.86e-6, "resistance": 0.081, "k_emf": 0.0265,
         "motor_inertia": 5e-5, "k_sv": 0.0347, "max_current": 38.0, "max_voltage": 22.2,
         "cd_area": (0.05, 0.05, 0.12), "rho": 1.225, "rotor_radius": 0.2286, "gravity": 9.81}
#: case-side effects (:class:`FlightSpec.effects`), SI: mass (kg at the CoM); payload (kg, x,
#: y, z m: a point mass; mass, CoM and inertia change together); com (x, y m); inertia
#: (relative change of Ixx Iyy Izz); weak_rotor (rotor 1..4, relative change of its k_thrust
#: and k_drag); thrust_scale (relative change of every propeller's k_thrust and k_drag);
#: motor_slow (factor on the motors' J); rate_damping (N m s/rad on x, y, z); wind (m/s world
#: x, y); torque (N m body x, y, z amplitude) with torque_hz; force (N body z amplitude) with
#: force_hz; rotor_delay (s, the log only).
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "motor_slow",
           "rate_damping", "wind", "torque", "torque_hz", "force", "force_hz", "rotor_delay")


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, sensor noise), speed factor of the path, duration (s,
    logged), case-side effects (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def multirotor_available() -> bool:
    """multirotor and numba importable (checked without importing them)."""
    return all(importlib.util.find_spec(m) is not None for m in ("multirotor", "numba"))


def hover_speed_of(mass: float = MODEL["mass"]) -> float:
    """Rotor speed (rad/s) at which the four propellers carry ``mass`` (kg):
    sqrt(m g / (4 k_thrust))."""
    return float(np.sqrt(mass * MODEL["gravity"] / (4 * MODEL["k_thrust"])))


def steady_speed(command: np.ndarray, k_drag: float = MODEL["k_drag"]) -> np.ndarray:
    """Steady rotor speed (rad/s) of multirotor's DC motor at a voltage fraction ``command``
    (0..1 of 22.2 V): ``k_t (c V - k_e W) / R = k_d W^2`` solved for W, and at the 38 A
    current limit ``k_t i_max = k_d W^2``."""
    m = MODEL
    c = np.clip(np.asarray(command, dtype=float), 0.0, 1.0)
    b = m["k_emf"] ** 2 / m["resistance"]
    free = (-b + np.sqrt(b * b + 4 * k_drag * m["k_emf"] * c * m["max_voltage"]
                         / m["resistance"])) / (2 * k_drag)
    return np.minimum(free, np.sqrt(m["k_emf"] * m["max_current"] / k_drag))


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of the nominal vehicle (module doc)."""
    m = MODEL
    rotors = tuple(Rotor(str(i + 1), np.array([m["arm"] * np.cos(a), m["arm"] * np.sin(a),
                                                0.0]), np.array([0.0, 0.0, 1.0]), -float(cw))
                   for i, (a, cw) in enumerate(zip(m["angles"], m["clockwise"])))
    grid = np.linspace(0.0, 1.0, 41)
    speed = steady_speed(grid)
    src = "multirotor 0.5.0 models/tarott18.py"
    params = VehicleParams(
        name="multirotor-x4", mass=m["mass"], com=np.zeros(3), inertia=np.diag(m["inertia"]),
        rotors=rotors, thrust_factor=m["k_thrust"], drag_factor=m["k_drag"],
        max_speed=float(speed[-1]), min_speed=0.0, rotor_radius=m["rotor_radius"],
        rotor_inertia=0.0, gravity=m["gravity"], air_density=m["rho"],
        motor_map=MotorMap("1", grid, np.tile(speed, (4, 1)),
                           "multirotor's DC motor in steady state (steady_speed): voltage "
                           "fraction of 22.2 V -> rad/s"),
        description="a 5.5 kg quadrotor X built in multirotor 0.5.0 (Tarot T18 motor, 18-inch "
                    "propellers) as quadsim sees it",
        sources={"mass": "chosen: a heavy-lift quadrotor (kg)",
                 "inertia": "chosen: Ixx Iyy Izz (kg m^2)",
                 "rotors": "0.45 m arms at 45, 135, 225, 315 deg; spins from multirotor's "
                           "clockwise (-1, 1, -1, 1) (m)",
                 "thrust_factor": f"{src}: k_thrust (N s^2/rad^2)",
                 "drag_factor": f"{src}: k_drag (N m s^2/rad^2)",
                 "max_speed": f"{src}: the 38 A current limit, sqrt(k_t i_max / k_d) (rad/s)",
                 "min_speed": "multirotor's motors stop at zero voltage (rad/s)",
                 "rotor_radius": f"{src}: 18-inch propeller (m)",
                 "rotor_inertia": "multirotor leaves the spin-up torque out (kg m^2)",
                 "gravity": "SimulationParams g (m/s^2)",
                 "air_density": "SimulationParams rho (kg/m^3)"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


#: the position and altitude loops' gains (1/s), the path's lead compensation
#: (:func:`path_setpoints`)
POSITION_KP, ALTITUDE_KP = 1.2, 1.5


def path_setpoints(t: np.ndarray, seed: int, speed: float, compensate: bool = True
                   ) -> np.ndarray:
    """Setpoints (T, 4) ``[x, y, z, yaw]`` (m, rad) of a 3-D Lissajous figure with a yaw sweep
    and a small fast weave (roll/pitch excitation): x = 3 sin(w t) + a sin(4.5 w t), y = 1.5
    sin(2 w t + phi) + a sin(5.5 w t + phi), a = 0.1 m / max(speed, 0.5)^2, z = 2 + 0.3
    sin(1.7 w t), yaw = 0.4 sin(1.3 w t), w = 0.6 speed rad/s, phase phi from the seed. Each
    setpoint is the path plus its rate over the loop gain (the proportional loops' lag
    compensated; ``compensate=False``: the path itself)."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.6 * speed
    weave = 0.1 / max(speed, 0.5) ** 2
    terms = ((0, 3.0, w, 0.0), (1, 1.5, 2 * w, phi), (2, 0.3, 1.7 * w, 0.0),
             (0, weave, 4.5 * w, 0.0), (1, weave, 5.5 * w, phi), (3, 0.4, 1.3 * w, 0.0))
    out = np.zeros((len(t), 4))
    out[:, 2] = 2.0
    for column, amp, freq, phase in terms:
        arg = freq * t + phase
        gain = ALTITUDE_KP if column == 2 else POSITION_KP
        lead = freq / gain * np.cos(arg) if compensate and column < 3 else 0.0
        out[:, column] += amp * (np.sin(arg) + lead)
    return out


# ----------------------------------------------------------------------------- the job


def _flight_job(spec: FlightSpec) -> dict:
    """multirotor parameters and disturbances of one flight."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown multirotor effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    m = MODEL
    mass, com, inertia = mass_properties(e, m["mass"], m["inertia"])
    scale = rotor_scales(e)
    return {"mass": mass, "com": com, "inertia": inertia, "prop_scale": scale,
            "motor_inertia": m["motor_inertia"] * float(e.get("motor_slow", 1.0)),
            **disturbances(e)}


def _vehicle(job: dict):
    """multirotor's VehicleParams of a job: the propellers about the job's CoM."""
    from multirotor.vehicle import BatteryParams, MotorParams, PropellerParams, VehicleParams

    m = MODEL
    motor = MotorParams(moment_of_inertia=job["motor_inertia"], resistance=m["resistance"],
                        k_emf=m["k_emf"], speed_voltage_scaling=m["k_sv"],
                        max_current=m["max_current"])
    props = [PropellerParams(moment_of_inertia=m["prop_inertia"], use_thrust_constant=True,
                             k_thrust=m["k_thrust"] * s, k_drag=m["k_drag"] * s,
                             motor=deepcopy(motor)) for s in job["prop_scale"]]
    hubs = np.array([[m["arm"] * np.cos(a), m["arm"] * np.sin(a)] for a in m["angles"]])
    rel = hubs - job["com"][:2]
    return VehicleParams(propellers=props, battery=BatteryParams(max_voltage=m["max_voltage"]),
                         angles=np.arctan2(rel[:, 1], rel[:, 0]),
                         distances=np.linalg.norm(rel, axis=1),
                         clockwise=np.array(m["clockwise"]), mass=job["mass"],
                         inertia_matrix=np.asarray(job["inertia"], dtype=float))


def _controller(vehicle):
    """multirotor's cascaded PID (position -> velocity -> attitude -> rate; altitude ->
    climb rate) with gains for this vehicle (its defaults are P-only with unit gains)."""
    from multirotor.controller import (
        AltController,
        AltRateController,
        AttController,
        Controller,
        PosController,
        RateController,
        VelController,
    )

    return Controller(
        ctrl_p=PosController(k_p=POSITION_KP, k_i=0.0, k_d=0.0, max_err_i=1.0, vehicle=vehicle,
                             max_velocity=6.0, square_root_scaling=False, leashing=False),
        ctrl_v=VelController(k_p=0.25, k_i=0.05, k_d=0.0, max_err_i=2.0, vehicle=vehicle,
                             max_tilt=0.45),
        ctrl_a=AttController(k_p=np.array([6.0, 6.0, 3.0]), k_i=0.0, k_d=0.0, max_err_i=1.0,
                             vehicle=vehicle),
        ctrl_r=RateController(k_p=np.array([25.0, 25.0, 12.0]), k_i=np.array([1.0, 1.0, 1.0]),
                              k_d=0.0, max_err_i=1.0, vehicle=vehicle, max_acceleration=40.0),
        ctrl_z=AltController(k_p=ALTITUDE_KP, k_i=0.0, k_d=0.0, max_err_i=1.0, vehicle=vehicle,
                             max_velocity=3.0),
        ctrl_vz=AltRateController(k_p=3.0, k_i=1.0, k_d=0.0, max_err_i=10.0, vehicle=vehicle),
        period_p=0.01, period_a=0.005, period_z=0.01)


def _disturbance(job: dict, state: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame force and torque quadsim adds over one step (module doc)."""
    from multirotor.coords import direction_cosine_matrix

    to_body = direction_cosine_matrix(*state[6:9])          # world -> body
    air = state[3:6] - to_body @ job["wind"]
    force = -0.5 * MODEL["rho"] * np.asarray(MODEL["cd_area"]) * np.abs(air) * air
    force[2] += job["force"] * np.sin(2 * np.pi * job["force_hz"] * t)
    torque = -job["rate_damping"] * state[9:12] \
        + job["torque"] * np.sin(2 * np.pi * job["torque_hz"] * t)
    return force, torque


def _two_point_trapezoid(y, dx=1.0, axis=0):
    """``scipy.integrate.trapezoid`` of the two samples multirotor passes (its motor step and
    its PID integrators): scipy's own arithmetic ``dx (y1 + y0) / 2`` without its generic
    argument handling (a third of multirotor's time per step; the same numbers)."""
    return dx * (np.asarray(y[1], dtype=float) + np.asarray(y[0], dtype=float)) / 2.0


def _fly(args) -> dict:
    """One flight in multirotor: true states at :data:`PHYSICS_HZ` after the lead-in."""
    spec, job = args
    from multirotor import simulation
    from multirotor.controller import pid
    from multirotor.simulation import Multirotor
    from multirotor.vehicle import SimulationParams

    simulation.trapezoid = pid.trapezoid = _two_point_trapezoid

    dt = 1.0 / PHYSICS_HZ
    sim = SimulationParams(dt=dt, g=MODEL["gravity"], rho=MODEL["rho"], dtype=np.float64)
    vehicle = Multirotor(_vehicle(job), sim)
    ctrl = _controller(vehicle)
    vehicle.reset()
    lead, n = round(LEAD_IN * PHYSICS_HZ), round(spec.duration * PHYSICS_HZ)
    t = np.arange(lead + n + 1) * dt
    ref = path_setpoints(t, spec.seed, spec.speed)
    start = path_setpoints(t[:1], spec.seed, spec.speed, compensate=False)[0]
    vehicle.state[0:3] = start[:3]
    vehicle.state[8] = start[3]
    hover = hover_speed_of(job["mass"])
    for prop in vehicle.propellers:
        prop.speed = prop.motor.speed = hover
    ctrl.reset()
    states = np.empty((lead + n + 1, 12))
    speeds = np.empty((lead + n + 1, 4))
    commands = np.empty((lead + n + 1, 4))
    states[0] = vehicle.state
    speeds[0] = hover
    commands[0] = 0.0
    for k in range(lead + n):
        action = ctrl.step(ref[k])
        u = vehicle.allocate_control(action[0], action[1:4])
        force, torque = _disturbance(job, vehicle.state, t[k])
        vehicle.step_speeds(u, disturb_forces=force, disturb_torques=torque)
        if not np.all(np.isfinite(vehicle.state)) or abs(vehicle.state[6]) > 1.2 \
                or abs(vehicle.state[7]) > 1.2:
            raise ModelError(f"multirotor flight (seed {spec.seed}) lost control at "
                             f"t = {t[k]:.2f} s")
        states[k + 1] = vehicle.state
        speeds[k + 1] = [p.speed for p in vehicle.propellers]
        commands[k + 1] = np.clip(MODEL["k_sv"] * u / MODEL["max_voltage"], 0.0, 1.0)
    return {"states": states[lead:], "speeds": speeds[lead:], "commands": commands[lead:]}


def multirotor_flights(specs: list[FlightSpec], workers: int | None = None
                       ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec in multirotor (``workers`` processes, default: the CPU count, at most
    4) and return ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the
    truth sidecar (effects, the flight's multirotor parameters, seed, speed)."""
    if not multirotor_available():
        raise ModelError("multirotor is not installed (pip install -e '.[multirotor]' then "
                         "pip install --no-deps multirotor==0.5.0)")
    jobs = [_flight_job(s) for s in specs]
    return fly_all(_fly, to_flight_log, specs, jobs, source="multirotor", model="multirotor-x4",
                   rates=(PHYSICS_HZ, LOG_HZ), workers=workers)


def to_flight_log(raw: dict, spec: FlightSpec, com: np.ndarray) -> FlightLog:
    """multirotor's states (body velocity, Z-Y-X Euler angles, body rates) at 1 kHz -> a
    quadsim :class:`FlightLog` of the body origin at :data:`LOG_HZ` with the sensor model of
    ``spec.sensors`` (seeded by ``spec.seed``)."""
    x = raw["states"]
    quat = euler_to_quat(x[:, 6:9])
    rot = quat_to_rotmat(quat)
    vel = np.einsum("nij,nj->ni", rot, x[:, 3:6])
    dt = 1.0 / PHYSICS_HZ
    # the velocity step after each sample, and the rotor speeds and commands of that step
    acc = np.diff(vel, axis=0) / dt
    ang_acc = np.diff(x[:, 9:12], axis=0) / dt
    keep = np.arange(0, len(x) - 1, PHYSICS_HZ // LOG_HZ)
    states = SimStates(rate_hz=LOG_HZ, pos=x[keep, 0:3], vel=vel[keep], quat=quat[keep],
                       ang_vel=x[keep, 9:12], ang_acc=ang_acc[keep], acc=acc[keep],
                       rotor_speed=raw["speeds"][keep + 1], command=raw["commands"][keep + 1])
    return body_origin_log(states, com, spec.sensors, spec.seed, hover_speed=hover_speed_of(),
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)))
