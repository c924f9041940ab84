"""Flights of an independent simulator source the project had never used: Peter Corke's
Robotics Toolbox for Python (``roboticstoolbox-python`` 1.5.0 on the package index, MIT), its
``MultiRotor`` block (``roboticstoolbox/blocks/uav.py``: Pounds & Corke's X-4 Flyer model, a
bdsim continuous block) and its default vehicle (``roboticstoolbox/blocks/quad_model.py``).

What is the toolbox's own (used as it is, through ``MultiRotor.deriv`` called directly): the
12-state rigid body in NED (z down) with ZYX Euler angles (state: NED position, (yaw, pitch,
roll), NED velocity, FRD body rates), the rotor model of each rotor at its hub displacement
``D_i = (d cos(i pi/2), d sin(i pi/2), h)`` (FRD; rotor 1 on +x, plus layout, h = -7 mm: the
rotors above the CoM): thrust ``Ct rho A r^2 w^2`` tilted by the first-harmonic flapping
angles (longitudinal ``(8/3 theta0 + 2 theta1) mu - 2 lc mu`` over ``1 - mu^2/2``, turned by
the hub's sideslip, and ``-16 / (gamma |w|)`` times the body pitch and roll rate), the thrust's
moment ``D_i x T_i`` and the drag torque ``Cq rho A r^3 w |w|``; and the vehicle's values
(``quadrotor``: M 4 kg, J diag(0.082, 0.082, 0.149) kg m^2, d 0.315 m, h -0.007 m, r 0.165
m, Ct 0.0048, Cq = Ct sqrt(Ct / 2), rho 1.184 kg/m^3, theta0 14.6 deg, tip 6.8 deg, Lock
number gamma 2.68; b = Ct rho A r^2 = 1.3234e-5 N s^2/rad^2, k = Cq rho A r^3 = 1.0697e-7 N m
s^2/rad^2). The block has no frame drag in this version (its comments name one from the
MATLAB original; the code has none), no rotor gyroscopic torque and no motor: its input is
the rotor speeds, signed (``MultiRotorMixer``'s signs +1, -1, +1, -1: the odd rotors turn the
other way). Its hub air velocity is ``o x D_i + v`` with v the NED *world* velocity read as
if in body axes (the original's; at a yaw psi the flapping drag is turned by psi): kept as it
is, the source's own trait. Its ground check is off (``groundcheck=False``: it writes into the
state it is given; the flights stay 0.05 m above the ground or stop).

What is this project's: the integrator (classic RK4 at :data:`CONTROL_HZ`, 2 ms, on the
block's 12 states and the 4 motor speeds, the speed command held over the step), the motor
the block lacks (a first-order lag ``dOmega/dt = (Omega_cmd - Omega) / tau``, tau
:data:`MOTOR_TAU`, the command clipped to [:data:`MIN_SPEED`, :data:`MAX_SPEED`]), the
controller (:class:`benchmarks.geometric.Geometric` on the nominal vehicle, blind to every
case), the path (:func:`benchmarks.dsim_source.path`, the Drake source's loop), the case
handles the block has no parameter for (module ``EFFECTS`` below) and the frame conversion at
the boundary: world NED -> world z up and body FRD -> body FLU by a half turn about x
(:data:`FLIP`, its own inverse): positions, velocities, accelerations, rates, moments and
hub displacements ``FLIP v``, inertia ``FLIP J FLIP``; the NED (yaw, pitch, roll) are the
FLU ZYX angles (roll, -pitch, -yaw), so the FLU quaternion (w first) is
:func:`quadsim.core.frames.euler_to_quat` of those.

Case changes (:data:`EFFECTS`, SI), through the block's own parameters where it has them:
``mass``, ``payload`` (point mass: mass, CoM and the full inertia; the model's ``M``, ``J``),
``com`` (x, y m: the CoM off the rotors' centre, as the block's hub displacements ``D``
moved by -com), ``inertia`` (relative change of Ixx, Iyy, Izz; ``J``), ``thrust_scale``
(every rotor: the model's ``Ct`` and ``Cq`` x (1 + change): thrust and drag torque alike),
``weak_rotor`` (one rotor: the block has one ``Ct`` for all rotors, so that rotor's speed is
passed to it as ``sqrt(1 + change) Omega``: its thrust and drag torque x (1 + change), its
flapping read at that speed, its advance ratio 2.6-8.5 % larger), ``drag_scale`` (factor on
the flapping's blade angles ``theta0`` and ``theta1``: the block's only drag, the in-plane
flapping force, scales by it), ``wind`` (m/s world x, y: the block's state velocity passed as
the air velocity ``v - wind``, the position still moving at v), ``motor_slow`` (factor on the
motor's tau), ``rate_damping`` (-k w, body), ``torque`` at ``torque_hz`` (body), ``force``
at ``force_hz`` (body z), ``rotor_delay`` (the rotor-speed log only, s late); the last four
are this project's loads added to the block's derivative.

The log (:func:`to_flight_log`, :data:`LOG_HZ` = the control rate): per step k the state at
t_k, the motor speeds at t_k (rad/s, unsigned, the true speeds), the command acting from t_k
(speed command / :data:`MAX_SPEED`) and the block's own derivative there (acceleration and
angular acceleration), converted to quadsim's frames and moved to the body origin (the
nominal CoM, where the block's hub displacements are measured from) by
:func:`.simlog.body_origin_log` with the other sources' sensor noise.

Example::

    >>> log, truth = rtb_flights([FlightSpec(seed=1, effects={"mass": 0.4})])[0]
"""

from __future__ import annotations

import importlib.util

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.core.frames import euler_to_quat
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .dsim_source import FlightSpec, path
from .flightjobs import disturbances, fly_all, mass_properties, rotor_scales
from .geometric import Geometric
from .simlog import SimStates, body_origin_log

__all__ = ["CONTROL_HZ", "EFFECTS", "FLIP", "LEAD_IN", "LOG_HZ", "MAX_SPEED", "MIN_SPEED",
           "MOTOR_TAU", "SPINS", "Controller", "FlightSpec", "derivative", "flap_coefficient",
           "flu_state", "fly_one", "hover_speed", "make_plant", "path", "rtb_available",
           "rtb_flights", "rtb_model", "to_flight_log", "vehicle_params"]

#: the controller's rate = the RK4 step (Hz) = the log's rate
CONTROL_HZ = 500
LOG_HZ = 500
#: s flown before the log starts (the integrals settle)
LEAD_IN = 3.0
#: s: the motor's time constant (this project's: the block has no motor; ESC/motor time
#: constants are 20-150 ms; the slowest case, x 2.5, is 75 ms: at 100 ms the attitude loop
#: below is barely damped)
MOTOR_TAU = 0.03
#: rad/s: the top speed, a thrust-to-weight of 1.94 (this project's: the block has no motor;
#: MultiRotorMixer's default wmax 1000 rad/s is 1.35, which the path's heavy cases saturate;
#: 2 is the usual design margin) and MultiRotorMixer's default floor wmin 5 rad/s (the block
#: is not defined at zero speed)
MAX_SPEED = 1200.0
MIN_SPEED = 5.0
#: the sign of each rotor's speed as the block takes it (MultiRotorMixer's ``signs``); in
#: quadsim's terms the spin (+1 ccw about body z up): the block's yaw moment on rotor i is
#: -k w_i |w_i| about FLU z
SPINS = np.array([1.0, -1.0, 1.0, -1.0])
#: body FLU <-> FRD and world (x, y, z up) <-> NED: a half turn about x (its own inverse)
FLIP = np.diag([1.0, -1.0, -1.0])
#: case-side changes (module doc)
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "motor_slow",
           "drag_scale", "wind", "rate_damping", "torque", "torque_hz", "force", "force_hz",
           "rotor_delay")


def rtb_available() -> bool:
    """roboticstoolbox and bdsim (which its blocks import) importable (checked without
    importing them)."""
    return all(importlib.util.find_spec(m) is not None for m in ("roboticstoolbox", "bdsim"))


def rtb_model() -> dict:
    """A copy of the toolbox's default vehicle (``roboticstoolbox.blocks.quad_model.
    quadrotor``: SI; its ``J`` copied too)."""
    if not rtb_available():
        raise ModelError("roboticstoolbox is not installed (pip install -e '.[rtb]')")
    from roboticstoolbox.blocks.quad_model import quadrotor

    model = dict(quadrotor)
    model["J"] = np.array(quadrotor["J"], dtype=float)
    return model


def hover_speed(mass: float | None = None) -> float:
    """Rotor speed (rad/s) at which four nominal rotors carry ``mass`` (kg; default the
    vehicle's M): sqrt(M g / (4 b)), b = Ct rho A r^2 (the model's ``b``)."""
    q = rtb_model()
    m = q["M"] if mass is None else mass
    return float(np.sqrt(m * q["g"] / 4.0 / q["b"]))


def flap_coefficient(model: dict | None = None) -> float:
    """The block's in-plane flapping force per rotor speed per hub air speed (kg/rad), to
    first order in the advance ratio: the thrust b w^2 tilted by (8/3 theta0 + 2 theta1) mu,
    mu = |V| / (w r), is ``b (8/3 theta0 + 2 theta1) / r`` w |V|: quadsim's rotor-drag form
    (:mod:`quadsim.effects.rotor_drag`), 3.267e-5 kg/rad for the default vehicle."""
    q = rtb_model() if model is None else model
    return float(q["b"] * (8.0 / 3.0 * q["theta0"] + 2.0 * q["theta1"]) / q["r"])


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of the toolbox's default vehicle, not fitted: mass, inertia
    (FRD and FLU alike: diagonal), rotor i at ``FLIP D_i`` (the block's hub displacements:
    (+-d, 0) and (0, -+d), 7 mm above the body origin, the nominal CoM), spins :data:`SPINS`,
    b and k, the motor's range (module doc), the rotor radius and air density; the command
    map linear, speed command / :data:`MAX_SPEED`. No rotor dynamics and no drag (quadsim's
    nominal model has neither: the shared effects of :mod:`.rtb_cases` carry them); no rotor
    inertia (the block has no gyroscopic torque)."""
    from roboticstoolbox.blocks.uav import MultiRotor

    q = rtb_model()
    hubs = (FLIP @ MultiRotor(q, groundcheck=False).D).T
    src = "roboticstoolbox-python 1.5.0 blocks/quad_model.py quadrotor"
    rotors = tuple(Rotor(str(i + 1), hubs[i].copy(), np.array([0.0, 0.0, 1.0]),
                         float(SPINS[i])) for i in range(4))
    params = VehicleParams(
        name="rtb-x4-flyer", mass=float(q["M"]), com=np.zeros(3), inertia=q["J"].copy(),
        rotors=rotors, thrust_factor=float(q["b"]), drag_factor=float(q["k"]),
        max_speed=MAX_SPEED, min_speed=MIN_SPEED, gravity=float(q["g"]),
        rotor_radius=float(q["r"]), air_density=float(q["rho"]),
        motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array([[0.0, MAX_SPEED]] * 4),
                           "command = speed command / 1200 rad/s (this project's motor)"),
        description="the Robotics Toolbox's MultiRotor default vehicle (X-4 Flyer) as "
                    "quadsim sees it",
        sources={"mass": f"{src}['M']", "inertia": f"{src}['J']",
                 "rotors": "MultiRotor.D (d, h of quad_model) turned to FLU; spins from "
                           "MultiRotorMixer's signs and the block's drag torque",
                 "thrust_factor": f"{src}['b'] = Ct rho A r^2",
                 "drag_factor": f"{src}['k'] = Cq rho A r^3",
                 "max_speed": "this project's motor: thrust-to-weight 1.94",
                 "min_speed": "MultiRotorMixer default wmin",
                 "rotor_radius": f"{src}['r']", "air_density": f"{src}['rho']",
                 "gravity": f"{src}['g']"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the plant


def _job(spec: FlightSpec) -> dict:
    """The flight's changes in SI (module doc): mass, com (3,) FLU, J (3, 3) FLU, ct_scale
    (every rotor's Ct and Cq), rotor_scale (4,) (one rotor's, beyond ct_scale), motor_tau,
    flap (factor on the blade angles) and the added loads."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown roboticstoolbox effect(s) {sorted(unknown)}; valid: "
                         f"{EFFECTS}")
    q = rtb_model()
    mass, com, inertia = mass_properties(e, q["M"], np.diag(q["J"]))
    common = 1.0 + float(e.get("thrust_scale", 0.0))
    return {"mass": mass, "com": com, "J": inertia, "ct_scale": common,
            "rotor_scale": rotor_scales(e) / common,
            "motor_tau": MOTOR_TAU * float(e.get("motor_slow", 1.0)),
            "flap": float(e.get("drag_scale", 1.0)), **disturbances(e)}


def make_plant(job: dict):
    """The toolbox's ``MultiRotor`` block of one flight: its model dict with the job's M, J
    (FRD), Ct and Cq (x ct_scale) and blade angles (x flap), ground check off, its hub
    displacements moved by -com (FRD)."""
    from roboticstoolbox.blocks.uav import MultiRotor

    q = rtb_model()
    q.update(M=float(job["mass"]), J=FLIP @ np.asarray(job["J"], dtype=float) @ FLIP,
             Ct=q["Ct"] * float(job["ct_scale"]), Cq=q["Cq"] * float(job["ct_scale"]),
             theta0=q["theta0"] * float(job["flap"]), theta1=q["theta1"] * float(job["flap"]))
    plant = MultiRotor(q, groundcheck=False)
    plant.D = plant.D - (FLIP @ np.asarray(job["com"], dtype=float))[:, None]
    return plant


def _rot_ned(x: np.ndarray) -> np.ndarray:
    """Body FRD -> world NED of the block's state (its (yaw, pitch, roll) in x[3:6])."""
    from quadsim.core.frames import quat_to_rotmat

    return FLIP @ quat_to_rotmat(flu_state(x)[2]) @ FLIP


def derivative(plant, job: dict, t: float, y: np.ndarray, command: np.ndarray) -> np.ndarray:
    """d/dt of y (16,): the block's 12 states and the 4 motor speeds (rad/s) under the speed
    command (4,) (rad/s): ``plant.deriv`` at the rotor speeds SPINS sqrt(rotor_scale) Omega
    and the air velocity v - wind in the velocity slots (the position moving at v), plus
    this project's loads (-k w + the periodic torque, body; the periodic body-z force) and
    the motor lag."""
    x = y[:12].copy()
    x[6:9] -= FLIP @ np.asarray(job["wind"], dtype=float)
    speeds = y[12:16]
    d = np.empty(16)
    d[:12] = plant.deriv(t, [SPINS * np.sqrt(job["rotor_scale"]) * speeds], x)
    d[0:3] = y[6:9]
    torque = (-np.asarray(job["rate_damping"]) * (FLIP @ y[9:12])
              + np.asarray(job["torque"]) * np.sin(2 * np.pi * job["torque_hz"] * t))
    if np.any(torque != 0):
        d[9:12] += np.linalg.solve(plant.model["J"], FLIP @ torque)
    if job["force"] != 0:
        force = job["force"] * np.sin(2 * np.pi * job["force_hz"] * t)
        d[6:9] += _rot_ned(y) @ np.array([0.0, 0.0, -force]) / plant.model["M"]
    d[12:16] = (np.clip(command, MIN_SPEED, MAX_SPEED) - speeds) / job["motor_tau"]
    return d


def flu_state(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The block's state (12,) in quadsim's frames: position and velocity (world z up),
    quaternion (w first, body FLU -> world) and body rates (FLU)."""
    yaw, pitch, roll = x[3:6]
    return (FLIP @ x[0:3], FLIP @ x[6:9], euler_to_quat(np.array([roll, -pitch, -yaw])),
            FLIP @ x[9:12])


# ----------------------------------------------------------------------------- flying


class Controller(Geometric):
    """:class:`benchmarks.geometric.Geometric` with the yaw loop at 2 rad/s (roll and pitch
    at its 10 rad/s): the X-4's drag torque is 0.8 % of its thrust per metre (k / b = 8.1
    mm), so its yaw authority at hover is 4 k Omega_hover^2 = 0.32 N m, 2.1 rad/s^2 on Izz;
    at the shared 5 rad/s its yaw demands reach that bound and the clipped rotors take thrust
    and roll/pitch with them. (Roll and pitch slower than 10 rad/s diverge: the shared
    position loop and attitude integral are tuned for it.)"""

    W_ATT = np.array([10.0, 10.0, 2.0])



def fly_one(args: tuple) -> dict:
    """One flight ``(spec, job)`` (top level: run in worker processes): the lead-in plus the
    logged samples at :data:`CONTROL_HZ` (module doc); (T, ...) arrays pos, vel (world,
    CoM), quat (wxyz body -> world), ang_vel, ang_acc (body), acc (world), rotor (rad/s),
    cmd (0..1), in quadsim's frames. The geometric controller on the nominal vehicle reads
    the true state. A flight that leaves control (tilt past 60 deg, below 0.05 m,
    non-finite) raises ModelError."""
    spec, job = args
    plant = make_plant(job)
    dt = 1.0 / CONTROL_HZ
    ctrl = Controller(dt, vehicle_params(), lambda w: np.clip(w / MAX_SPEED, 0.0, 1.0))
    lead, n = round(LEAD_IN * CONTROL_HZ), round(spec.duration * CONTROL_HZ)
    sp = path(np.arange(lead + n + 1) * dt, spec.seed, spec.speed)
    y = np.zeros(16)
    y[0:3], y[6:9], y[3] = FLIP @ sp["pos"][0], FLIP @ sp["vel"][0], -sp["yaw"][0]
    y[11] = -sp["yaw_rate"][0]          # level: the body yaw rate is the path's (FRD z down)
    y[12:16] = hover_speed(job["mass"] / job["ct_scale"]
                           / float(np.mean(job["rotor_scale"])))
    out = {k: np.zeros((n, 4 if k in ("quat", "rotor", "cmd") else 3))
           for k in ("pos", "vel", "quat", "ang_vel", "ang_acc", "acc", "rotor", "cmd")}
    for k in range(lead + n):
        t = k * dt
        pos, vel, quat, rate = flu_state(y)
        cmd = ctrl.step(pos, vel, quat, rate, sp["pos"][k], sp["vel"][k], sp["acc"][k],
                        float(sp["yaw"][k]), float(sp["yaw_rate"][k]))
        target = cmd * MAX_SPEED
        k1 = derivative(plant, job, t, y, target)
        k2 = derivative(plant, job, t + dt / 2, y + dt / 2 * k1, target)
        k3 = derivative(plant, job, t + dt / 2, y + dt / 2 * k2, target)
        k4 = derivative(plant, job, t + dt, y + dt * k3, target)
        if k >= lead:
            i = k - lead
            out["pos"][i], out["vel"][i], out["quat"][i], out["ang_vel"][i] = pos, vel, quat, rate
            out["acc"][i], out["ang_acc"][i] = FLIP @ k1[6:9], FLIP @ k1[9:12]
            out["rotor"][i], out["cmd"][i] = y[12:16], cmd
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if (not np.all(np.isfinite(y)) or np.cos(y[4]) * np.cos(y[5]) < 0.5
                or -y[2] < 0.05):
            raise ModelError(f"roboticstoolbox flight (seed {spec.seed}) lost control at t = "
                             f"{(k + 1) * dt - LEAD_IN:.3f} s")
    return out


def rtb_flights(specs: list[FlightSpec], workers: int | None = None
                ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec (in ``workers`` processes, :func:`benchmarks.flightjobs.fly_all`) and
    return ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth
    sidecar (effects, the flight's changes in SI, seed, speed)."""
    if not rtb_available():
        raise ModelError("roboticstoolbox is not installed (pip install -e '.[rtb]')")
    jobs = [_job(s) for s in specs]
    return fly_all(fly_one, to_flight_log, specs, jobs, source="roboticstoolbox",
                   model="MultiRotor", rates=(CONTROL_HZ, LOG_HZ), workers=workers)


def to_flight_log(raw: dict, spec: FlightSpec, com=None) -> FlightLog:
    """:func:`fly_one`'s samples (of the CoM) -> a quadsim :class:`FlightLog` of the body
    origin (``com`` (3,) m body: the CoM relative to it) with the sensor model of
    ``spec.sensors`` (seeded by ``spec.seed``; the rotor log ``rotor_delay`` s late when the
    spec asks)."""
    states = SimStates(rate_hz=LOG_HZ, pos=raw["pos"], vel=raw["vel"], quat=raw["quat"],
                       ang_vel=raw["ang_vel"], ang_acc=raw["ang_acc"], acc=raw["acc"],
                       rotor_speed=raw["rotor"], command=raw["cmd"])
    return body_origin_log(states, np.zeros(3) if com is None else np.asarray(com, float),
                           spec.sensors, spec.seed, hover_speed=hover_speed(),
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)),
                           gravity=float(rtb_model()["g"]))
