"""Flights of an independent simulator source the project had never used: drone-models
(utiasDSL, ``drone_models`` 0.1.0 on the package index, MIT), its first-principles model of
the Crazyflie 2.1 Brushless (``cf21B_500``).

drone-models is pure dynamics: a function of the state and the four RPM commands that
returns the state's derivative (``drone_models.first_principles.dynamics``: quaternion rigid
body, thrust and torque curves quadratic in RPM with a linear term, rotor dynamics with
different spin-up and spin-down rates, a linear body-frame drag matrix, propeller gyroscopic
and reaction torques, world-frame disturbance force and torque inputs) and its parameter file
``data/params.toml``. The integrator (fixed-step RK4 at :data:`PHYSICS_HZ`) and the
closed-loop controller (a PID cascade in the shape of the Crazyflie firmware's) are this
project's, in :mod:`.dm_worker`, which runs in a child process: ``import drone_models``
needs SciPy's array-API mode set before SciPy loads, which quadsim's process must not use.

Case changes (:data:`EFFECTS`, SI), each through drone-models' own parameters or its
disturbance inputs (:mod:`.dm_worker`'s module doc): ``mass``, ``payload`` (point mass:
mass, CoM and the full inertia change together), ``com`` (the CoM off the rotors' centre:
the thrust's moment through ``dist_t``), ``inertia`` (relative change of Jxx, Jyy, Jzz),
``weak_rotor`` and ``thrust_scale`` (factors on ``rpm2thrust`` and ``rpm2torque``),
``motor_slow`` (``rotor_dyn_coef`` divided: time constants x factor), ``drag_scale`` (factor
on ``drag_matrix``), ``wind`` (the drag matrix's force at the air speed, ``dist_f``),
``rate_damping`` (-k w, ``dist_t``), ``torque`` at ``torque_hz`` (periodic body torque,
``dist_t``), ``force`` at ``force_hz`` (periodic body-z force, ``dist_f``), ``rotor_delay``
(the rotor-speed log only, s late).

The log (:func:`to_flight_log`, :data:`LOG_HZ` = the physics rate; :mod:`.simlog`): the CoM
moved to the body origin (the rotors' centre), its attitude, world velocity, body rates, the
specific force and angular acceleration from drone-models' state derivative at each sample,
the rotor-speed state (RPM -> rad/s) and the command (commanded RPM / the RPM at
``thrust_max``), with the other sources' sensor noise.

Units and frames: drone-models' are quadsim's (world z up, body x forward, y left) but its
quaternions are xyzw (reordered w-first) and its rotor speeds RPM (x 2 pi / 60).

Example::

    >>> log, truth = dm_flights([FlightSpec(seed=1, effects={"mass": 0.003})])[0]
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, mass_properties, rotor_scales
from .simlog import Sensors, SimStates, body_origin_log, jsonable

__all__ = ["ATTITUDE_HZ", "DRONE", "EFFECTS", "LEAD_IN", "LOG_HZ", "PHYSICS_HZ", "POSITION_HZ",
           "RPM", "FlightSpec", "dm_available", "dm_flights", "dm_params", "hover_rpm",
           "max_rpm", "path", "probe", "to_flight_log", "vehicle_params"]

DRONE = "cf21B_500"
#: the RK4 step and the rate loop (Hz)
PHYSICS_HZ = 500
#: the position/velocity loop and the attitude loop (Hz), as the Crazyflie firmware's
POSITION_HZ = 100
ATTITUDE_HZ = 250
LOG_HZ = 500
#: s flown before the log starts (the controller's integrals settle)
LEAD_IN = 3.0
#: rad/s per RPM
RPM = 2.0 * np.pi / 60.0
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


def dm_available() -> bool:
    """drone-models and what its dynamics import (casadi, array-api-compat) importable
    (checked without importing them)."""
    return all(importlib.util.find_spec(m) is not None
               for m in ("drone_models", "casadi", "array_api_compat"))


def dm_params(drone: str = DRONE) -> dict:
    """drone-models' physical parameters of ``drone`` (``data/params.toml``, read without
    importing drone-models; its units: kg, m, kg m^2, N and N m per RPM powers, 1/s)."""
    spec = importlib.util.find_spec("drone_models")
    if spec is None or not spec.submodule_search_locations:
        raise ModelError("drone-models is not installed (pip install -e '.[dm]')")
    root = Path(next(iter(spec.submodule_search_locations)))
    with open(root / "data" / "params.toml", "rb") as handle:
        return {k: np.asarray(v, dtype=float) for k, v in tomllib.load(handle)[drone].items()}


def _rpm_for_thrust(curve: np.ndarray, thrust) -> np.ndarray:
    """RPM where the curve a + b rpm + c rpm^2 (``curve`` = (a, b, c)) gives ``thrust`` N."""
    a, b, c = np.ravel(curve)
    return (-b + np.sqrt(b * b - 4 * c * (a - np.asarray(thrust, dtype=float)))) / (2 * c)


def hover_rpm(mass: float | None = None, drone: str = DRONE) -> float:
    """RPM at which four rotors on the nominal curve carry ``mass`` (kg; default the
    vehicle's) against drone-models' gravity."""
    p = dm_params(drone)
    m = float(p["mass"]) if mass is None else mass
    return float(_rpm_for_thrust(p["rpm2thrust"], -m * float(p["gravity_vec"][2]) / 4.0))


def max_rpm(drone: str = DRONE) -> float:
    """RPM at ``thrust_max`` per rotor on the nominal curve (the command's full scale)."""
    p = dm_params(drone)
    return float(_rpm_for_thrust(p["rpm2thrust"], float(p["thrust_max"])))


def vehicle_params(drone: str = DRONE) -> VehicleParams:
    """quadsim's parameter set of drone-models' ``drone``: its params.toml values converted to
    SI, not fitted. Rotor i at (-M[1, i] L, M[0, i] L) with spin -M[2, i] (its mixing matrix
    M: roll L M[0] f, pitch L M[1] f, yaw M[2] tau); b and d the curves' quadratic
    coefficients (N/RPM^2 / RPM^2 -> N s^2/rad^2); their linear terms (thrust -3.13e-7 N/RPM,
    -4.7 % of the hover thrust; torque +1.66e-9 N m/RPM, +4.2 % of the hover torque) have no
    place in quadsim's set: part of the source the diagnosis has to live with."""
    p = dm_params(drone)
    src = f"drone-models 0.1.0 data/params.toml [{drone}]"
    mix, arm = p["mixing_matrix"], float(p["L"])
    rotors = tuple(Rotor(str(i + 1), np.array([-mix[1, i] * arm, mix[0, i] * arm, 0.0]),
                         np.array([0.0, 0.0, 1.0]), float(-mix[2, i])) for i in range(4))
    top = max_rpm(drone) * RPM
    low = float(_rpm_for_thrust(p["rpm2thrust"], float(p["thrust_min"]))) * RPM
    params = VehicleParams(
        name=f"dm-{drone}", mass=float(p["mass"]), com=np.zeros(3),
        inertia=np.asarray(p["J"], dtype=float), rotors=rotors,
        thrust_factor=float(p["rpm2thrust"][2]) / RPM ** 2,
        drag_factor=float(p["rpm2torque"][2]) / RPM ** 2, max_speed=top, min_speed=low,
        rotor_radius=float(p["prop_radius"]), rotor_inertia=float(p["prop_inertia"]),
        gravity=-float(p["gravity_vec"][2]),
        motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array([[0.0, top]] * 4),
                           "command = commanded RPM / the RPM at thrust_max"),
        description=f"drone-models {drone} (Crazyflie 2.1 Brushless) as quadsim sees it",
        sources={"mass": f"{src}: mass (kg)", "inertia": f"{src}: J (kg m^2)",
                 "rotors": f"{src}: L (m, the rotor's x and y offset) and mixing_matrix",
                 "thrust_factor": f"{src}: rpm2thrust[2] 4.407e-10 N/RPM^2 (N s^2/rad^2)",
                 "drag_factor": f"{src}: rpm2torque[2] 2.469e-12 N m/RPM^2 (N m s^2/rad^2)",
                 "max_speed": f"{src}: thrust_max per rotor through rpm2thrust (rad/s)",
                 "min_speed": f"{src}: thrust_min per rotor through rpm2thrust (rad/s)",
                 "rotor_radius": f"{src}: prop_radius (m)",
                 "rotor_inertia": f"{src}: prop_inertia (kg m^2)",
                 "gravity": f"{src}: gravity_vec (m/s^2)"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path(t: np.ndarray, seed: int, speed: float) -> dict:
    """Setpoints of a wandering loop sized for a Crazyflie: ``pos``, ``vel``, ``acc`` (T, 3)
    (m, m/s, m/s^2), ``yaw``, ``yaw_rate`` (T,) (rad, rad/s). x = 0.7 cos(w t + phi) + 0.15
    sin(2.7 w t) + a sin(6.1 w t), y = 0.5 sin(w t + phi) + 0.2 sin(1.9 w t + phi) + a sin(7.3
    w t + phi), z = 1.0 + 0.2 sin(1.3 w t) + 0.05 sin(3.7 w t), yaw = 0.5 sin(0.8 w t), a =
    0.02 m / max(speed, 0.5)^2 (a weave of about 0.6 m/s^2 at every speed: roll and pitch
    excitation), w = 0.9 speed rad/s, phase phi from the seed."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.9 * speed
    weave = 0.02 / max(speed, 0.5) ** 2
    terms = ((0, 0.7, w, phi + np.pi / 2), (0, 0.15, 2.7 * w, 0.0), (0, weave, 6.1 * w, 0.0),
             (1, 0.5, w, phi), (1, 0.2, 1.9 * w, phi), (1, weave, 7.3 * w, phi),
             (2, 0.2, 1.3 * w, 0.0), (2, 0.05, 3.7 * w, 0.0))
    pos, vel, acc = np.zeros((len(t), 3)), np.zeros((len(t), 3)), np.zeros((len(t), 3))
    pos[:, 2] = 1.0
    for column, amp, freq, phase in terms:
        arg = freq * t + phase
        pos[:, column] += amp * np.sin(arg)
        vel[:, column] += amp * freq * np.cos(arg)
        acc[:, column] -= amp * freq ** 2 * np.sin(arg)
    return {"pos": pos, "vel": vel, "acc": acc, "yaw": 0.5 * np.sin(0.8 * w * t),
            "yaw_rate": 0.5 * 0.8 * w * np.cos(0.8 * w * t)}


# ----------------------------------------------------------------------------- the job


def _flight_job(spec: FlightSpec, p: dict) -> dict:
    """The flight's changes in the worker's terms (SI; :mod:`.dm_worker`)."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown drone-models effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    mass, com, inertia = mass_properties(e, float(p["mass"]), np.diag(p["J"]))
    return {"mass": mass, "com": com, "J": inertia, "rotor_scale": rotor_scales(e),
            "motor_slow": float(e.get("motor_slow", 1.0)),
            "drag_scale": float(e.get("drag_scale", 1.0)), **disturbances(e)}


def dm_flights(specs: list[FlightSpec], drone: str = DRONE) -> list[tuple[FlightLog, dict]]:
    """Fly every spec (one child process for all of them, integrated side by side) and
    return ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth
    sidecar (effects, the flight's parameters in the worker's terms, seed, speed)."""
    if not dm_available():
        raise ModelError("drone-models is not installed (pip install -e '.[dm]')")
    p = dm_params(drone)
    n = round(specs[0].duration * PHYSICS_HZ) if specs else 0
    if any(round(s.duration * PHYSICS_HZ) != n for s in specs):
        raise ValueError("dm_flights: every spec of one batch has the same duration")
    lead = round(LEAD_IN * PHYSICS_HZ)
    t = np.arange(lead + n + 1) / PHYSICS_HZ
    jobs = [_flight_job(s, p) for s in specs]
    paths = [path(t, s.seed, s.speed) for s in specs]
    job = {k: np.stack([np.asarray(j[k], dtype=float) for j in jobs]) for k in jobs[0]}
    job.update({f"{k}_sp": np.stack([q[k] for q in paths]) for k in paths[0]})
    job["start"] = job["pos_sp"][:, 0]
    job["start_vel"] = job["vel_sp"][:, 0]
    job["start_yaw"] = job["yaw_sp"][:, 0]
    job["rotor0"] = np.array([hover_rpm(j["mass"] / float(np.mean(j["rotor_scale"])), drone)
                              for j in jobs])
    job.update(physics_hz=np.asarray(PHYSICS_HZ), position_hz=np.asarray(POSITION_HZ),
               attitude_hz=np.asarray(ATTITUDE_HZ), drone=np.asarray(drone))
    raw = _run_worker(job)
    out = []
    for k, spec in enumerate(specs):
        sample = {name: value[k, lead:lead + n] for name, value in raw.items()}
        log = to_flight_log(sample, spec, jobs[k]["com"], drone)
        truth = {"source": "drone-models", "model": drone, "seed": spec.seed,
                 "speed": spec.speed, "duration_s": spec.duration, "physics_hz": PHYSICS_HZ,
                 "log_hz": LOG_HZ, "effects": jsonable(spec.effects),
                 "drone-models_params": jsonable(jobs[k])}
        out.append((log, truth))
    return out


def _run_worker(job: dict) -> dict:
    """Run :mod:`.dm_worker` on ``job`` in a temporary folder, its output captured (a
    failure is one line of its stderr)."""
    env = {**os.environ, "SCIPY_ARRAY_API": "1"}
    with tempfile.TemporaryDirectory(prefix="quadsim-dm-") as tmp:
        job_path, out_path = os.path.join(tmp, "job.npz"), os.path.join(tmp, "out.npz")
        np.savez(job_path, **job)
        worker = str(Path(__file__).resolve().with_name("dm_worker.py"))
        done = subprocess.run([sys.executable, worker, job_path, out_path], env=env,
                              capture_output=True, text=True, cwd=tmp, check=False)
        if done.returncode != 0:
            tail = done.stderr.strip().splitlines()[-1:] or ["no output"]
            raise ModelError(f"drone-models worker failed ({done.returncode}): {tail[0]}")
        with np.load(out_path) as data:
            return {k: np.array(data[k]) for k in data.files}


def probe(state: np.ndarray, cmd: np.ndarray, drone: str = DRONE) -> np.ndarray:
    """drone-models' own state derivative (N, 17) at ``state`` (N, 17: position, xyzw
    quaternion, velocity, body rate, rotor RPM) and RPM commands ``cmd`` (N, 4), nominal
    parameters, no disturbance: evaluated in the worker's interpreter (for tests)."""
    code = ("import sys, numpy as np; from drone_models.core import parametrize; "
            "from drone_models.first_principles import dynamics; "
            "d = np.load(sys.argv[1]); x = d['x']; "
            "f = parametrize(dynamics, sys.argv[3]); "
            "r = f(x[:, 0:3], x[:, 3:7], x[:, 7:10], x[:, 10:13], d['cmd'], x[:, 13:17]); "
            "np.save(sys.argv[2], np.concatenate(r, axis=1))")
    env = {**os.environ, "SCIPY_ARRAY_API": "1"}
    with tempfile.TemporaryDirectory(prefix="quadsim-dm-") as tmp:
        job, out = os.path.join(tmp, "x.npz"), os.path.join(tmp, "out.npy")
        np.savez(job, x=np.atleast_2d(state), cmd=np.atleast_2d(cmd))
        done = subprocess.run([sys.executable, "-c", code, job, out, drone], env=env,
                              capture_output=True, text=True, cwd=tmp, check=False)
        if done.returncode != 0:
            raise ModelError(f"drone-models probe failed: {done.stderr.strip()[-200:]}")
        return np.load(out)


def to_flight_log(raw: dict, spec: FlightSpec, com: np.ndarray, drone: str = DRONE
                  ) -> FlightLog:
    """The worker's states (CoM, xyzw, body rates, rotor RPM, derivatives) at
    :data:`PHYSICS_HZ` -> a quadsim :class:`FlightLog` of the body origin with the sensor
    model of ``spec.sensors`` (seeded by ``spec.seed``; the rotor log ``rotor_delay`` s late
    when the spec asks)."""
    p = dm_params(drone)
    states = SimStates(rate_hz=LOG_HZ, pos=raw["pos"], vel=raw["vel"],
                       quat=raw["quat"][:, [3, 0, 1, 2]], ang_vel=raw["ang_vel"],
                       ang_acc=raw["ang_acc"], acc=raw["acc"], rotor_speed=raw["rotor"] * RPM,
                       command=raw["cmd"] / max_rpm(drone))
    return body_origin_log(states, com, spec.sensors, spec.seed,
                           hover_speed=hover_rpm(drone=drone) * RPM,
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)),
                           gravity=-float(p["gravity_vec"][2]))
