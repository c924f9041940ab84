"""Flights of an independent simulator source the project had never used: drones-sim
(``drones-sim`` 0.2.0 on the package index, pure Python), its six-degree-of-freedom plant,
its disturbances and its SE(3) controller.

What is drones-sim's own: the plant (``drones_sim.dynamics.QuadcopterDynamics``: a
13-state rigid body, quaternion body -> world, its fixed-step RK4 with the rotor speeds held
over the step), the rotor forces (``allocation_matrix``: per rotor a thrust ``k_f Omega^2``
along body z and a moment ``dir k_m Omega^2`` about it, at the rotor's place ``rotor_positions``
of ``QuadcopterConfig``), the rotor dynamics (an exact first-order lag of each speed on its
command, ``motor_time_constant``), the drag (linear in the body-axis air velocity,
``-linear_drag v_air``, at the CoM), the wind (``ConstantWind``: the drag on the air
velocity), the rotor efficiency (``MotorFailure``: a factor on one rotor's or every rotor's
thrust and moment), the disturbance hooks (``Disturbance.external_force`` world,
``external_torque`` body), the vehicle (``QuadcopterConfig()``'s defaults: m 1.0 kg, I
diag(0.01, 0.01, 0.018) kg m^2, arm 0.2 m in a plus layout (front, +y, rear, -y), k_f 1e-6
N s^2/rad^2, k_m 1e-7 N m s^2/rad^2, rotor directions +1, -1, +1, -1, linear drag 0.1
N/(m/s) on each body axis, motor time constant 40 ms, speeds 0-4000 rad/s, g 9.81; the
propeller radius 0.06 m of its ``models/quadcopter.urdf``) and the controller
(``drones_sim.control.GeometricController`` with its default gains and its bounded
least-squares allocator, given a nominal plant: it knows only the nominal values).

What is this project's: the path (:func:`path`, the Drake source's loop), the case handles
that drones-sim has no parameter for -- a CoM off the rotors' centre (the rotors' places
relative to the CoM moved, :class:`_ShiftedConfig`), the rate damping and the periodic body
torque and body-z force (:class:`_Loads`, through drones-sim's ``Disturbance`` hooks) -- and
the log conversion (:mod:`.simlog`'s shared sensor noise).

Case changes (:data:`EFFECTS`, SI): ``mass``, ``payload`` (point mass: mass, CoM and the
full inertia, drones-sim's config takes a full matrix), ``com`` (x, y m), ``inertia``
(relative change of Ixx, Iyy, Izz), ``weak_rotor`` and ``thrust_scale`` (``MotorFailure``
efficiencies from t = 0), ``motor_slow`` (factor on the motor time constant),
``drag_scale`` (factor on the linear drag), ``wind`` (m/s world x, y; ``ConstantWind``),
``rate_damping`` (-k w, body), ``torque`` at ``torque_hz``, ``force`` at ``force_hz``,
``rotor_delay`` (the rotor-speed log only, s late).

The log (:func:`to_flight_log`, :data:`LOG_HZ` = the control rate): per control step k the
plant after ``update(dt, command_k)``: its state (CoM), the rotor speeds held over that step
(``get_motor_speeds``), the plant's own acceleration and angular acceleration of that state
under them (``last_acceleration``, ``last_angular_acceleration``), the command_k (speed
command / the top speed); moved to the rotors' centre (:func:`.simlog.body_origin_log`)
with the other sources' sensor noise.

Example::

    >>> log, truth = dsim_flights([FlightSpec(seed=1, effects={"mass": 0.05})])[0]
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass, field

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, fly_all, mass_properties, rotor_scales
from .simlog import Sensors, SimStates, body_origin_log

__all__ = ["CONTROL_HZ", "EFFECTS", "LEAD_IN", "LOG_HZ", "ROTOR_RADIUS", "FlightSpec",
           "dsim_available", "dsim_flights", "dsim_params", "fly_one", "hover_speed",
           "make_plant", "path", "to_flight_log", "vehicle_params"]

#: the controller's rate = the plant's RK4 step (Hz); the log's rate
CONTROL_HZ = 500
LOG_HZ = 500
#: s flown before the log starts (the integrals settle)
LEAD_IN = 3.0
#: m: the propeller disc radius of drones-sim's models/quadcopter.urdf (its ``prop`` links'
#: cylinder radius 0.06)
ROTOR_RADIUS = 0.06
#: case-side changes (module doc)
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "motor_slow",
           "drag_scale", "wind", "rate_damping", "torque", "torque_hz", "force", "force_hz",
           "rotor_delay")


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, sensor noise), speed factor of the path, duration (s,
    logged), case-side changes (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def dsim_available() -> bool:
    """drones_sim importable (checked without importing it)."""
    return importlib.util.find_spec("drones_sim") is not None


def dsim_params() -> dict:
    """drones-sim's default vehicle (``QuadcopterConfig()``): m kg, g m/s^2, L m, I (3, 3)
    kg m^2, kf N s^2/rad^2, km N m s^2/rad^2, drag (3,) N/(m/s), tau s, wmin, wmax rad/s,
    dirs (4,), pos (4, 3) m."""
    if not dsim_available():
        raise ModelError("drones-sim is not installed (pip install -e '.[dsim]')")
    from drones_sim.dynamics import QuadcopterConfig

    c = QuadcopterConfig()
    return {"m": c.mass, "g": c.gravity, "L": c.arm_length, "I": c.inertia.copy(),
            "kf": c.thrust_coefficient, "km": c.moment_coefficient,
            "drag": c.linear_drag.copy(), "quad_drag": c.quadratic_drag.copy(),
            "tau": c.motor_time_constant, "wmin": c.min_motor_speed,
            "wmax": c.max_motor_speed, "dirs": c.rotor_directions.copy(),
            "pos": c.rotor_positions.copy()}


def hover_speed(mass: float | None = None) -> float:
    """Rotor speed (rad/s) at which four nominal rotors carry ``mass`` (kg; default the
    vehicle's): sqrt(m g / (4 k_f))."""
    p = dsim_params()
    m = p["m"] if mass is None else mass
    return float(np.sqrt(m * p["g"] / 4.0 / p["kf"]))


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of drones-sim's default vehicle: ``QuadcopterConfig()``'s
    values, not fitted; rotor k at ``rotor_positions``, spin -direction (a moment +k_m along
    +z is the reaction of a clockwise rotor); the command map linear, speed command / the top
    speed; no rotor dynamics and no drag (quadsim's nominal model has neither: the shared
    effects of :mod:`.dsim_cases` carry them)."""
    p = dsim_params()
    src = "drones-sim 0.2.0 QuadcopterConfig()"
    rotors = tuple(Rotor(str(k + 1), np.asarray(pos, dtype=float), np.array([0.0, 0.0, 1.0]),
                         -float(d)) for k, (pos, d) in enumerate(zip(p["pos"], p["dirs"])))
    top = p["wmax"]
    params = VehicleParams(
        name="drones-sim-quadcopter", mass=p["m"], com=np.zeros(3), inertia=p["I"],
        rotors=rotors, thrust_factor=p["kf"], drag_factor=p["km"], max_speed=top,
        min_speed=p["wmin"], gravity=p["g"], rotor_radius=ROTOR_RADIUS,
        motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array([[0.0, top]] * 4),
                           "command = speed command / max_motor_speed"),
        description="drones-sim's default QuadcopterConfig as quadsim sees it",
        sources={"mass": f"{src}.mass", "inertia": f"{src}.inertia",
                 "rotors": f"{src}.rotor_positions, rotor_directions",
                 "thrust_factor": f"{src}.thrust_coefficient",
                 "drag_factor": f"{src}.moment_coefficient",
                 "max_speed": f"{src}.max_motor_speed",
                 "min_speed": f"{src}.min_motor_speed",
                 "rotor_radius": "drones_sim/models/quadcopter.urdf prop cylinder radius",
                 "gravity": f"{src}.gravity"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path(t: np.ndarray, seed: int, speed: float) -> dict:
    """Setpoints of a wandering loop: ``pos``, ``vel``, ``acc`` (T, 3) (m, m/s, m/s^2),
    ``yaw``, ``yaw_rate`` (T,) (rad, rad/s): the Drake source's loop
    (:func:`benchmarks.drake_source.path`, copied so that this source's code hash covers it):
    x = 0.7 cos(w t + phi) + 0.15 sin(2.7 w t) + a sin(6.1 w t), y = 0.5 sin(w t + phi) + 0.2
    sin(1.9 w t + phi) + a sin(7.3 w t + phi), z = 1.5 + 0.2 sin(1.3 w t) + 0.05 sin(3.7 w t),
    yaw = 0.5 sin(0.8 w t), a = 0.03 m / max(speed, 0.5)^2, w = 0.9 speed rad/s, phase phi
    from the seed."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.9 * speed
    weave = 0.03 / max(speed, 0.5) ** 2
    terms = ((0, 0.7, w, phi + np.pi / 2), (0, 0.15, 2.7 * w, 0.0), (0, weave, 6.1 * w, 0.0),
             (1, 0.5, w, phi), (1, 0.2, 1.9 * w, phi), (1, weave, 7.3 * w, phi),
             (2, 0.2, 1.3 * w, 0.0), (2, 0.05, 3.7 * w, 0.0))
    pos, vel, acc = np.zeros((len(t), 3)), np.zeros((len(t), 3)), np.zeros((len(t), 3))
    pos[:, 2] = 1.5
    for column, amp, freq, phase in terms:
        arg = freq * t + phase
        pos[:, column] += amp * np.sin(arg)
        vel[:, column] += amp * freq * np.cos(arg)
        acc[:, column] -= amp * freq ** 2 * np.sin(arg)
    return {"pos": pos, "vel": vel, "acc": acc, "yaw": 0.5 * np.sin(0.8 * w * t),
            "yaw_rate": 0.5 * 0.8 * w * np.cos(0.8 * w * t)}


# ----------------------------------------------------------------------------- the plant


def _job(spec: FlightSpec) -> dict:
    """The flight's changes in SI (module doc)."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown drones-sim effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    p = dsim_params()
    mass, com, inertia = mass_properties(e, p["m"], np.diag(p["I"]))
    return {"mass": mass, "com": com, "J": inertia, "rotor_scale": rotor_scales(e),
            "motor_tau": p["tau"] * float(e.get("motor_slow", 1.0)),
            "drag": p["drag"] * float(e.get("drag_scale", 1.0)), **disturbances(e)}


def _shifted_config_class():
    """:class:`_ShiftedConfig` (built on first use: drones_sim imported lazily)."""
    from drones_sim.dynamics import QuadcopterConfig

    class _ShiftedConfig(QuadcopterConfig):
        """drones-sim's config with the rotors' places relative to the CoM moved by -com
        (this project's: drones-sim's plant integrates its CoM and places the rotors at
        ``rotor_positions``; a CoM off the rotors' centre is those places moved)."""

        def __init__(self, *args, com=(0.0, 0.0, 0.0), **kwargs):
            self.com = np.asarray(com, dtype=float)
            super().__init__(*args, **kwargs)

        @property
        def rotor_positions(self):
            return super().rotor_positions - self.com

    return _ShiftedConfig


def _loads_class():
    """:class:`_Loads` (built on first use: drones_sim imported lazily)."""
    from drones_sim.dynamics import Disturbance
    from drones_sim.math_utils import quat_to_rotation_matrix

    class _Loads(Disturbance):
        """This project's loads through drones-sim's disturbance hooks: a body torque -k w
        + torque sin(2 pi torque_hz t), a body-z force force sin(2 pi force_hz t) rotated to
        the world (state: position, velocity, quaternion wxyz, body rates)."""

        def __init__(self, job: dict):
            self.damping = np.asarray(job["rate_damping"], dtype=float)
            self.torque, self.torque_hz = (np.asarray(job["torque"], dtype=float),
                                           float(job["torque_hz"]))
            self.force, self.force_hz = float(job["force"]), float(job["force_hz"])

        def external_force(self, t, dt, state):
            rot = quat_to_rotation_matrix(state[6:10])
            return rot[:, 2] * self.force * np.sin(2 * np.pi * self.force_hz * t)

        def external_torque(self, t, dt, state):
            return (-self.damping * state[10:13]
                    + self.torque * np.sin(2 * np.pi * self.torque_hz * t))

    return _Loads


def make_plant(job: dict):
    """drones-sim's plant of one flight (``QuadcopterDynamics`` with a config of the job's
    mass, inertia, CoM, motor time constant and drag, and the disturbances: ``MotorFailure``
    from t = 0 per rotor whose factor is not 1, ``ConstantWind`` when the wind is not zero,
    :class:`_Loads` when a load is not zero); ``job`` as :func:`_job` makes it."""
    from drones_sim.dynamics import ConstantWind, MotorFailure, QuadcopterDynamics

    p = dsim_params()
    config = _shifted_config_class()(
        mass=float(job["mass"]), inertia=np.asarray(job["J"], dtype=float),
        arm_length=p["L"], thrust_coefficient=p["kf"], moment_coefficient=p["km"],
        linear_drag=np.asarray(job["drag"], dtype=float), quadratic_drag=p["quad_drag"],
        gravity=p["g"], motor_time_constant=float(job["motor_tau"]),
        min_motor_speed=p["wmin"], max_motor_speed=p["wmax"], rotor_directions=p["dirs"],
        com=np.asarray(job["com"], dtype=float))
    extra = [MotorFailure([k], efficiency=float(s), t_fail=0.0)
             for k, s in enumerate(np.asarray(job["rotor_scale"], dtype=float)) if s != 1.0]
    if np.any(np.asarray(job["wind"]) != 0):
        extra.append(ConstantWind(np.asarray(job["wind"], dtype=float)))
    if (np.any(np.asarray(job["rate_damping"]) != 0) or job["force"] != 0
            or np.any(np.asarray(job["torque"]) != 0)):
        extra.append(_loads_class()(job))
    return QuadcopterDynamics(config=config, disturbances=extra)


# ----------------------------------------------------------------------------- flying


def fly_one(args: tuple) -> dict:
    """One flight ``(spec, job)`` (top level: run in worker processes): the lead-in plus the
    logged samples at :data:`CONTROL_HZ` (module doc); (T, ...) arrays pos, vel (world,
    CoM), quat (wxyz body -> world), ang_vel, ang_acc (body), acc (world), rotor, cmd
    (rad/s). drones-sim's ``GeometricController`` on a nominal plant (the nominal values)
    reads the true state. A flight that leaves control (tilt past 60 deg, below 0.05 m,
    non-finite) raises ModelError."""
    from drones_sim.control.geometric import GeometricController
    from drones_sim.state import TrajectorySetpoint

    spec, job = args
    p = dsim_params()
    plant = make_plant(job)
    nominal = make_plant({"mass": p["m"], "com": np.zeros(3), "J": p["I"],
                          "rotor_scale": np.ones(4), "motor_tau": p["tau"], "drag": p["drag"],
                          **disturbances({})})
    ctrl = GeometricController(nominal)
    lead = round(LEAD_IN * CONTROL_HZ)
    n = round(spec.duration * CONTROL_HZ)
    dt = 1.0 / CONTROL_HZ
    sp_all = path(np.arange(lead + n + 1) * dt, spec.seed, spec.speed)
    plant.reset(position=sp_all["pos"][0], attitude=np.array([0.0, 0.0, sp_all["yaw"][0]]))
    plant.state[3:6] = sp_all["vel"][0]
    plant.motor_states = np.full(4, hover_speed(job["mass"]
                                                / float(np.mean(job["rotor_scale"]))))
    out = {k: np.zeros((n, 4 if k in ("quat", "rotor", "cmd") else 3))
           for k in ("pos", "vel", "quat", "ang_vel", "ang_acc", "acc", "rotor", "cmd")}
    for k in range(lead + n):
        state = plant.get_state()
        sp = TrajectorySetpoint(position=sp_all["pos"][k], velocity=sp_all["vel"][k],
                                acceleration=sp_all["acc"][k], yaw=float(sp_all["yaw"][k]),
                                yaw_rate=float(sp_all["yaw_rate"][k]))
        cmd = ctrl.compute_output(sp, dt, state=state).motor_speeds
        x = plant.update(dt, cmd)
        tilt = plant.rotation_matrix()[2, 2]
        if not np.all(np.isfinite(x)) or tilt < 0.5 or x[2] < 0.05:
            raise ModelError(f"drones-sim flight (seed {spec.seed}) lost control at t = "
                             f"{(k + 1) * dt - LEAD_IN:.3f} s")
        if k >= lead:
            i = k - lead
            out["pos"][i], out["vel"][i], out["quat"][i] = x[0:3], x[3:6], x[6:10]
            out["ang_vel"][i] = x[10:13]
            out["ang_acc"][i] = plant.last_angular_acceleration
            out["acc"][i] = plant.last_acceleration
            out["rotor"][i], out["cmd"][i] = plant.get_motor_speeds(), cmd
    return out


def dsim_flights(specs: list[FlightSpec], workers: int | None = None
                 ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec (in ``workers`` processes, :func:`benchmarks.flightjobs.fly_all`) and
    return ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth
    sidecar (effects, the flight's changes in SI, seed, speed)."""
    if not dsim_available():
        raise ModelError("drones-sim is not installed (pip install -e '.[dsim]')")
    jobs = [_job(s) for s in specs]
    return fly_all(fly_one, to_flight_log, specs, jobs, source="drones-sim",
                   model="QuadcopterDynamics", rates=(CONTROL_HZ, LOG_HZ), workers=workers)


def to_flight_log(raw: dict, spec: FlightSpec, com=None) -> FlightLog:
    """:func:`fly_one`'s samples (of the CoM) -> a quadsim :class:`FlightLog` of the rotors'
    centre (``com`` (3,) m body: the CoM relative to it) with the sensor model of
    ``spec.sensors`` (seeded by ``spec.seed``; the rotor log ``rotor_delay`` s late when the
    spec asks)."""
    p = dsim_params()
    states = SimStates(rate_hz=LOG_HZ, pos=raw["pos"], vel=raw["vel"], quat=raw["quat"],
                       ang_vel=raw["ang_vel"], ang_acc=raw["ang_acc"], acc=raw["acc"],
                       rotor_speed=raw["rotor"], command=raw["cmd"] / p["wmax"])
    return body_origin_log(states, np.zeros(3) if com is None else np.asarray(com, float),
                           spec.sensors, spec.seed, hover_speed=hover_speed(),
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)),
                           gravity=p["g"])
