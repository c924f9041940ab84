"""Flights of an independent simulator source the project had never used: pymulticopter
(``pymulticopter`` 0.0.1 on the package index, pure Python, by its author's ``pysimenv``
0.0.22 framework): its rigid body, its integrator, its quad-X effector and mixer, its
actuator-fault model and its quaternion position and attitude controllers.

What is pymulticopter's own: the plant (``base.MulticopterDyn``: NED position and velocity,
the rotation matrix body (FRD) -> world R and the body rates; v' = g e3 - f R e3 / m - D_v v
/ m, R' = R hat(w), J w' = -w x J w + tau - D_omega w, with g = pysimenv's 9.805 m/s^2),
pysimenv's integrator (``Simulator.step``: classic RK4 with the inputs held over the step,
R re-orthogonalised at every stage), the rotor map (``model.QuadXEffector``: rotor thrusts
f_i -> (f, tau) by its matrix B of arm spacings d_phi, d_theta and torque ratio c_tau_f;
``model.QuadXMixer``: B's inverse), the fault model (``model.ActuatorFault``: f_i* = alp_i
f_i + rho_i, per-motor gain and bias) and its controllers (``control.QuaternionPosControl``
(p_d, v_d) -> total force and attitude setpoint; ``control.QuaternionAttControl`` -> moments;
LQR gains from their own ``gain(Q, R)``; given the nominal m and J: they know only the
nominal values).

What is this project's: the vehicle's rotor side (:data:`D_ARM`, :data:`C_TAU_F` its
examples' values, ``test_oaf_control``: d_phi = d_theta = 0.15 m, c_tau_f = 0.0196 m; the
mass and inertia its ``model.main`` example's, 4.34 kg, diag(0.0820, 0.0845, 0.1377)
kg m^2), the rotor-speed scale (pymulticopter has no rotor speeds: :data:`THRUST_FACTOR` b
gives the speeds we log, sqrt(f_i / b), hover 2977 rad/s, and :data:`ROTOR_RADIUS`, a 5-inch
propeller, the largest the 0.15 m spacing holds), the thrust limits (each commanded rotor
thrust clipped to 0..b :data:`MAX_SPEED`^2 before the fault: pymulticopter clips none), the
position gains (its ``gain`` with Q = diag(10, 10, 10, 1, 1, 1)^2, R = I where its example
has diag(1, 1, 1, 0.1, 0.1, 0.1)^2: its gains leave a 1.6 m height error for a 20 % heavier
vehicle, which reaches the ground; the attitude gains are its example's), the path (the
Drake source's loop with its velocity as v_d, :func:`path`; its position controller takes
no yaw: the vehicle holds yaw 0), the frame conversion (NED/FRD -> world z up, body FLU: a
half turn about x), the control and log rate (500 Hz; its examples step at 100 Hz), and the
loads it has no handle for (:func:`wrench`: the CoM's moment of the total thrust, the
out-of-library periodic body torque).

Its code as it is, no change to its physics. Kept, found by the tests: its gravity is 9.805
times a float32 e3 (9.8050003 m/s^2); pysimenv's "RK4" steps its third stage by dt/2 where
RK4 steps dt (``StateVariable.rk4_update_3``): each step a position gains dt v + 5/12 a dt^2
(RK4: 1/2), the position lags the velocity by dt/12 (0.17 ms at 500 Hz); velocities and
rates are integrated exactly under held inputs.

Case changes (:data:`EFFECTS`, SI; the handle of pymulticopter each sets): ``mass`` (m),
``payload`` (m, J: its full matrix, and the CoM patch), ``com`` (x, y m: patch, -c x f R e3
as a moment), ``inertia`` (relative change of J's diagonal), ``weak_rotor`` and
``thrust_scale`` (ActuatorFault's gain alp, per motor), ``rate_damping`` (N m s/rad x, y, z:
its D_omega), ``bias`` (rotor 1..4, N: ActuatorFault's bias rho of that motor), ``torque``
at ``torque_hz`` (N m body: patch).

The log (:func:`to_flight_log`, :data:`LOG_HZ` = the control rate): per control step k the
plant after the step with the inputs of step k held: its state (CoM), the commanded rotor
speeds sqrt(f_i / b) (f_i: the mixer's thrusts after the limits, before the fault: a motor
reaches its commanded speed whatever its propeller), its own state derivative at that state
under the held inputs (``MulticopterDyn._deriv``: acceleration and angular acceleration),
the speeds / :data:`MAX_SPEED`; converted to our frames and moved to the rotors' centre
(:func:`.simlog.body_origin_log`) with the other sources' sensor noise.

Example::

    >>> log, truth = pm_flights([FlightSpec(seed=1, effects={"mass": 0.3})])[0]
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

__all__ = ["CONTROL_HZ", "C_TAU_F", "D_ARM", "EFFECTS", "GRAVITY", "INERTIA", "LEAD_IN",
           "LOG_HZ", "MASS", "MAX_SPEED", "ROTOR_RADIUS", "THRUST_FACTOR", "FlightSpec",
           "effector_matrix", "fly_one", "hover_speed", "make_job", "path", "pm_available",
           "pm_flights", "to_flight_log", "vehicle_params", "wrench"]

#: the controller's rate = the plant's step (Hz); the log's rate
CONTROL_HZ = 500
LOG_HZ = 500
#: s flown before the log starts (the path's blend from rest and the loops settle)
LEAD_IN = 3.0
#: s over which the path blends from its start point into the loop (quintic smoothstep)
RAMP = 2.0
#: kg, kg m^2: pymulticopter's model.main example vehicle
MASS = 4.34
INERTIA = np.diag([0.0820, 0.0845, 0.1377])
#: m: d_phi = d_theta (rotor spacing across x and y; arms d / 2), m: c_tau_f (yaw moment per
#: N of thrust): its test_oaf_control example's QuadXEffector
D_ARM = 0.15
C_TAU_F = 0.0196
#: m/s^2: pysimenv's FlatEarthEnv.grav_accel
GRAVITY = 9.805
#: N s^2/rad^2: thrust per speed^2 (this project's: hover at sqrt(m g / 4 b) = 2977 rad/s,
#: 28 400 rpm, a 5-inch propeller's range)
THRUST_FACTOR = 1.2e-6
#: rad/s: the top speed (this project's: 2.8 x the hover thrust per rotor)
MAX_SPEED = 5000.0
#: m: a 5-inch propeller, the largest the 0.15 m spacing holds (pymulticopter has none)
ROTOR_RADIUS = 0.0635
#: case-side changes (module doc)
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "rate_damping",
           "bias", "torque", "torque_hz")
#: body FLU <-> FRD and world (x, y, z up) <-> NED: a half turn about x (its own inverse)
FLIP = np.diag([1.0, -1.0, -1.0])
#: LQR weights of its gain(Q, R): position (ours, module doc), attitude (its example)
POS_Q, POS_R = np.diag([10.0, 10.0, 10.0, 1.0, 1.0, 1.0]) ** 2, np.identity(3)
ATT_Q, ATT_R = np.diag([1.0, 1.0, 1.0, 0.1, 0.1, 0.1]) ** 2, 1e-4 * np.identity(3)


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, sensor noise), speed factor of the path, duration (s,
    logged), case-side changes (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def pm_available() -> bool:
    """pymulticopter and pysimenv importable (checked without importing them)."""
    return all(importlib.util.find_spec(m) is not None for m in ("pymulticopter", "pysimenv"))


def _require() -> None:
    if not pm_available():
        raise ModelError("pymulticopter is not installed (pip install --no-deps "
                         "pymulticopter==0.0.1 pysimenv==0.0.22 h5py pytictoc pyquaternion)")


def hover_speed(mass: float = MASS) -> float:
    """Rotor speed (rad/s) at which four nominal rotors carry ``mass`` (kg): sqrt(m g / 4 b)."""
    return float(np.sqrt(mass * GRAVITY / 4.0 / THRUST_FACTOR))


def effector_matrix() -> np.ndarray:
    """(4, 4) its QuadXEffector's B of :data:`D_ARM`, :data:`C_TAU_F` (FRD): (f, tau) = B f_i."""
    d, c = D_ARM / 2.0, C_TAU_F
    return np.array([[1.0, 1.0, 1.0, 1.0], [-d, d, d, -d], [d, -d, d, -d], [c, c, -c, -c]])


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of the vehicle (module doc), not fitted. Rotors in its
    numbering, read off its B (FRD: roll row -y_i, pitch row x_i): 1 front right, 2 rear left,
    3 front left, 4 rear right, at (+-d/2, +-d/2) m; its yaw row (+c_tau_f f_i about FRD z,
    i.e. down, for rotors 1, 2) makes rotors 1, 2 counter-clockwise (quadsim spin +1: reaction
    -d Omega^2 about up) and 3, 4 clockwise (-1); b = :data:`THRUST_FACTOR`, the yaw drag
    factor c_tau_f b; the command map linear, speed / :data:`MAX_SPEED`; no drag, no rotor
    dynamics (pymulticopter has neither)."""
    h = D_ARM / 2.0
    places = ((h, -h), (-h, h), (h, h), (-h, -h))
    rotors = tuple(Rotor(str(k + 1), np.array([x, y, 0.0]), np.array([0.0, 0.0, 1.0]), s)
                   for k, ((x, y), s) in enumerate(zip(places, (1.0, 1.0, -1.0, -1.0))))
    src = "pymulticopter 0.0.1"
    params = VehicleParams(
        name="pymulticopter-quadx", mass=MASS, com=np.zeros(3), inertia=INERTIA.copy(),
        rotors=rotors, thrust_factor=THRUST_FACTOR, drag_factor=C_TAU_F * THRUST_FACTOR,
        max_speed=MAX_SPEED, min_speed=0.0, gravity=GRAVITY, rotor_radius=ROTOR_RADIUS,
        motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array([[0.0, MAX_SPEED]] * 4),
                           "command = speed / MAX_SPEED"),
        description="pymulticopter's example vehicle (model.main, test_oaf_control) as "
                    "quadsim sees it",
        sources={"mass": f"{src} model.main m", "inertia": f"{src} model.main J",
                 "rotors": f"{src} QuadXEffector B (test_oaf_control d_phi, d_theta)",
                 "thrust_factor": "this project's (no rotor speeds in the source)",
                 "drag_factor": f"{src} test_oaf_control c_tau_f x thrust_factor",
                 "max_speed": "this project's", "rotor_radius": "this project's: 5-inch",
                 "gravity": "pysimenv FlatEarthEnv.grav_accel"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path(t: np.ndarray, seed: int, speed: float) -> dict:
    """The Drake source's wandering loop (:func:`benchmarks.drake_source.path`, copied so that
    this source's code hash covers it; world x, y, z up): ``pos`` (T, 3) m and its exact time
    derivative ``vel`` (T, 3) m/s: x = 0.7 cos(w t + phi) + 0.15 sin(2.7 w t) + a sin(6.1 w
    t), y = 0.5 sin(w t + phi) + 0.2 sin(1.9 w t + phi) + a sin(7.3 w t + phi), z = 1.5 + 0.2
    sin(1.3 w t) + 0.05 sin(3.7 w t), a = 0.03 m / max(speed, 0.5)^2, w = 0.9 speed rad/s,
    phase phi from the seed."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.9 * speed
    weave = 0.03 / max(speed, 0.5) ** 2
    terms = ((0, 0.7, w, phi + np.pi / 2), (0, 0.15, 2.7 * w, 0.0), (0, weave, 6.1 * w, 0.0),
             (1, 0.5, w, phi), (1, 0.2, 1.9 * w, phi), (1, weave, 7.3 * w, phi),
             (2, 0.2, 1.3 * w, 0.0), (2, 0.05, 3.7 * w, 0.0))
    t = np.asarray(t, dtype=float)
    pos, vel = np.zeros((len(t), 3)), np.zeros((len(t), 3))
    pos[:, 2] = 1.5
    for column, amp, freq, phase in terms:
        pos[:, column] += amp * np.sin(freq * t + phase)
        vel[:, column] += amp * freq * np.cos(freq * t + phase)
    return {"pos": pos, "vel": vel}


def _setpoint(t: float, seed: int, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """(p_d, v_d) NED at ``t`` s: the loop blended in from its start point over
    :data:`RAMP` s (quintic smoothstep s(t): p = p0 + s (loop - p0), v = s' (loop - p0) + s
    loop')."""
    now, start = path(np.array([t]), seed, speed), path(np.zeros(1), seed, speed)
    x = min(max(t / RAMP, 0.0), 1.0)
    s = x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)
    ds = 30.0 * x * x * (1.0 - x) ** 2 / RAMP
    delta = now["pos"][0] - start["pos"][0]
    return (FLIP @ (start["pos"][0] + s * delta),
            FLIP @ (ds * delta + s * now["vel"][0]))


# ----------------------------------------------------------------------------- the plant


def make_job(spec: FlightSpec) -> dict:
    """The flight's changes in SI (module doc): mass, com (3,) body FLU, J (3, 3) FLU, alp
    (4,) and rho (4,) N (its fault's gain and bias), rate_damping (3,), and
    :func:`benchmarks.flightjobs.disturbances`' loads."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown pymulticopter effect(s) {sorted(unknown)}; "
                         f"valid: {EFFECTS}")
    mass, com, inertia = mass_properties(e, MASS, np.diag(INERTIA))
    rho = np.zeros(4)
    if "bias" in e:
        rho[int(e["bias"][0]) - 1] = float(e["bias"][1])
    return {"mass": mass, "com": com, "J": inertia, "alp": rotor_scales(e), "rho": rho,
            **disturbances(e)}


def wrench(job: dict, thrusts: np.ndarray, t: float) -> tuple[float, np.ndarray]:
    """(f N, tau (3,) N m FRD) the plant gets: its QuadXEffector of the ``thrusts`` (N, after
    its fault) plus this project's loads: the CoM's moment (FRD (-cy f, -cx f, 0) for our
    (cx, cy): the total thrust at the rotors' centre, -c from the CoM) and the job's body
    torque sin(2 pi torque_hz t) (FLU -> FRD)."""
    u = effector_matrix() @ np.asarray(thrusts, dtype=float)
    c = job["com"]
    tau = u[1:4] + np.array([-c[1] * u[0], -c[0] * u[0], 0.0])
    tau = tau + FLIP @ (np.asarray(job["torque"], dtype=float)
                        * np.sin(2 * np.pi * job["torque_hz"] * t))
    return float(u[0]), tau


def _vehicle_class():
    """:class:`_Vehicle` (built on first use: pysimenv imported lazily)."""
    from pysimenv.core.base import SimObject

    class _Vehicle(SimObject):
        """Its MulticopterDyn driven by held rotor thrusts (after the fault) through
        :func:`wrench` at every RK4 stage's time."""

        def __init__(self, dyn, job: dict):
            super().__init__(name="pm-vehicle")
            self.dyn, self.job = dyn, job
            self._add_sim_objs([dyn])

        def _forward(self, thrusts: np.ndarray):
            f, tau = wrench(self.job, thrusts, self.time)
            self.dyn.forward(f=f, tau=tau)

    return _Vehicle


def make_plant(job: dict, position=(0.0, 0.0, 0.0)):
    """(simulator, vehicle, dyn): pysimenv's Simulator of its MulticopterDyn with the job's
    m, J (FRD: F J F), D_omega = diag(rate_damping), D_v = 0, level and at rest at
    ``position`` (NED m)."""
    from pymulticopter.base import MulticopterDyn
    from pysimenv.core.simulator import Simulator

    dyn = MulticopterDyn(p_0=np.asarray(position, dtype=float), v_0=np.zeros(3),
                         R_0=np.identity(3), omega_0=np.zeros(3), m=float(job["mass"]),
                         J=FLIP @ np.asarray(job["J"], dtype=float) @ FLIP,
                         D_omega=np.diag(np.asarray(job["rate_damping"], dtype=float)),
                         name="pm-dyn")
    vehicle = _vehicle_class()(dyn, job)
    sim = Simulator(vehicle, verbose=False)
    sim.sim_clock.set_time_interval(1.0 / CONTROL_HZ)
    return sim, vehicle, dyn


def controllers():
    """(position, attitude, mixer): its QuaternionPosControl and QuaternionAttControl with
    the nominal m, J and the gains of :data:`POS_Q`/:data:`ATT_Q` by their own ``gain``; its
    QuadXMixer of the nominal effector."""
    from pymulticopter.control import QuaternionAttControl, QuaternionPosControl
    from pymulticopter.model import QuadXMixer

    pos = QuaternionPosControl(MASS, QuaternionPosControl.gain(POS_Q, POS_R))
    att = QuaternionAttControl(FLIP @ INERTIA @ FLIP, QuaternionAttControl.gain(ATT_Q, ATT_R))
    return pos, att, QuadXMixer(D_ARM, D_ARM, C_TAU_F)


def fly_one(args: tuple) -> dict:
    """One flight ``(spec, job)`` (top level: run in worker processes): the lead-in plus the
    logged samples at :data:`CONTROL_HZ` (module doc); (T, ...) arrays in our frames pos,
    vel (world, CoM), rot (body -> world), ang_vel, ang_acc (body), acc (world, with
    gravity), rotor (rad/s). Its controllers (their ``_forward``: pure functions of the
    state) read the true state once per step; the thrusts are clipped to 0..b MAX_SPEED^2,
    pass its ActuatorFault and are held over the RK4 step. A flight that leaves control
    (tilt past 60 deg, below 0.05 m, non-finite) raises ModelError."""
    from pymulticopter.model import ActuatorFault

    spec, job = args
    dt = 1.0 / CONTROL_HZ
    lead = round(LEAD_IN * CONTROL_HZ)
    n = round(spec.duration * CONTROL_HZ)
    p0, _ = _setpoint(0.0, spec.seed, spec.speed)
    sim, vehicle, dyn = make_plant(job, p0)
    pos_ctrl, att_ctrl, mixer = controllers()
    fault = ActuatorFault([0.0], [np.asarray(job["alp"], float)],
                          [np.asarray(job["rho"], float)])
    top = THRUST_FACTOR * MAX_SPEED ** 2
    out = {k: np.zeros((n, 3)) for k in ("pos", "vel", "ang_vel", "ang_acc", "acc")}
    out["rot"], out["rotor"] = np.zeros((n, 3, 3)), np.zeros((n, 4))
    for k in range(lead + n):
        t = k * dt
        p_d, v_d = _setpoint(t, spec.seed, spec.speed)
        f, q_d, omega_d = pos_ctrl._forward(dyn, p_d, v_d)
        tau = att_ctrl._forward(dyn, q_d, omega_d)
        command = np.clip(mixer.convert(f, tau), 0.0, top)
        thrusts = fault._forward(command)
        sim.step(dt, thrusts=thrusts)
        s = dyn.state()
        if (not all(np.all(np.isfinite(v)) for v in s.values()) or s["R"][2, 2] < 0.5
                or -s["p"][2] < 0.05):
            raise ModelError(f"pymulticopter flight (seed {spec.seed}) lost control at "
                             f"t = {(k + 1) * dt - LEAD_IN:.3f} s")
        if k >= lead:
            i = k - lead
            f_u, tau_u = wrench(job, thrusts, t + dt)
            d = dyn._deriv(s["p"], s["v"], s["R"], s["omega"], f_u, tau_u)
            out["pos"][i], out["vel"][i], out["rot"][i] = s["p"], s["v"], s["R"]
            out["ang_vel"][i], out["ang_acc"][i], out["acc"][i] = s["omega"], d["omega"], d["v"]
            out["rotor"][i] = np.sqrt(command / THRUST_FACTOR)
    for key in ("pos", "vel", "ang_vel", "ang_acc", "acc"):
        out[key] = out[key] @ FLIP
    out["rot"] = FLIP @ out["rot"] @ FLIP
    return out


def pm_flights(specs: list[FlightSpec], workers: int | None = None
               ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec (in ``workers`` processes, :func:`benchmarks.flightjobs.fly_all`) and
    return ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth
    sidecar (effects, the flight's changes in SI, seed, speed)."""
    _require()
    jobs = [make_job(s) for s in specs]
    return fly_all(fly_one, to_flight_log, specs, jobs, source="pymulticopter",
                   model="MulticopterDyn", rates=(CONTROL_HZ, LOG_HZ), workers=workers)


def _rot_to_quat(rot: np.ndarray) -> np.ndarray:
    """(N, 4) scalar-first unit quaternions (w >= 0) of (N, 3, 3) rotation matrices."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(rot).as_quat()[:, [3, 0, 1, 2]]
    return np.where(q[:, :1] < 0, -q, q)


def to_flight_log(raw: dict, spec: FlightSpec, com=None) -> FlightLog:
    """:func:`fly_one`'s samples (of the CoM, our frames) -> a quadsim :class:`FlightLog` of
    the rotors' centre (``com`` (3,) m body: the CoM relative to it) with the sensor model of
    ``spec.sensors`` (seeded by ``spec.seed``)."""
    states = SimStates(rate_hz=LOG_HZ, pos=raw["pos"], vel=raw["vel"],
                       quat=_rot_to_quat(raw["rot"]), ang_vel=raw["ang_vel"],
                       ang_acc=raw["ang_acc"], acc=raw["acc"], rotor_speed=raw["rotor"],
                       command=raw["rotor"] / MAX_SPEED)
    return body_origin_log(states, np.zeros(3) if com is None else np.asarray(com, float),
                           spec.sensors, spec.seed, hover_speed=hover_speed(),
                           gravity=GRAVITY)
