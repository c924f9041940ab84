"""Independent flights from Crazyflow (JAX + MuJoCo; its own dynamics, integrator, controller,
vehicle).

Crazyflow (``pip install crazyflow``, tested with 0.4.0; Learning Systems and Robotics Lab,
TU Munich, https://github.com/utiasDSL/crazyflow) flies a Crazyflie 2.1 Brushless
(``cf21B_500``) with its own first-principles dynamics (thrust and torque *quadratic
polynomials in RPM with a linear term*, nonlinear rotor dynamics with different spin-up and
spin-down rates -- about 57 ms time constant at hover --, linear body drag 22/25 mN/(m/s),
propeller gyroscopic and reaction torques), its own RK4 integrator at 500 Hz and its own
Mellinger controller (firmware gains, its own controller mass 39.3 g against the 43.4 g
vehicle). None of quadsim's effect hooks, engines or controllers is used: an effect is a
change of Crazyflow's own parameters (``sim.data.params``) or a force/torque through its own
disturbance inputs. The JAX part runs in a child process (:mod:`.crazyflow_worker`: Crazyflow
needs SciPy's array-API mode, which must not be switched on in quadsim's process).

Units at the boundary: Crazyflow's rotor speeds are RPM (``rad/s = RPM * 2 pi / 60``), its
quaternions xyzw (reordered to wxyz), its frames z up with body x forward, y left (as quadsim:
no sign change); its motor 1 is front-right at (+L, -L), 2 back-right, 3 back-left, 4
front-left, from its mixing matrix ``M``: ``x_i = -M[1, i] L``, ``y_i = M[0, i] L``, and its
yaw torque ``+M[2, i] t_i`` is quadsim's ``-s_i d Omega_i^2``, so ``s_i = -M[2, i]``.

The quadsim parameter set of this vehicle (:func:`vehicle_params`, built in code from
Crazyflow's own ``params.toml``): mass, inertia, rotor positions and spins as above; ``b``
and ``d`` are the least-squares fits of ``b Omega^2`` to Crazyflow's thrust and torque
curves over 0.75-1.25 x the hover speed (quadsim's rotor model has no linear term: that is
part of the independent source's own physics the diagnosis has to live with); max/min speed
from Crazyflow's thrust limits; the command map is linear (command = commanded speed / max
speed, as the logged commands are defined).

The log (:func:`to_flight_log`, 500 Hz): position, velocity and attitude of the body origin
(the geometric centre: the CoM moved by ``com`` is not where a marker set sits) with
motion-capture noise; gyro and accelerometer (specific force at the body origin, from
Crazyflow's own state derivative) with IMU noise and a gyro bias; rotor speeds (rad/s) with
telemetry noise, delayed by ``rotor_delay`` s when asked; commands (commanded speed / max
speed, 0-1). No battery is modelled by Crazyflow: no ``vbat`` column. Noise levels in
:class:`Sensors` (Vicon-class motion capture 0.3 mm / 1 mrad; BMI088-class IMU).

Example::

    >>> spec = FlightSpec(seed=1, effects={"mass": 0.004})
    >>> log, truth = crazyflow_flights([spec])[0]
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

from .simlog import Sensors, SimStates, body_origin_log, jsonable, truth_json

__all__ = ["DRONE", "EFFECTS", "RATE_HZ", "RPM", "FlightSpec", "Sensors", "crazyflow_available",
           "crazyflow_flights", "crazyflow_params", "hover_rpm", "path_setpoints", "to_flight_log",
           "truth_json", "vehicle_params"]

DRONE = "cf21B_500"
RATE_HZ = 500
#: rad/s per RPM
RPM = 2.0 * np.pi / 60.0
#: s flown before the log starts (the controller settles from the start state)
LEAD_IN = 1.0
#: Crazyflow-side effects (:class:`FlightSpec.effects`), SI units:
#: mass (kg, at the CoM); payload (kg, x, y, z m: a point mass at that body position: mass,
#: CoM and inertia change together); com (x, y m: the CoM moves); inertia (relative change
#: of Jxx Jyy Jzz); weak_rotor (rotor 1..4, relative change of its thrust and torque curve);
#: thrust_scale (relative change of every thrust and torque curve); motor_slow (factor > 1
#: dividing every rotor-dynamics coefficient: time constants x factor); drag_scale (factor
#: on the x, y entries of the drag matrix); wind (m/s world x, y); lift (N/(m/s)^2 per rotor,
#: translational lift); flap (N m s^2/(rad m), blade-flapping moment); torque (N m body x,
#: y, z amplitude) with torque_hz (Hz); rotor_delay (s, the rotor-speed log only).
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "motor_slow",
           "drag_scale", "wind", "lift", "flap", "torque", "torque_hz", "rotor_delay")


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, noise), speed factor of the path, duration (s, logged),
    Crazyflow-side effects (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def crazyflow_available() -> bool:
    """crazyflow and jax importable (checked without importing them)."""
    return all(importlib.util.find_spec(m) is not None for m in ("crazyflow", "jax"))


def _package_dir() -> Path:
    spec = importlib.util.find_spec("crazyflow")
    if spec is None or not spec.submodule_search_locations:
        raise ModelError("crazyflow is not installed (pip install -e '.[crazyflow]')")
    return Path(next(iter(spec.submodule_search_locations)))


def crazyflow_params(drone: str = DRONE) -> dict:
    """Crazyflow's first-principles parameters of ``drone`` as its own loader merges them
    (``dynamics/params.toml`` | ``dynamics/first_principles/params.toml[drone]``), read
    without importing crazyflow; numpy arrays, Crazyflow's units (RPM polynomials)."""
    root = _package_dir() / "dynamics"
    with open(root / "params.toml", "rb") as handle:
        merged = tomllib.load(handle)
    with open(root / "first_principles" / "params.toml", "rb") as handle:
        merged |= tomllib.load(handle)[drone]
    return {k: np.asarray(v, dtype=float) if not isinstance(v, dict) else v
            for k, v in merged.items() if not isinstance(v, dict)}


def _speed_for_thrust(curve: np.ndarray, thrust: float) -> float:
    """RPM where the polynomial ``curve`` (powers 0, 1, 2) gives ``thrust`` N."""
    c, b, a = curve
    return float((-b + np.sqrt(b * b - 4 * a * (c - thrust))) / (2 * a))


def hover_rpm(cp: dict, mass: float | None = None) -> float:
    m = float(cp["mass"]) if mass is None else mass
    return _speed_for_thrust(np.ravel(cp["rpm2thrust"]), m * 9.81 / 4.0)


def vehicle_params(drone: str = DRONE) -> VehicleParams:
    """quadsim's parameter set of Crazyflow's nominal ``drone`` (see the module docstring)."""
    cp = crazyflow_params(drone)
    src = f"crazyflow {drone} first_principles params.toml"
    mixing, arm = cp["mixing_matrix"], float(np.ravel(cp["L"])[0])
    hover = hover_rpm(cp)
    omega = np.linspace(0.75, 1.25, 101) * hover                        # RPM
    x = (omega * RPM) ** 2
    thrust = np.polyval(np.ravel(cp["rpm2thrust"])[::-1], omega)
    torque = np.polyval(np.ravel(cp["rpm2torque"])[::-1], omega)
    b = float(x @ thrust / (x @ x))
    d = float(x @ torque / (x @ x))
    max_rpm = _speed_for_thrust(np.ravel(cp["rpm2thrust"]), float(cp["thrust_max"]))
    min_rpm = _speed_for_thrust(np.ravel(cp["rpm2thrust"]), float(cp["thrust_min"]))
    rotors = tuple(Rotor(str(i + 1), np.array([-mixing[1, i] * arm, mixing[0, i] * arm, 0.0]),
                         np.array([0.0, 0.0, 1.0]), float(-mixing[2, i])) for i in range(4))
    max_speed = max_rpm * RPM
    fit = "least-squares b Omega^2 fit of its curve over 0.75-1.25 x hover"
    params = VehicleParams(
        name=f"crazyflow-{drone}", mass=float(cp["mass"]), com=np.zeros(3),
        inertia=np.asarray(cp["J"], dtype=float), rotors=rotors, thrust_factor=b,
        drag_factor=d, max_speed=max_speed, min_speed=min_rpm * RPM, rotor_radius=0.0275,
        rotor_inertia=float(np.ravel(cp["prop_inertia"])[0]), gravity=9.81,
        motor_map=MotorMap("1", np.array([0.0, 1.0]),
                           np.array([[0.0, max_speed]] * 4), "command = commanded speed / max"),
        description=f"Crazyflow {drone} (Crazyflie 2.1 Brushless) as quadsim sees it",
        sources={"mass": f"{src}: mass (kg)", "inertia": f"{src}: J (kg m^2)",
                 "rotors": f"{src}: L (m) and mixing_matrix",
                 "thrust_factor": f"{src}: rpm2thrust, {fit} (N s^2/rad^2)",
                 "drag_factor": f"{src}: rpm2torque, {fit} (N m s^2/rad^2)",
                 "max_speed": f"{src}: thrust_max per motor through rpm2thrust (rad/s)",
                 "min_speed": f"{src}: thrust_min per motor through rpm2thrust (rad/s)",
                 "rotor_inertia": f"{src}: prop_inertia (kg m^2)",
                 "rotor_radius": "crazyflie21 parameter set (not in Crazyflow; m)",
                 "gravity": f"{src}: gravity_vec (m/s^2)"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path_setpoints(t: np.ndarray, seed: int, speed: float) -> np.ndarray:
    """Mellinger state setpoints (T, 16) of a 3-D Lissajous figure with a yaw sweep and a
    small fast weave (roll/pitch excitation: about 1.3 m/s^2 at every speed, 6 rad/s^2 at
    speed 1): x = 0.5 sin(w t) + a sin(4.5 w t), y = 0.3 sin(2 w t + phi) + a sin(5.5 w t +
    phi), a = 0.03 m / max(speed, 0.5)^2, z = 1 + 0.1
    sin(1.7 w t), yaw = 0.4 sin(1.3 w t), w = 1.2 speed rad/s (about 1 m/s peak at speed
    1), phase phi from the seed."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 1.2 * speed
    weave = 0.03 / max(speed, 0.5) ** 2
    # (axis, amplitude m, angular frequency rad/s, phase rad)
    terms = ((0, 0.5, w, 0.0), (1, 0.3, 2 * w, phi), (2, 0.1, 1.7 * w, 0.0),
             (0, weave, 4.5 * w, 0.0), (1, weave, 5.5 * w, phi))
    out = np.zeros((len(t), 16))
    out[:, 2] = 1.0
    for axis, amp, freq, phase in terms:
        arg = freq * t + phase
        out[:, axis] += amp * np.sin(arg)
        out[:, 3 + axis] += amp * freq * np.cos(arg)
        out[:, 6 + axis] -= amp * freq ** 2 * np.sin(arg)
    yaw = 0.4 * np.sin(1.3 * w * t)
    out[:, 11], out[:, 12] = np.sin(yaw / 2), np.cos(yaw / 2)
    out[:, 15] = 0.4 * 1.3 * w * np.cos(1.3 * w * t)
    return out


# ----------------------------------------------------------------------------- the job


def _flight_job(spec: FlightSpec, cp: dict) -> dict:
    """Crazyflow parameters and disturbances of one flight (worker job entries)."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown Crazyflow effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    mass = float(cp["mass"]) + float(e.get("mass", 0.0))
    inertia = np.asarray(cp["J"], dtype=float) * (1.0 + np.asarray(e.get("inertia", (0, 0, 0))))
    com = np.zeros(3)
    com[:2] = e.get("com", (0.0, 0.0))
    if "payload" in e:                       # point mass m_p at r_p (body), about the new CoM
        m_p, r_p = float(e["payload"][0]), np.asarray(e["payload"][1:], dtype=float)
        c = com + m_p * r_p / (mass + m_p)
        inertia = (inertia + mass * (c @ c * np.eye(3) - np.outer(c, c))
                   + m_p * ((r_p - c) @ (r_p - c) * np.eye(3) - np.outer(r_p - c, r_p - c)))
        mass, com = mass + m_p, c
    thrust = np.tile(np.ravel(cp["rpm2thrust"]), (4, 1))
    torque = np.tile(np.ravel(cp["rpm2torque"]), (4, 1))
    scale = np.full(4, 1.0 + float(e.get("thrust_scale", 0.0)))
    if "weak_rotor" in e:
        scale[int(e["weak_rotor"][0]) - 1] *= 1.0 + float(e["weak_rotor"][1])
    thrust, torque = thrust * scale[:, None], torque * scale[:, None]
    dyn = np.tile(np.ravel(cp["rotor_dyn_coef"]), (4, 1)) / float(e.get("motor_slow", 1.0))
    arm = float(np.ravel(cp["L"])[0])
    mixing = np.asarray(cp["mixing_matrix"], dtype=float).copy()
    mixing[0] -= com[1] / arm                # torque_x = sum (y_i - c_y) f_i
    mixing[1] += com[0] / arm                # torque_y = -sum (x_i - c_x) f_i
    drag = np.asarray(cp["drag_matrix"], dtype=float).copy()
    drag[:2, :2] *= float(e.get("drag_scale", 1.0))
    wind = np.zeros(3)
    wind[:2] = e.get("wind", (0.0, 0.0))
    return {"mass": mass, "J": inertia, "rpm2thrust": thrust, "rpm2torque": torque,
            "rotor_dyn_coef": dyn, "mixing_matrix": mixing, "drag_matrix": drag, "wind": wind,
            "lift": float(e.get("lift", 0.0)), "flap": float(e.get("flap", 0.0)) * RPM,
            "torque": np.asarray(e.get("torque", (0.0, 0.0, 0.0)), dtype=float),
            "torque_hz": float(e.get("torque_hz", 0.0)), "_com": com}


def crazyflow_flights(specs: list[FlightSpec], drone: str = DRONE) -> list[tuple[FlightLog, dict]]:
    """Fly every spec in Crazyflow (one child process for all of them) and return
    ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth sidecar
    (effects in Crazyflow's terms, the Crazyflow parameters that differ, seed, speed)."""
    cp = crazyflow_params(drone)
    n = round(specs[0].duration * RATE_HZ) if specs else 0
    if any(round(s.duration * RATE_HZ) != n for s in specs):
        raise ValueError("crazyflow_flights: every spec of one batch has the same duration")
    lead = round(LEAD_IN * RATE_HZ)
    t = (np.arange(n + lead) - lead) / RATE_HZ
    jobs = [_flight_job(s, cp) for s in specs]
    cmd = np.stack([path_setpoints(t + LEAD_IN, s.seed, s.speed) for s in specs])
    start = np.zeros((len(specs), 13))
    start[:, 0:6] = cmd[:, 0, 0:6]
    start[:, 6:10] = [0.0, 0.0, 0.0, 1.0]
    job = {k: np.stack([j[k] for j in jobs]) for k in jobs[0] if not k.startswith("_")}
    job["rotor0"] = np.stack([np.full(4, hover_rpm(cp, j["mass"])) for j in jobs])
    job.update(cmd=cmd, start=start, freq=np.asarray(RATE_HZ), drone=np.asarray(drone))
    raw = _run_worker(job)
    out = []
    for k, spec in enumerate(specs):
        sample = {name: value[k, lead:] for name, value in raw.items()}
        log = to_flight_log(sample, spec, jobs[k]["_com"], drone)
        truth = {"source": "crazyflow", "drone": drone, "seed": spec.seed, "speed": spec.speed,
                 "duration_s": spec.duration, "effects": jsonable(spec.effects),
                 "crazyflow_params": jsonable({key: jobs[k][key] for key in jobs[k]
                                                if not key.startswith("_")})}
        out.append((log, truth))
    return out


def _run_worker(job: dict) -> dict:
    env = {**os.environ, "SCIPY_ARRAY_API": "1", "JAX_PLATFORMS": "cpu"}
    with tempfile.TemporaryDirectory(prefix="quadsim-crazyflow-") as tmp:
        job_path, out_path = os.path.join(tmp, "job.npz"), os.path.join(tmp, "out.npz")
        np.savez(job_path, **job)
        # run by file name in the temporary folder: MuJoCo's MUJOCO_LOG.TXT lands there
        worker = str(Path(__file__).resolve().with_name("crazyflow_worker.py"))
        done = subprocess.run([sys.executable, worker, job_path, out_path], env=env,
                              capture_output=True, text=True, cwd=tmp, check=False)
        if done.returncode != 0:
            tail = done.stderr.strip().splitlines()[-1:] or ["no output"]
            raise ModelError(f"crazyflow worker failed ({done.returncode}): {tail[0]}")
        with np.load(out_path) as data:
            return {k: np.array(data[k]) for k in data.files}


def to_flight_log(raw: dict, spec: FlightSpec, com: np.ndarray, drone: str = DRONE) -> FlightLog:
    """Crazyflow's states (xyzw, RPM, CoM) -> a quadsim :class:`FlightLog` of the body origin
    with the sensor model of ``spec.sensors`` (seeded by ``spec.seed``; :mod:`.simlog`)."""
    cp = crazyflow_params(drone)
    max_rpm = _speed_for_thrust(np.ravel(cp["rpm2thrust"]), float(cp["thrust_max"]))
    states = SimStates(rate_hz=RATE_HZ, pos=raw["pos"], vel=raw["vel"],
                       quat=raw["quat"][:, [3, 0, 1, 2]],          # xyzw -> wxyz, body -> world
                       ang_vel=raw["ang_vel"], ang_acc=raw["ang_acc"], acc=raw["acc"],
                       rotor_speed=raw["rotor_vel"] * RPM, command=raw["rotor_cmd"] / max_rpm)
    return body_origin_log(states, com, spec.sensors, spec.seed,
                           hover_speed=hover_rpm(cp) * RPM,
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)))
