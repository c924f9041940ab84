"""Independent flights from PyFlyt (pybullet physics; its own QuadX, motors, drag and PID cascade).

PyFlyt (``pip install pybullet pettingzoo`` then ``pip install --no-deps PyFlyt==0.29.0``:
PyFlyt pins numpy<2 in its metadata but runs on numpy 2; Tai, Wong et al., "PyFlyt -- UAV
Simulation Environments for Reinforcement Learning Research", arXiv:2304.01305;
https://github.com/jjshoots/PyFlyt) flies its QuadX with the ``cf2x`` model (a 27 g
Crazyflie 2.x: ``cf2x.urdf`` mass and inertia, ``cf2x.yaml`` motor, drag and controller
constants) in pybullet's rigid-body step. Its physics that quadsim's nominal model lacks:
first-order motors (throttle ``y += dt/tau (pwm - y)``, tau 10 ms) with multiplicative
motor noise, quadratic body drag ``-0.5 rho C_d A v_i |v_i|`` per body axis
(``drag_coef_xyz`` 3.0 x ``drag_area_xyz`` 4e-4 m^2) and a quadratic angular-rate damping
``-drag_coef_pqr w_i |w_i|`` (1e-4 N m s^2/rad^2). Its PID cascade in mode 7 (x, y, yaw, z
setpoints) flies the path. No quadsim hook, engine or controller is used: an effect is a
change of PyFlyt's vehicle files or parameters, a PyFlyt wind field, or a force/torque
through pybullet (:mod:`.pyflyt_worker`, which runs in a child process so that pybullet's
C-level prints never reach the user).

PyFlyt's motor noise as 0.29.0 ships it: ``throttle += np_random.normal(*shape) * throttle
* noise_ratio`` draws ``normal(4)``, i.e. ONE sample of N(mean 4, sd 1) per physics step,
common to the four motors. So per step ``y' = (1 - a + r n) y + a u`` (a = dt/tau, r =
noise_ratio = 0.02, n ~ N(4, 1)): a steady gain ``a / (a - 4 r)`` and an effective time
constant ``-dt / ln(1 - a + 4 r)`` (:func:`motor_response`), both depending on the physics
rate, with a common 2 %-per-step throttle noise. At 500 Hz the gain is 1.67 and a motor
with tau doubled (20 ms) has gain 5 and 100 ms; at 2.5 x tau it is unstable. So the flights
run at PyFlyt's recommended 240 Hz (physics) and its default 120 Hz control, where tau =
10 ms gives gain 1.24 and 10 ms, and 2.5 x tau gives 1.92 and 46 ms. The log carries
PyFlyt's own motor state, so the diagnosis sees the rotor speeds that made the thrust.

Units and frames at the boundary: PyFlyt's world is z up (gravity -9.81 on z), its body x
forward, y left, z up (as quadsim: no sign change); pybullet quaternions are xyzw (reordered
to wxyz), body -> world; its base position and velocity are those of the centre of mass
(the URDF's inertial origin), its angular velocity is in the world frame (rotated to the
body). PyFlyt's motor "rpm" ``throttle x max_rpm`` with thrust ``thrust_coef rpm^2``
(N/RPM^2): rad/s = RPM x 2 pi / 60, so ``b = thrust_coef / (2 pi / 60)^2``. Motors 0..3
(quadsim rotors 1..4) sit at the URDF prop links: 1 front-right (+L, -L), 2 back-left, 3
front-left, 4 back-right, L = 28 mm; the reaction torque ``torque_coef_i rpm^2`` about body
z is -k for motors 1, 2 and +k for 3, 4, quadsim's ``-s_i d Omega_i^2``: spins +1, +1, -1, -1.

The log (:func:`to_flight_log`, 240 Hz, every physics step; :mod:`.simlog`): position,
velocity and attitude of the body origin (the URDF link origin; the CoM moved by ``com`` is
not where a marker set sits) with motion-capture noise; gyro and accelerometer (specific
force at the body origin from pybullet's own velocity step ``(v_k+1 - v_k) / dt``) with IMU
noise and a gyro bias; rotor speeds (rad/s, PyFlyt's throttle x max rpm) with telemetry
noise, delayed by ``rotor_delay`` s when asked; commands (PyFlyt's pwm, 0-1). No battery is
modelled by PyFlyt: no ``vbat`` column.

Example::

    >>> log, truth = pyflyt_flights([FlightSpec(seed=1, effects={"mass": 0.003})])[0]
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.core.frames import quat_to_rotmat
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .simlog import Sensors, SimStates, body_origin_log, jsonable, truth_json

__all__ = ["CONTROL_HZ", "EFFECTS", "PHYSICS_HZ", "RPM", "WORKER_ENV", "FlightSpec", "Sensors",
           "hover_throttle", "motor_response", "path_setpoints", "pyflyt_available",
           "pyflyt_flights", "pyflyt_model", "to_flight_log", "truth_json", "vehicle_params"]

PHYSICS_HZ = 240
CONTROL_HZ = 120
#: rad/s per RPM
RPM = 2.0 * np.pi / 60.0
#: s flown before the log starts (motors at hover throttle, the PID integrators settle)
LEAD_IN = 2.0
#: the worker's environment: PyFlyt's one numba-jitted function (the motors' thrust and
#: torque, a few array products) runs as the plain Python it is written in -- the same
#: arithmetic without a 15-20 s compile in every child process
WORKER_ENV = {"NUMBA_DISABLE_JIT": "1", "OMP_NUM_THREADS": "1"}
#: mean of PyFlyt 0.29.0's per-step motor-noise draw ``np_random.normal(4)`` (module doc)
NOISE_MEAN = 4.0
#: PyFlyt-side effects (:class:`FlightSpec.effects`), SI units: mass (kg, at the CoM);
#: payload (kg, x, y, z m: a point mass at that body position: mass, CoM and principal
#: inertia change together); com (x, y m: the URDF's inertial origin moves); inertia
#: (relative change of Ixx Iyy Izz); weak_rotor (rotor 1..4, relative change of its
#: thrust and torque coefficient); thrust_scale (relative change of every coefficient);
#: motor_slow (factor on the motor tau); rate_damping (factor on drag_coef_pqr); wind (m/s
#: world x, y, PyFlyt's wind field); lift (N/(m/s)^2 per rotor, translational lift);
#: torque (N m body x, y, z amplitude) with torque_hz (Hz); rotor_delay (s, the log only).
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "motor_slow",
           "rate_damping", "wind", "lift", "torque", "torque_hz", "rotor_delay")


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, PyFlyt's motor noise, sensor noise), speed factor of
    the path, duration (s, logged), PyFlyt-side effects (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def pyflyt_available() -> bool:
    """PyFlyt and pybullet importable (checked without importing them: pybullet prints)."""
    return all(importlib.util.find_spec(m) is not None for m in ("PyFlyt", "pybullet", "yaml"))


def _model_dir() -> Path:
    spec = importlib.util.find_spec("PyFlyt")
    if spec is None or not spec.submodule_search_locations:
        raise ModelError("PyFlyt is not installed (pip install -e '.[pyflyt]' then "
                         "pip install --no-deps PyFlyt==0.29.0)")
    return Path(next(iter(spec.submodule_search_locations))) / "models" / "vehicles" / "cf2x"


def pyflyt_model() -> dict:
    """PyFlyt's ``cf2x`` model as its files state it (read without importing PyFlyt), in
    PyFlyt's units: mass kg, inertia (3,) kg m^2, props (4, 3) m, thrust_coef N/RPM^2,
    torque_coef N m/RPM^2, tau s, max_rpm RPM, drag constants."""
    import yaml

    root = _model_dir()
    with open(root / "cf2x.yaml") as handle:
        cfg = yaml.safe_load(handle)
    urdf = ET.parse(root / "cf2x.urdf").getroot()
    base = urdf.find("./link[@name='base_link']/inertial")
    inertia = base.find("inertia").attrib
    props = np.array([[float(v) for v in urdf.find(f"./link[@name='prop{i}_link']/inertial/"
                                                    "origin").get("xyz").split()]
                      for i in range(1, 5)])
    motor, drag = cfg["motor_params"], cfg["drag_params"]
    return {"mass": float(base.find("mass").get("value")),
            "inertia": np.array([float(inertia[k]) for k in ("ixx", "iyy", "izz")]),
            "props": props, "thrust_coef": float(motor["thrust_coef"]),
            "torque_coef": float(motor["torque_coef"]), "tau": float(motor["tau"]),
            "noise_ratio": float(motor["noise_ratio"]),
            "max_rpm": float(np.sqrt(motor["total_thrust"] / (4 * motor["thrust_coef"]))),
            "drag_coef_xyz": float(drag["drag_coef_xyz"]),
            "drag_area_xyz": float(drag["drag_area_xyz"]),
            "drag_coef_pqr": float(drag["drag_coef_pqr"]),
            "lin_pos_kp": float(cfg["control_params"]["lin_pos"]["kp"][0]),
            "z_pos_kp": float(cfg["control_params"]["z_pos"]["kp"]),
            "ang_pos_kp": float(cfg["control_params"]["ang_pos"]["kp"][2])}


def motor_response(tau: float, noise_ratio: float, physics_hz: int = PHYSICS_HZ
                   ) -> tuple[float, float]:
    """(steady gain throttle/pwm, effective time constant s) of PyFlyt's motor with its
    mean noise draw (module docstring); raises when the motor is unstable at that rate."""
    dt = 1.0 / physics_hz
    a, drift = dt / tau, NOISE_MEAN * noise_ratio
    pole = 1.0 - a + drift
    if not 0.0 < pole < 1.0:
        raise ModelError(f"PyFlyt motor tau {tau} s at {physics_hz} Hz: per-step pole {pole:.3f} "
                         "(its mean noise draw makes it unstable or oscillating)")
    return a / (a - drift), -dt / np.log(pole)


def hover_throttle(model: dict, mass: float | None = None) -> float:
    """Throttle (0..1 of max rpm) whose four thrusts carry ``mass`` (kg)."""
    m = model["mass"] if mass is None else mass
    return float(np.sqrt(m * 9.81 / (4 * model["thrust_coef"])) / model["max_rpm"])


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of PyFlyt's nominal ``cf2x`` (see the module docstring)."""
    model = pyflyt_model()
    yml, urdf = "PyFlyt 0.29.0 cf2x.yaml", "PyFlyt 0.29.0 cf2x.urdf"
    spins = (1.0, 1.0, -1.0, -1.0)
    rotors = tuple(Rotor(str(i + 1), model["props"][i].copy(), np.array([0.0, 0.0, 1.0]),
                         spins[i]) for i in range(4))
    max_speed = model["max_rpm"] * RPM
    gain, _ = motor_response(model["tau"], model["noise_ratio"])
    params = VehicleParams(
        name="pyflyt-cf2x", mass=model["mass"], com=np.zeros(3),
        inertia=np.diag(model["inertia"]), rotors=rotors,
        thrust_factor=model["thrust_coef"] / RPM ** 2,
        drag_factor=model["torque_coef"] / RPM ** 2, max_speed=max_speed, min_speed=0.0,
        rotor_radius=0.0231, rotor_inertia=0.0, gravity=9.81, air_density=1.225,
        motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array([[0.0, gain * max_speed]] * 4),
                           f"PyFlyt's steady throttle = {gain:.4f} x pwm at {PHYSICS_HZ} Hz "
                           "(motor_response), speed = throttle x max rpm"),
        description="PyFlyt QuadX cf2x (Crazyflie 2.x) as quadsim sees it",
        sources={"mass": f"{urdf}: base_link mass (kg)",
                 "inertia": f"{urdf}: base_link ixx iyy izz (kg m^2)",
                 "rotors": f"{urdf}: prop1..4_link inertial origins (m); spins from the "
                           "signs of PyFlyt QuadX torque_coef (-, -, +, +)",
                 "thrust_factor": f"{yml}: thrust_coef (N/RPM^2) / (2 pi/60)^2 (N s^2/rad^2)",
                 "drag_factor": f"{yml}: torque_coef (N m/RPM^2) / (2 pi/60)^2 "
                                "(N m s^2/rad^2)",
                 "max_speed": f"{yml}: sqrt(total_thrust / (4 thrust_coef)) RPM -> rad/s",
                 "min_speed": "PyFlyt's motors go to zero throttle (rad/s)",
                 "rotor_radius": "Crazyflie 2.x 46 mm propeller (not in PyFlyt; m)",
                 "rotor_inertia": "PyFlyt models no propeller spin inertia (kg m^2)",
                 "gravity": "PyFlyt Aviary setGravity(0, 0, -9.81) (m/s^2)",
                 "air_density": "PyFlyt BoringBodies 1.225 (kg/m^3)"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path_setpoints(t: np.ndarray, seed: int, speed: float, compensate: bool = True
                   ) -> np.ndarray:
    """PyFlyt mode-7 setpoints (T, 4) ``[x, y, yaw, z]`` (m, rad) of a 3-D Lissajous figure
    with a yaw sweep and a small fast weave (roll/pitch excitation): x = 0.6 sin(w t) + a
    sin(4.5 w t), y = 0.3 sin(2 w t + phi) + a sin(5.5 w t + phi), a = 0.06 m / max(speed,
    0.5)^2, z = 1 + 0.1 sin(1.7 w t), yaw = 0.5 sin(1.3 w t), w = speed rad/s, phase phi
    from the seed (flown: 1.2 / 1.4 / 1.8 m/s peak, 18 / 20 / 23 deg peak tilt, roll
    acceleration 1.9 / 3.8 / 4.3 rad/s^2 rms at speed 0.7 / 1.0 / 1.4). PyFlyt's position loops are
    proportional (x, y, z: kp 1/s; yaw: kp 2/s), so each setpoint is the path plus its
    rate over that gain (the loop's first-order lag compensated): the vehicle flies near
    the path instead of a shrunk, late copy of it (``compensate=False``: the path itself)."""
    model = pyflyt_model()
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = speed
    weave = 0.06 / max(speed, 0.5) ** 2
    # (column, amplitude m or rad, angular frequency rad/s, phase rad, position gain 1/s)
    terms = ((0, 0.6, w, 0.0, model["lin_pos_kp"]), (1, 0.3, 2 * w, phi, model["lin_pos_kp"]),
             (3, 0.1, 1.7 * w, 0.0, model["z_pos_kp"]),
             (0, weave, 4.5 * w, 0.0, model["lin_pos_kp"]),
             (1, weave, 5.5 * w, phi, model["lin_pos_kp"]),
             (2, 0.5, 1.3 * w, 0.0, model["ang_pos_kp"]))
    out = np.zeros((len(t), 4))
    out[:, 3] = 1.0
    for column, amp, freq, phase, gain in terms:
        arg = freq * t + phase
        lead = freq / gain * np.cos(arg) if compensate else 0.0
        out[:, column] += amp * (np.sin(arg) + lead)
    return out


# ----------------------------------------------------------------------------- the job


def _flight_job(spec: FlightSpec, model: dict) -> dict:
    """PyFlyt parameters and disturbances of one flight (worker job entries)."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown PyFlyt effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    mass = model["mass"] + float(e.get("mass", 0.0))
    inertia = model["inertia"] * (1.0 + np.asarray(e.get("inertia", (0, 0, 0)), dtype=float))
    com = np.zeros(3)
    com[:2] = e.get("com", (0.0, 0.0))
    if "payload" in e:        # point mass m_p at r_p (body): parallel axes about the new CoM
        m_p, r_p = float(e["payload"][0]), np.asarray(e["payload"][1:], dtype=float)
        c = com + m_p * r_p / (mass + m_p)
        full = (np.diag(inertia) + mass * (c @ c * np.eye(3) - np.outer(c, c))
                + m_p * ((r_p - c) @ (r_p - c) * np.eye(3) - np.outer(r_p - c, r_p - c)))
        # pybullet takes principal moments from the URDF; the products (a few % here) are
        # left out, as in the truth sidecar
        inertia, mass, com = np.diag(full).copy(), mass + m_p, c
    scale = np.full(4, 1.0 + float(e.get("thrust_scale", 0.0)))
    if "weak_rotor" in e:
        scale[int(e["weak_rotor"][0]) - 1] *= 1.0 + float(e["weak_rotor"][1])
    tau = model["tau"] * float(e.get("motor_slow", 1.0))
    motor_response(tau, model["noise_ratio"])            # refuses an unstable motor
    wind = np.zeros(3)
    wind[:2] = e.get("wind", (0.0, 0.0))
    return {"mass": mass, "com": com, "inertia": inertia, "tau": tau,
            "drag_coef_pqr": model["drag_coef_pqr"] * float(e.get("rate_damping", 1.0)),
            "motor_scale": scale, "wind": wind, "lift": float(e.get("lift", 0.0)),
            "torque": np.asarray(e.get("torque", (0.0, 0.0, 0.0)), dtype=float),
            "torque_hz": float(e.get("torque_hz", 0.0))}


def pyflyt_flights(specs: list[FlightSpec]) -> list[tuple[FlightLog, dict]]:
    """Fly every spec in PyFlyt (one child process for all of them) and return ``(log,
    truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth sidecar
    (effects in PyFlyt's terms, the PyFlyt parameters of the flight, seed, speed)."""
    model = pyflyt_model()
    n = round(specs[0].duration * PHYSICS_HZ) if specs else 0
    if any(round(s.duration * PHYSICS_HZ) != n for s in specs):
        raise ValueError("pyflyt_flights: every spec of one batch has the same duration")
    lead = round(LEAD_IN * PHYSICS_HZ)
    ratio = PHYSICS_HZ // CONTROL_HZ
    t_control = np.arange((n + lead) // ratio) * ratio / PHYSICS_HZ
    jobs = [_flight_job(s, model) for s in specs]
    setpoints = np.stack([path_setpoints(t_control, s.seed, s.speed) for s in specs])
    job = {k: np.stack([np.asarray(j[k], dtype=float) for j in jobs]) for k in jobs[0]}
    job["setpoints"] = setpoints
    # at rest on the path's start point (the path itself, without the lag compensation)
    job["start"] = np.stack([path_setpoints(np.zeros(1), s.seed, s.speed, compensate=False)[0]
                             [[0, 1, 3, 2]] for s in specs])
    job["throttle0"] = np.array([hover_throttle(model, j["mass"]) for j in jobs])
    job["seed"] = np.array([s.seed for s in specs], dtype=float)
    job.update(physics_hz=np.asarray(PHYSICS_HZ), control_hz=np.asarray(CONTROL_HZ))
    raw = _run_worker(job)
    out = []
    for k, spec in enumerate(specs):
        sample = {name: value[k, lead:lead + n] for name, value in raw.items()}
        if np.min(raw["pos"][k, :, 2]) < 0.2:   # PyFlyt drops its rate damping on contact
            raise ModelError(f"PyFlyt flight {k} (seed {spec.seed}) came within 0.2 m of "
                             "the ground: not a free flight")
        log = to_flight_log(sample, spec, jobs[k]["com"], model)
        truth = {"source": "pyflyt", "model": "cf2x", "seed": spec.seed, "speed": spec.speed,
                 "duration_s": spec.duration, "physics_hz": PHYSICS_HZ,
                 "control_hz": CONTROL_HZ, "effects": jsonable(spec.effects),
                 "pyflyt_params": jsonable(jobs[k])}
        out.append((log, truth))
    return out


def _run_worker(job: dict) -> dict:
    """Run :mod:`.pyflyt_worker` on ``job`` in a temporary folder, its output captured (what
    pybullet prints never reaches the user; a failure is one line of its stderr)."""
    with tempfile.TemporaryDirectory(prefix="quadsim-pyflyt-") as tmp:
        job_path, out_path = os.path.join(tmp, "job.npz"), os.path.join(tmp, "out.npz")
        np.savez(job_path, **job)
        worker = str(Path(__file__).resolve().with_name("pyflyt_worker.py"))
        env = {**os.environ, **WORKER_ENV}
        done = subprocess.run([sys.executable, worker, job_path, out_path], env=env,
                              capture_output=True, text=True, cwd=tmp, check=False)
        if done.returncode != 0:
            tail = done.stderr.strip().splitlines()[-1:] or ["no output"]
            raise ModelError(f"PyFlyt worker failed ({done.returncode}): {tail[0]}")
        with np.load(out_path) as data:
            return {k: np.array(data[k]) for k in data.files}


def to_flight_log(raw: dict, spec: FlightSpec, com: np.ndarray, model: dict | None = None
                  ) -> FlightLog:
    """PyFlyt's states (xyzw, world-frame rates, throttle) -> a quadsim :class:`FlightLog`
    of the body origin with the sensor model of ``spec.sensors`` (seeded by ``spec.seed``)."""
    model = pyflyt_model() if model is None else model
    quat = raw["quat"][:, [3, 0, 1, 2]]                            # xyzw -> wxyz, body -> world
    rot = quat_to_rotmat(quat / np.linalg.norm(quat, axis=1, keepdims=True))

    def to_body(v):
        return np.einsum("nji,nj->ni", rot, v)

    states = SimStates(rate_hz=PHYSICS_HZ, pos=raw["pos"], vel=raw["vel"], quat=quat,
                       ang_vel=to_body(raw["ang_vel"]), ang_acc=to_body(raw["ang_acc"]),
                       acc=raw["acc"], rotor_speed=raw["throttle"] * model["max_rpm"] * RPM,
                       command=raw["pwm"])
    return body_origin_log(states, com, spec.sensors, spec.seed,
                           hover_speed=hover_throttle(model) * model["max_rpm"] * RPM,
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)))
