"""Flights of an independent simulator: quadcopter-sim 0.3.0 (2black0, PyPI
``quadcopter-sim``, github.com/2black0/quadcopter-sim-python, MIT): its own rigid-body
equations (``quadcopter.dynamics.derivative``: position and world velocity, a scalar-first
quaternion, body rates, the inertia matrix solved per call) and its own vehicle, a 0.65 kg
quadrotor in **plus** configuration -- the first of the project's sources whose rotors sit
on the body axes, so roll is made by two rotors and pitch by the other two.

What quadcopter-sim models: thrust ``b Omega_i^2`` per rotor along body z, roll torque
``l b (Omega_3^2 - Omega_1^2)``, pitch torque ``l b (Omega_4^2 - Omega_2^2)``, yaw torque
``d (Omega_2^2 + Omega_4^2 - Omega_1^2 - Omega_3^2)``, gravity, and nothing else: no motor,
no air, no CoM offset. Its controllers are placeholders (its ``PositionController`` mixes
position errors straight into rotor speeds), so the flights use quadsim's geometric
controller (:class:`benchmarks.geometric.Geometric`).

quadsim adds (each documented where it is defined; the references share the first two):

* **DC motors** (:data:`MOTOR`, :class:`benchmarks.geometric.DCMotor`): ``J dOmega/dt =
  k_t (c V - k_e Omega) / R - d_i Omega^2`` with the duty cycle c in 0..1 of a 3S battery (11.1 V),
  motor constants of a 380 KV outrunner (k_t = k_e = 60 / (2 pi 380) V s/rad, R 0.12 ohm) and the
  rotor and 12-inch propeller's J 1.2e-4 kg m^2: the time constant at hover is 21 ms, hover needs a
  duty of 0.52, a propeller with less drag torque spins faster per command. The current may
  turn negative (an ESC with active braking): spin-up and spin-down alike.
* **Body drag** on each body axis, ``-1/2 rho C_dA_i |v_i| v_i`` of the air-relative
  velocity (C_dA 0.015, 0.015, 0.04 m^2: a 0.15 m x 0.1 m hub and battery from the side, the
  arms and hub from above, C_d ~ 1); without it a wind acts through nothing.
* The case effects quadcopter-sim has no parameter for: a CoM offset (the rotors' thrust
  about the moved CoM: ``-c x T z``), one weak rotor (its Omega passed as ``sqrt(s) Omega``:
  thrust and drag torque both x s), rate damping, wind, a periodic torque or force, a late
  rotor log. Mass and inertia go through quadcopter-sim's own ``Params`` (m, the full I).

Integration: the rigid body's 13 states and the 4 motor speeds together by a fixed-step RK4
at :data:`PHYSICS_HZ` (quadcopter-sim's ``simulate(method="rk4")`` is the same scheme but has
no hook for the motors or added loads), the duty cycles held over each step, the controller
at :data:`CONTROL_HZ`.

Vehicle (:data:`MODEL`, "qcsim-plus"): quadcopter-sim's defaults (``Params()``: m 0.65 kg,
l 0.25 m, b 3.25e-5 N s^2, d 7.5e-7 N m s^2, I diag(7.5e-3, 7.5e-3, 1.3e-2) kg m^2, g 9.81
m/s^2); rotor 1 on -y, 2 on +x, 3 on +y, 4 on -x (from its torque equations), 2 and 4
turning clockwise seen from above (their reaction torque +z). A 12-inch propeller (radius
0.1524 m) is the one whose coefficients match b and d: C_T = b / (rho D^4 / 4 pi^2) 0.12,
C_P 0.058 at hover (221 rad/s).

The log (:func:`to_flight_log`, 500 Hz: every second 1 kHz step; :mod:`.simlog`): motion of
the body origin with motion-capture noise, gyro and accelerometer (specific force from the
velocity step) with IMU noise, rotor speeds (the mean of each step's first and last motor
speed, the speed that made that step's thrust) with telemetry noise, delayed by
``rotor_delay`` s when asked, and commands as the duty cycle.

Units and frames: quadcopter-sim's are quadsim's (world z up, body x forward, y left, z up,
quaternion w-first body -> world, body rates); its rotor speeds are rad/s.

Example::

    >>> log, truth = qcsim_flights([FlightSpec(seed=1, effects={"mass": 0.05})])[0]
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass, field

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.core.frames import quat_to_rotmat
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, fly_all, mass_properties, rotor_scales
from .geometric import DCMotor, Geometric
from .simlog import Sensors, SimStates, body_origin_log, truth_json

__all__ = ["CONTROL_HZ", "EFFECTS", "LOG_HZ", "MODEL", "MOTOR", "PHYSICS_HZ", "FlightSpec",
           "Geometric", "Sensors", "duty_for", "hover_speed_of", "motor_acceleration", "path",
           "qcsim_available", "qcsim_flights", "steady_speed", "to_flight_log", "truth_json",
           "vehicle_params"]

PHYSICS_HZ = 1000
CONTROL_HZ = 500
LOG_HZ = 500
#: s flown before the log starts (the controller's integrals settle)
LEAD_IN = 2.0
#: the vehicle in SI units (module doc): quadcopter-sim's Params() defaults, rotor layout and
#: spins from its derivative(); quadsim's motor, battery, propeller radius and body drag
MODEL = {"mass": 0.65, "inertia": (7.5e-3, 7.5e-3, 1.3e-2), "arm": 0.25, "b": 3.25e-5,
         "d": 7.5e-7, "gravity": 9.81,
         "positions": ((0.0, -1.0), (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)),
         "reaction": (-1, 1, -1, 1),
         "battery": 11.1, "k_emf": 60.0 / (2 * np.pi * 380.0), "resistance": 0.12,
         "motor_inertia": 1.2e-4, "cd_area": (0.015, 0.015, 0.04), "rho": 1.225,
         "rotor_radius": 0.1524}
#: case-side effects (:class:`FlightSpec.effects`, :mod:`.flightjobs`), SI: mass, payload,
#: com, inertia, weak_rotor, thrust_scale; motor_slow (factor on the motors' J);
#: rate_damping, wind, torque, torque_hz, force, force_hz; rotor_delay (s, the log only)
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


def qcsim_available() -> bool:
    """quadcopter-sim importable (its import name is ``quadcopter``; checked without importing
    it)."""
    return importlib.util.find_spec("quadcopter") is not None \
        and importlib.util.find_spec("quadcopter.dynamics") is not None


def hover_speed_of(mass: float = MODEL["mass"]) -> float:
    """Rotor speed (rad/s) at which the four rotors carry ``mass`` (kg): sqrt(m g / 4 b)."""
    return float(np.sqrt(mass * MODEL["gravity"] / (4 * MODEL["b"])))


#: the motors (module doc): 380 KV on 3S, the rotor and 12-inch propeller's J
MOTOR = DCMotor(battery=MODEL["battery"], k_emf=MODEL["k_emf"], resistance=MODEL["resistance"],
                inertia=MODEL["motor_inertia"])


def steady_speed(duty, k_drag: float = MODEL["d"]) -> np.ndarray:
    """Steady rotor speed (rad/s) at duty cycle ``duty`` (0..1 of the battery)
    (:meth:`benchmarks.geometric.DCMotor.steady_speed`)."""
    return MOTOR.steady_speed(duty, k_drag)


def duty_for(speed) -> np.ndarray:
    """The duty cycle whose steady speed is ``speed`` (rad/s) with the nominal propeller (the
    controller's feed-forward)."""
    return MOTOR.duty_for(speed, MODEL["d"])


def motor_acceleration(speed, duty, k_drag, inertia) -> np.ndarray:
    """dOmega/dt (rad/s^2) of the DC motors; ``k_drag`` (4,) per rotor, ``inertia`` J."""
    return MOTOR.acceleration(speed, duty, k_drag, inertia)


def _rotor_positions() -> np.ndarray:
    return MODEL["arm"] * np.array([[x, y, 0.0] for x, y in MODEL["positions"]])


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of the nominal vehicle (module doc)."""
    m = MODEL
    rotors = tuple(Rotor(str(i + 1), p, np.array([0.0, 0.0, 1.0]), -float(r))
                   for i, (p, r) in enumerate(zip(_rotor_positions(), m["reaction"])))
    grid = np.linspace(0.0, 1.0, 41)
    speed = steady_speed(grid)
    src = "quadcopter-sim 0.3.0 quadcopter/dynamics.py Params()"
    params = VehicleParams(
        name="qcsim-plus", mass=m["mass"], com=np.zeros(3), inertia=np.diag(m["inertia"]),
        rotors=rotors, thrust_factor=m["b"], drag_factor=m["d"], max_speed=float(speed[-1]),
        min_speed=0.0, rotor_radius=m["rotor_radius"], rotor_inertia=0.0,
        gravity=m["gravity"], air_density=m["rho"],
        motor_map=MotorMap("1", grid, np.tile(speed, (4, 1)),
                           "the DC motor in steady state (steady_speed): duty cycle of "
                           "11.1 V -> rad/s"),
        description="quadcopter-sim 0.3.0's 0.65 kg plus-configuration quadrotor with quadsim's "
                    "DC motors (380 KV, 3S) as quadsim sees it",
        sources={"mass": f"{src}: m (kg)", "inertia": f"{src}: I (kg m^2)",
                 "rotors": f"{src}: l 0.25 m; rotors on -y, +x, +y, -x and spins from "
                           "derivative()'s torque equations (m)",
                 "thrust_factor": f"{src}: b (N s^2/rad^2)",
                 "drag_factor": f"{src}: d (N m s^2/rad^2)",
                 "max_speed": "steady speed at full duty (rad/s)",
                 "min_speed": "the motors stop at zero duty (rad/s)",
                 "rotor_radius": "12-inch propeller: C_T 0.12, C_P 0.058 match b, d (m)",
                 "rotor_inertia": "quadcopter-sim leaves the spin-up torque out (kg m^2)",
                 "gravity": f"{src}: g (m/s^2)",
                 "air_density": "ISA sea level (kg/m^3)"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path(t: np.ndarray, seed: int, speed: float) -> tuple[np.ndarray, np.ndarray,
                                                          np.ndarray, np.ndarray, np.ndarray]:
    """Setpoints of a wandering loop with altitude swells, a yaw sweep and a small fast weave
    (roll/pitch excitation): position, velocity, acceleration (T, 3) (m, m/s, m/s^2), yaw
    and yaw rate (T,) (rad, rad/s). x = 2 cos(w t + phi) + 0.4 sin(3.3 w t) + a sin(6.5 w t),
    y = 1.4 sin(w t + phi) + 0.5 sin(2.1 w t + phi) + a sin(7.5 w t + phi), z = 1.5 + 0.4
    sin(1.3 w t) + 0.12 sin(4.1 w t), yaw = 0.6 sin(0.9 w t), a = 0.06 m / max(speed, 0.5)^2,
    w = 0.55 speed rad/s, phase phi from the seed."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.55 * speed
    weave = 0.06 / max(speed, 0.5) ** 2
    # (column, amplitude, frequency, phase): cos(a) = sin(a + pi/2)
    terms = ((0, 2.0, w, phi + np.pi / 2), (0, 0.4, 3.3 * w, 0.0), (0, weave, 6.5 * w, 0.0),
             (1, 1.4, w, phi), (1, 0.5, 2.1 * w, phi), (1, weave, 7.5 * w, phi),
             (2, 0.4, 1.3 * w, 0.0), (2, 0.12, 4.1 * w, 0.0))
    pos, vel, acc = np.zeros((len(t), 3)), np.zeros((len(t), 3)), np.zeros((len(t), 3))
    pos[:, 2] = 1.5
    for column, amp, freq, phase in terms:
        arg = freq * t + phase
        pos[:, column] += amp * np.sin(arg)
        vel[:, column] += amp * freq * np.cos(arg)
        acc[:, column] -= amp * freq ** 2 * np.sin(arg)
    return pos, vel, acc, 0.6 * np.sin(0.9 * w * t), 0.6 * 0.9 * w * np.cos(0.9 * w * t)


# ----------------------------------------------------------------------------- the job


def _flight_job(spec: FlightSpec) -> dict:
    """quadcopter-sim parameters and this module's additions of one flight (SI)."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown quadcopter-sim effect(s) {sorted(unknown)}; valid: "
                         f"{EFFECTS}")
    mass, com, inertia = mass_properties(e, MODEL["mass"], MODEL["inertia"])
    return {"mass": mass, "com": com, "inertia": inertia, "rotor_scale": rotor_scales(e),
            "motor_inertia": MODEL["motor_inertia"] * float(e.get("motor_slow", 1.0)),
            **disturbances(e)}


def _added(job: dict, y: np.ndarray, speeds: np.ndarray, t: float
           ) -> tuple[np.ndarray, np.ndarray]:
    """World acceleration and body angular acceleration quadsim adds to quadcopter-sim's
    (module doc): body drag (wind), the CoM offset's thrust moment, rate damping, the periodic
    torque and force."""
    m = MODEL
    rot = quat_to_rotmat(y[6:10] / np.linalg.norm(y[6:10]))
    air = rot.T @ (y[3:6] - job["wind"])
    force = -0.5 * m["rho"] * np.asarray(m["cd_area"]) * np.abs(air) * air
    force[2] += job["force"] * np.sin(2 * np.pi * job["force_hz"] * t)
    thrust = m["b"] * float(job["rotor_scale"] @ (speeds * speeds))
    c = job["com"]
    torque = np.array([-c[1] * thrust, c[0] * thrust, 0.0]) - job["rate_damping"] * y[10:13] \
        + job["torque"] * np.sin(2 * np.pi * job["torque_hz"] * t)
    return rot @ force / job["mass"], np.linalg.solve(job["inertia"], torque)


def _fly(args) -> dict:
    """One flight: quadcopter-sim's rigid body and quadsim's motors by RK4 (module doc); true
    states at :data:`PHYSICS_HZ` after the lead-in."""
    spec, job = args
    from quadcopter.dynamics import Params, derivative

    m = MODEL
    params = Params(m=job["mass"], g=m["gravity"], l=m["arm"], b=m["b"], d=m["d"],
                    I=np.asarray(job["inertia"], dtype=float))
    root = np.sqrt(job["rotor_scale"])
    k_drag = m["d"] * job["rotor_scale"]

    def rhs(t, x, duty):
        speeds = x[13:17]
        out = np.empty(17)
        out[:13] = derivative(t, x[:13], root * speeds, params)
        acc, ang = _added(job, x[:13], speeds, t)
        out[3:6] += acc
        out[10:13] += ang
        out[13:17] = motor_acceleration(speeds, duty, k_drag, job["motor_inertia"])
        return out

    dt = 1.0 / PHYSICS_HZ
    every = PHYSICS_HZ // CONTROL_HZ
    lead, n = round(LEAD_IN * PHYSICS_HZ), round(spec.duration * PHYSICS_HZ)
    t = np.arange(lead + n + 1) * dt
    sp_pos, sp_vel, sp_acc, sp_yaw, sp_yaw_rate = path(t, spec.seed, spec.speed)
    ctrl = Geometric(every * dt, vehicle_params(), duty_for)
    x = np.zeros(17)
    x[0:3], x[3:6], x[6] = sp_pos[0], sp_vel[0], 1.0
    x[13:17] = hover_speed_of(job["mass"]) / root
    states = np.empty((lead + n + 1, 13))
    speeds = np.empty((lead + n + 1, 4))
    commands = np.empty((lead + n + 1, 4))
    states[0], speeds[0] = x[:13], x[13:17]
    duty = duty_for(x[13:17])
    commands[0] = duty
    for k in range(lead + n):
        if k % every == 0:
            duty = ctrl.step(x[0:3], x[3:6], x[6:10], x[10:13], sp_pos[k], sp_vel[k],
                             sp_acc[k], sp_yaw[k], sp_yaw_rate[k])
        k1 = rhs(t[k], x, duty)
        k2 = rhs(t[k] + dt / 2, x + dt / 2 * k1, duty)
        k3 = rhs(t[k] + dt / 2, x + dt / 2 * k2, duty)
        k4 = rhs(t[k] + dt, x + dt * k3, duty)
        start = x[13:17].copy()
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        x[6:10] /= np.linalg.norm(x[6:10])
        if not np.all(np.isfinite(x)) or x[6] ** 2 < 0.5:
            raise ModelError(f"quadcopter-sim flight (seed {spec.seed}) lost control at "
                             f"t = {t[k]:.2f} s")
        states[k + 1] = x[:13]
        speeds[k + 1] = 0.5 * (start + x[13:17])
        commands[k + 1] = duty
    return {"states": states[lead:], "speeds": speeds[lead:], "commands": commands[lead:]}


def qcsim_flights(specs: list[FlightSpec], workers: int | None = None
                  ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec (``workers`` processes, default: the CPU count, at most 4) and return
    ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth sidecar
    (effects, the flight's parameters, seed, speed)."""
    if not qcsim_available():
        raise ModelError("quadcopter-sim is not installed (pip install -e '.[qcsim]')")
    jobs = [_flight_job(s) for s in specs]
    return fly_all(_fly, to_flight_log, specs, jobs, source="quadcopter-sim",
                   model="qcsim-plus", rates=(PHYSICS_HZ, LOG_HZ), workers=workers)


def to_flight_log(raw: dict, spec: FlightSpec, com: np.ndarray) -> FlightLog:
    """The true states (CoM position and world velocity, quaternion, body rate) at 1 kHz, the
    rotor speeds of each step -> a quadsim :class:`FlightLog` of the body origin at
    :data:`LOG_HZ` with the sensor model of ``spec.sensors`` (seeded by ``spec.seed``)."""
    x = raw["states"]
    dt = 1.0 / PHYSICS_HZ
    acc = np.diff(x[:, 3:6], axis=0) / dt
    ang_acc = np.diff(x[:, 10:13], axis=0) / dt
    keep = np.arange(0, len(x) - 1, PHYSICS_HZ // LOG_HZ)
    states = SimStates(rate_hz=LOG_HZ, pos=x[keep, 0:3], vel=x[keep, 3:6], quat=x[keep, 6:10],
                       ang_vel=x[keep, 10:13], ang_acc=ang_acc[keep], acc=acc[keep],
                       rotor_speed=raw["speeds"][keep + 1], command=raw["commands"][keep + 1])
    return body_origin_log(states, com, spec.sensors, spec.seed, hover_speed=hover_speed_of(),
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)),
                           gravity=MODEL["gravity"])
