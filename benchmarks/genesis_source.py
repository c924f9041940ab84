"""Flights of an independent simulator: Genesis 1.4.5 (PyPI ``genesis-world``, Genesis
Authors, "Genesis: A Generative and Universal Physics Engine for Robotics and Beyond",
2024; github.com/Genesis-Embodied-AI/Genesis, Apache-2.0): its own rigid-body solver and
its own drone, ``genesis.morphs.Drone`` with the vehicle file ``urdf/drones/racer.urdf``
shipped in Genesis' assets (a 0.83 kg racing quadrotor, rotors on a 170 x 135 mm
rectangle, ``model="RACE"``), flown on Genesis' CPU backend in double precision.

What Genesis models: per propeller a thrust ``KF rpm^2`` along the link's z and a torque
``KM rpm^2`` about it (rpm in rev/min; the RACE model's sign), on its propeller link; the
rigid solver does the rest. No motor, no air, no ground effect (the file's drag, ground and
downwash coefficients are not read by Genesis).

quadsim adds (:mod:`.genesis_worker`, every 1 kHz physics step; the references share the
first two):

* **DC motors** (:data:`MOTOR`, :class:`benchmarks.geometric.DCMotor`): a 2400 KV
  outrunner on 4S (14.8 V), k_t = k_e = 60 / (2 pi 2400) V s/rad, R 0.07 ohm, the rotor and
  5-inch propeller's J 8e-6 kg m^2: 34 ms at hover, hover at a duty of 0.44.
* **The file's rotor drag** (:func:`rotor_drag_force`): ``drag_coeff_xy`` and
  ``drag_coeff_z`` of ``racer.urdf`` (9.1785e-7, 10.311e-7 N s/m per rad/s), in the form
  gym-pybullet-drones gives them: ``F_body = -diag(k_xy, k_xy, k_z) (sum_i Omega_i) v_air``
  (quadsim's ``rotor_drag`` with its axial coefficient); with a wind, v_air = v - wind.
* A weak rotor (its rpm x sqrt(scale): thrust and torque x scale, its motor's load too);
  rate damping, a periodic torque or force (one external wrench at the base link's CoM);
  mass, CoM and inertia through Genesis' own setters; a late rotor log.

The flights' controller is quadsim's geometric controller
(:class:`benchmarks.geometric.Geometric`) on the vehicle's nominal numbers, the path
:func:`benchmarks.qcsim_source.path`.

Vehicle (:func:`vehicle_params`, "genesis-racer"): ``racer.urdf``: mass 0.830 kg, inertia
0.003113 kg m^2 on every axis, rotors at (+-0.085, +-0.0675) m, KF 8.47e-9 N/rpm^2 (b =
KF (60 / 2 pi)^2 = 7.72e-7 N s^2/rad^2), KM 2.13e-11 N m/rpm^2 (d = 1.94e-9 N m
s^2/rad^2), prop_radius 0.127 m as the file states (rotors 0.135 m apart: its propellers
would overlap; the file's number is kept); spins: Genesis' default (-1, 1, -1, 1), which under
RACE are quadsim's spins. Hover at 1623 rad/s (15 500 rpm).

The log (:func:`to_flight_log`, 500 Hz: every second 1 kHz step; :mod:`.simlog`): motion of
the base link's origin (Genesis' ``get_pos``/``get_vel``; the CoM moved by ``com`` is not
where it sits) with motion-capture noise, gyro and accelerometer (specific force from the
velocity step) with IMU noise, rotor speeds (each step's mean motor speed) with telemetry
noise, delayed by ``rotor_delay`` s when asked, and commands as the duty cycle.

Units and frames at the boundary: Genesis' world is z up, its quaternions w-first body ->
world, its angular velocity in world axes (turned into body rates here), its propeller speeds
rev/min (rad/s inside quadsim).

Install: Genesis needs torch; ``pip install -e '.[genesis]'`` in an environment with
torch's CPU wheel (``pip install torch --index-url https://download.pytorch.org/whl/cpu``),
or point ``QUADSIM_GENESIS_PYTHON`` at the interpreter of another environment that has
Genesis (the worker imports quadsim's pure modules from this checkout; that environment
needs numpy and scipy).

Example::

    >>> log, truth = genesis_flights([FlightSpec(seed=1, effects={"mass": 0.1})])[0]
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, mass_properties, rotor_scales
from .geometric import DCMotor
from .qcsim_source import EFFECTS, FlightSpec
from .simlog import Sensors, SimStates, body_origin_log, jsonable, truth_json

__all__ = ["EFFECTS", "LOG_HZ", "MODEL", "MOTOR", "PHYSICS_HZ", "URDF", "FlightSpec",
           "Sensors", "duty_for", "genesis_available", "genesis_flights", "genesis_python",
           "genesis_version",
           "hover_speed_of", "rotor_drag_force", "to_flight_log", "truth_json",
           "vehicle_params"]

PHYSICS_HZ = 1000
CONTROL_HZ = 500
LOG_HZ = 500
#: s flown before the log starts (from rest at the path's start: the controller catches up)
LEAD_IN = 2.0
#: the vehicle file, in Genesis' assets
URDF = "urdf/drones/racer.urdf"
RPM = 60.0 / (2.0 * np.pi)
#: the vehicle in SI units (module doc): racer.urdf's numbers; quadsim's motor and battery
MODEL = {"mass": 0.830, "inertia": (0.003113, 0.003113, 0.003113), "gravity": 9.81,
         "positions": ((0.085, 0.0675), (-0.085, 0.0675), (-0.085, -0.0675), (0.085, -0.0675)),
         "spins": (-1, 1, -1, 1), "b": 8.47e-9 * RPM ** 2, "d": 2.13e-11 * RPM ** 2,
         "prop_radius": 0.127, "drag_xy": 9.1785e-7, "drag_z": 10.311e-7,
         "battery": 14.8, "k_emf": 60.0 / (2 * np.pi * 2400.0), "resistance": 0.07,
         "motor_inertia": 8e-6, "rho": 1.225}
#: the motors (module doc)
MOTOR = DCMotor(battery=MODEL["battery"], k_emf=MODEL["k_emf"], resistance=MODEL["resistance"],
                inertia=MODEL["motor_inertia"])
# a flight (FlightSpec) and its case-side effects (EFFECTS) are quadcopter-sim's: the same
# table, the same additions


def genesis_python() -> str:
    """The interpreter that runs the flights: ``QUADSIM_GENESIS_PYTHON`` or this one."""
    return os.environ.get("QUADSIM_GENESIS_PYTHON") or sys.executable


def genesis_available() -> bool:
    """Genesis importable by :func:`genesis_python` (checked without importing it)."""
    probe = "import importlib.util, sys; sys.exit(importlib.util.find_spec('genesis') is None)"
    try:
        return subprocess.run([genesis_python(), "-c", probe], capture_output=True,
                              timeout=60, check=False).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def genesis_version() -> str:
    """genesis-world's version as :func:`genesis_python` has it (the flights' cache key)."""
    probe = "import importlib.metadata as m; print(m.version('genesis-world'))"
    done = subprocess.run([genesis_python(), "-c", probe], capture_output=True, text=True,
                          timeout=60, check=False)
    if done.returncode != 0:
        raise ModelError(f"genesis-world is not installed for {genesis_python()}")
    return done.stdout.strip()


def hover_speed_of(mass: float = MODEL["mass"]) -> float:
    """Rotor speed (rad/s) at which the four rotors carry ``mass`` (kg): sqrt(m g / 4 b)."""
    return float(np.sqrt(mass * MODEL["gravity"] / (4 * MODEL["b"])))


def duty_for(speed) -> np.ndarray:
    """The duty cycle whose steady speed is ``speed`` (rad/s) with the nominal propeller (the
    controller's feed-forward)."""
    return MOTOR.duty_for(speed, MODEL["d"])


def rotor_drag_force(air_body: np.ndarray, speeds: np.ndarray) -> np.ndarray:
    """The vehicle file's rotor drag (N, body axes; module doc): ``-diag(k_xy, k_xy, k_z)
    (sum_i Omega_i) v_air`` for the body-frame air velocity (m/s) and rotor speeds (rad/s)."""
    k = np.array([MODEL["drag_xy"], MODEL["drag_xy"], MODEL["drag_z"]])
    return -k * float(np.sum(speeds)) * np.asarray(air_body, dtype=float)


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of the nominal vehicle (module doc)."""
    m = MODEL
    rotors = tuple(Rotor(str(i + 1), np.array([x, y, 0.0]), np.array([0.0, 0.0, 1.0]),
                         float(spin))
                   for i, ((x, y), spin) in enumerate(zip(m["positions"], m["spins"])))
    grid = np.linspace(0.0, 1.0, 41)
    speed = MOTOR.steady_speed(grid, m["d"])
    src = "genesis-world 1.4.5 assets/urdf/drones/racer.urdf"
    params = VehicleParams(
        name="genesis-racer", mass=m["mass"], com=np.zeros(3), inertia=np.diag(m["inertia"]),
        rotors=rotors, thrust_factor=m["b"], drag_factor=m["d"], max_speed=float(speed[-1]),
        min_speed=0.0, rotor_radius=m["prop_radius"], rotor_inertia=0.0,
        gravity=m["gravity"], air_density=m["rho"],
        motor_map=MotorMap("1", grid, np.tile(speed, (4, 1)),
                           "the DC motor in steady state: duty cycle of 14.8 V -> rad/s"),
        description="Genesis 1.4.5's 0.83 kg racer (racer.urdf) with quadsim's DC motors "
                    "(2400 KV, 4S) as quadsim sees it",
        sources={"mass": f"{src}: base_link mass (kg)",
                 "inertia": f"{src}: base_link inertia (kg m^2)",
                 "rotors": f"{src}: prop0..3 link origins; Genesis' default spins under "
                           "model RACE (m)",
                 "thrust_factor": f"{src}: kf 8.47e-9 N/rpm^2 x (60 / 2 pi)^2 "
                                  "(N s^2/rad^2)",
                 "drag_factor": f"{src}: km 2.13e-11 N m/rpm^2 x (60 / 2 pi)^2 "
                                "(N m s^2/rad^2)",
                 "max_speed": "steady speed at full duty (rad/s)",
                 "min_speed": "the motors stop at zero duty (rad/s)",
                 "rotor_radius": f"{src}: prop_radius (m)",
                 "rotor_inertia": "Genesis leaves the spin-up torque out (kg m^2)",
                 "gravity": "Genesis' SimOptions gravity as set (m/s^2)",
                 "air_density": "ISA sea level (kg/m^3)"})
    check_physical(params, where=params.name)
    return params


def _flight_job(spec: FlightSpec) -> dict:
    """Genesis parameters and this module's additions of one flight (SI)."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown Genesis effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    mass, com, inertia = mass_properties(e, MODEL["mass"], MODEL["inertia"])
    return {"mass": mass, "com": com, "inertia": inertia, "rotor_scale": rotor_scales(e),
            "motor_inertia": MODEL["motor_inertia"] * float(e.get("motor_slow", 1.0)),
            **disturbances(e)}


#: worker processes (one Genesis scene each; each builds in ~10 s with a warm kernel cache)
WORKERS = 2


def genesis_flights(specs: list[FlightSpec], workers: int | None = None
                    ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec in Genesis (``workers`` child processes of :func:`genesis_python`,
    default :data:`WORKERS`) and return ``(log, truth)`` per spec: the log as
    :func:`to_flight_log` makes it, the truth sidecar (effects, the flight's parameters,
    seed, speed)."""
    if not genesis_available():
        raise ModelError(f"Genesis is not importable by {genesis_python()} (pip install "
                         "'quadsim[genesis]' with torch's CPU wheel, or set "
                         "QUADSIM_GENESIS_PYTHON)")
    jobs = [_flight_job(s) for s in specs]
    n = max(1, min(len(specs), workers or WORKERS))
    chunks = [list(range(k, len(specs), n)) for k in range(n)]
    with tempfile.TemporaryDirectory() as tmp:
        procs = []
        for c, idx in enumerate(chunks):
            job = {key: np.array([jobs[i][key] for i in idx]) for key in jobs[0]}
            job.update(seed=np.array([specs[i].seed for i in idx]),
                       speed=np.array([specs[i].speed for i in idx]),
                       steps=np.array([round(specs[i].duration * PHYSICS_HZ) for i in idx]),
                       lead=round(LEAD_IN * PHYSICS_HZ), physics_hz=PHYSICS_HZ,
                       control_hz=CONTROL_HZ)
            path = Path(tmp) / f"job{c}.npz"
            np.savez(path, **job)
            worker = str(Path(__file__).resolve().with_name("genesis_worker.py"))
            procs.append(subprocess.Popen([genesis_python(), worker, str(path),
                                           str(Path(tmp) / f"out{c}.npz")], cwd=tmp,
                                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT))
        outputs = [p.communicate()[0] for p in procs]
        raws: dict[int, dict] = {}
        for c, (idx, p, text) in enumerate(zip(chunks, procs, outputs)):
            if p.returncode != 0:
                tail = text.decode(errors="replace").strip().splitlines()[-1:] or ["?"]
                raise ModelError(f"Genesis worker failed ({p.returncode}): {tail[0]}")
            out = np.load(Path(tmp) / f"out{c}.npz")
            for j, i in enumerate(idx):
                raws[i] = {key: out[f"{key}_{j}"] for key in ("states", "speeds", "commands")}
    lead = round(LEAD_IN * PHYSICS_HZ)
    return [(to_flight_log({k: v[lead:] for k, v in raws[i].items()}, spec),
             {"source": "genesis", "model": "genesis-racer", "seed": spec.seed,
              "speed": spec.speed, "duration_s": spec.duration, "physics_hz": PHYSICS_HZ,
              "log_hz": LOG_HZ, "effects": jsonable(spec.effects),
              "genesis_params": jsonable(jobs[i])})
            for i, spec in enumerate(specs)]


def to_flight_log(raw: dict, spec: FlightSpec) -> FlightLog:
    """The base link origin's states at 1 kHz and the rotor speeds and duties of each step
    -> a quadsim :class:`FlightLog` at :data:`LOG_HZ` with the sensor model of
    ``spec.sensors`` (seeded by ``spec.seed``); the states are the origin's already."""
    x = raw["states"]
    dt = 1.0 / PHYSICS_HZ
    acc = np.diff(x[:, 3:6], axis=0) / dt
    ang_acc = np.diff(x[:, 10:13], axis=0) / dt
    keep = np.arange(0, len(x) - 1, PHYSICS_HZ // LOG_HZ)
    states = SimStates(rate_hz=LOG_HZ, pos=x[keep, 0:3], vel=x[keep, 3:6], quat=x[keep, 6:10],
                       ang_vel=x[keep, 10:13], ang_acc=ang_acc[keep], acc=acc[keep],
                       rotor_speed=raw["speeds"][keep + 1], command=raw["commands"][keep + 1])
    return body_origin_log(states, np.zeros(3), spec.sensors, spec.seed,
                           hover_speed=hover_speed_of(),
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)),
                           gravity=MODEL["gravity"])
