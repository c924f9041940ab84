"""Flights of an independent simulator the project had never used: gym-pybullet-drones
(University of Toronto DSL, ``gym_pybullet_drones``, MIT), as packaged on the package index by
its fork ``swarm-drone-gym`` 2.0.0.3 (the upstream name is not on the index; the fork keeps
upstream's ``CtrlAviary``, ``DSLPIDControl`` and ``cf2x.urdf``, and adds its own drone model
beside them) on pybullet 3.2.7.

Everything that moves the vehicle is the simulator's own:

* **dynamics**: ``Physics.PYB_GND_DRAG_DW`` -- pybullet's multibody integrator (semi-implicit
  Euler at :data:`PHYSICS_HZ`) with the aviary's forces: per rotor ``kf rpm^2`` along body z at
  its propeller link, the yaw torque ``km (-rpm0^2 + rpm1^2 - rpm2^2 + rpm3^2)``, its ground
  effect (nil at the flights' 0.8-1.3 m), its drag ``R^T (-k (sum_i Omega_i) v)`` with the
  per-world-axis coefficients k of the URDF (Foerster 2015: 9.1785e-7, 9.1785e-7, 10.311e-7
  kg/rad; ``Omega`` in rad/s of the previous step's command) and its downwash (nil: one
  drone); and pybullet's default damping of every multibody, which the aviary leaves on:
  linear ``-m v (0.04 + 0.04 |v|)``, angular ``-J w (0.04 + 0.04 |w|)`` (measured on this
  install: the velocity's decay rate per second is 0.04 + 0.04 |v|);
* **controller**: ``DSLPIDControl`` for ``DroneModel.CF2X`` (its PID gains, PWM map and
  clipping), at :data:`CONTROL_HZ`, given the path's position, velocity and yaw;
* **vehicle**: ``cf2x.urdf`` (:data:`MODEL`); the rotor speed is the commanded RPM (the
  aviary has no motor dynamics).

Case changes, each through the simulator's own handles: mass and inertia by pybullet's
``changeDynamics`` (``mass``, ``localInertiaDiagonal``); one rotor's or every rotor's kf (and
km with it) and a CoM offset in :class:`_aviary_class`'s ``_physics``, the aviary's own method
with a factor per rotor and the thrust applied at ``-c`` in each propeller link's frame (the
rotors sit at ``r_i - c`` from the CoM, pybullet's base); a wind and a drag scale in its
``_drag`` (air-relative velocity ``v - w``; k x ``drag_scale``, 0 = the drag off); a periodic
body torque or vertical force by pybullet's ``applyExternalTorque`` / ``applyExternalForce``
in the same physics step.

The log (:func:`to_flight_log`, :data:`LOG_HZ` = the physics rate; :mod:`.simlog`): pybullet's
base (the CoM) moved to the body origin (the rotors' centre), its attitude, its world velocity,
body rates (``R^T w`` of pybullet's world angular velocity), the specific force from the
velocity step over each physics step, the rotor speed of that step (commanded RPM in rad/s)
and the command ``rpm / MAX_RPM``, with the same sensor noise as the other sources.

Units and frames: pybullet's are quadsim's (world z up, body x forward, z up); its
quaternions are (x, y, z, w) and are reordered w-first; RPM -> rad/s by 2 pi / 60.

Example::

    >>> log, truth = gpd_flights([FlightSpec(seed=1, effects={"mass": 0.003})])[0]
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
from dataclasses import dataclass, field

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, fly_all, mass_properties, rotor_scales
from .simlog import Sensors, SimStates, body_origin_log

__all__ = ["CONTROL_HZ", "EFFECTS", "LEAD_IN", "LOG_HZ", "MODEL", "PHYSICS_HZ", "RPM",
           "FlightSpec", "gpd_available", "gpd_flights", "hover_speed_of", "max_speed", "path",
           "to_flight_log", "vehicle_params"]

PHYSICS_HZ = 500
CONTROL_HZ = 250
LOG_HZ = 500
#: s flown before the log starts (the PID's integrals settle)
LEAD_IN = 2.0
#: rad/s per RPM
RPM = 2.0 * np.pi / 60.0
#: cf2x.urdf as shipped (``<properties>`` and base_link's ``<inertial>``), SI; gravity is
#: BaseAviary's ``G``; the rotors' (x, y) from the propeller links' origins (prop0..prop3), the
#: sign of each one's reaction torque about body z from ``_physics`` (-t0 + t1 - t2 + t3);
#: damping: pybullet's default multibody damping (module doc)
MODEL = {"mass": 0.027, "arm": 0.0397, "kf": 3.16e-10, "km": 7.94e-12, "thrust2weight": 2.25,
         "inertia": (1.4e-5, 1.4e-5, 2.17e-5), "prop_radius": 2.31348e-2,
         "drag_xy": 9.1785e-7, "drag_z": 10.311e-7, "gravity": 9.8,
         "positions": ((0.028, -0.028), (-0.028, -0.028), (-0.028, 0.028), (0.028, 0.028)),
         "reaction": (-1, 1, -1, 1), "damping": 0.04}
#: case-side effects (SI; :mod:`.flightjobs`): mass, com, inertia, weak_rotor, thrust_scale,
#: wind; drag_scale (factor on the aviary's drag coefficients); torque, torque_hz, force,
#: force_hz (periodic loads)
EFFECTS = ("mass", "com", "inertia", "weak_rotor", "thrust_scale", "wind", "drag_scale",
           "torque", "torque_hz", "force", "force_hz")


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, sensor noise), speed factor of the path, duration (s,
    logged), case-side effects (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def gpd_available() -> bool:
    """gym-pybullet-drones and pybullet importable (checked without importing them)."""
    return importlib.util.find_spec("pybullet") is not None \
        and importlib.util.find_spec("gym_pybullet_drones") is not None


def hover_speed_of(mass: float = MODEL["mass"]) -> float:
    """Rotor speed (rad/s) at which four rotors carry ``mass`` (kg): sqrt(m g / 4 kf) RPM."""
    return float(np.sqrt(mass * MODEL["gravity"] / (4 * MODEL["kf"]))) * RPM


def max_speed() -> float:
    """The aviary's MAX_RPM in rad/s: sqrt(thrust2weight m g / 4 kf) RPM."""
    m = MODEL
    return float(np.sqrt(m["thrust2weight"] * m["mass"] * m["gravity"] / (4 * m["kf"]))) * RPM


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of cf2x.urdf (module doc): b = kf / RPM^2, d = km / RPM^2."""
    m = MODEL
    rotors = tuple(Rotor(str(i + 1), np.array([x, y, 0.0]), np.array([0.0, 0.0, 1.0]),
                         -float(r)) for i, ((x, y), r) in enumerate(zip(m["positions"],
                                                                        m["reaction"])))
    top = max_speed()
    src = "gym-pybullet-drones cf2x.urdf"
    params = VehicleParams(
        name="gpd-cf2x", mass=m["mass"], com=np.zeros(3), inertia=np.diag(m["inertia"]),
        rotors=rotors, thrust_factor=m["kf"] / RPM ** 2, drag_factor=m["km"] / RPM ** 2,
        max_speed=top, min_speed=0.0, rotor_radius=m["prop_radius"], rotor_inertia=0.0,
        gravity=m["gravity"],
        motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array([[0.0, top]] * 4),
                           "command = commanded RPM / MAX_RPM (no motor dynamics)"),
        description="gym-pybullet-drones' cf2x (Crazyflie 2.0, X) as quadsim sees it",
        sources={"mass": f"{src}: base_link mass (kg)",
                 "inertia": f"{src}: base_link ixx, iyy, izz (kg m^2)",
                 "rotors": f"{src}: prop0..3 link origins (m); spins from BaseAviary._physics",
                 "thrust_factor": f"{src}: kf 3.16e-10 N/RPM^2 (N s^2/rad^2)",
                 "drag_factor": f"{src}: km 7.94e-12 N m/RPM^2 (N m s^2/rad^2)",
                 "max_speed": f"{src}: thrust2weight 2.25 -> BaseAviary.MAX_RPM (rad/s)",
                 "min_speed": "BaseAviary clips the RPM at 0 (rad/s)",
                 "rotor_radius": f"{src}: prop_radius (m)",
                 "rotor_inertia": "the aviary has no motor or rotor inertia (kg m^2)",
                 "gravity": "BaseAviary.G (m/s^2)"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path(t: np.ndarray, seed: int, speed: float) -> tuple[np.ndarray, np.ndarray,
                                                          np.ndarray, np.ndarray]:
    """Setpoints of a wandering loop sized for a Crazyflie: position and velocity (T, 3)
    (m, m/s), yaw and yaw rate (T,) (rad, rad/s). x = 0.8 cos(w t + phi) + 0.15 sin(3.3 w t) +
    a sin(6.5 w t), y = 0.6 sin(w t + phi) + 0.2 sin(2.1 w t + phi) + a sin(7.5 w t + phi),
    z = 1.0 + 0.2 sin(1.3 w t) + 0.05 sin(4.1 w t), yaw = 0.6 sin(0.9 w t), a = 0.02 m /
    max(speed, 0.5)^2, w = 0.9 speed rad/s, phase phi from the seed."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.9 * speed
    weave = 0.02 / max(speed, 0.5) ** 2
    terms = ((0, 0.8, w, phi + np.pi / 2), (0, 0.15, 3.3 * w, 0.0), (0, weave, 6.5 * w, 0.0),
             (1, 0.6, w, phi), (1, 0.2, 2.1 * w, phi), (1, weave, 7.5 * w, phi),
             (2, 0.2, 1.3 * w, 0.0), (2, 0.05, 4.1 * w, 0.0))
    pos, vel = np.zeros((len(t), 3)), np.zeros((len(t), 3))
    pos[:, 2] = 1.0
    for column, amp, freq, phase in terms:
        arg = freq * t + phase
        pos[:, column] += amp * np.sin(arg)
        vel[:, column] += amp * freq * np.cos(arg)
    return pos, vel, 0.6 * np.sin(0.9 * w * t), 0.6 * 0.9 * w * np.cos(0.9 * w * t)


# ----------------------------------------------------------------------------- the job


def _flight_job(spec: FlightSpec) -> dict:
    """The flight's changes in the simulator's terms (SI)."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown gym-pybullet-drones effect(s) {sorted(unknown)}; valid: "
                         f"{EFFECTS}")
    mass, com, inertia = mass_properties(e, MODEL["mass"], MODEL["inertia"])
    return {"mass": mass, "com": com, "inertia": np.diag(inertia).copy(),
            "rotor_scale": rotor_scales(e), "drag_scale": float(e.get("drag_scale", 1.0)),
            **disturbances(e)}


def _aviary_class():
    """CtrlAviary with the case's handles in its own ``_physics`` and ``_drag`` (module doc);
    built on call so that importing this module needs no simulator."""
    import pybullet as p
    from gym_pybullet_drones.envs.CtrlAviary import CtrlAviary

    class CaseAviary(CtrlAviary):
        """``job``: :func:`_flight_job`'s dict."""

        def __init__(self, job: dict, **kwargs):
            self.job = job
            super().__init__(**kwargs)

        def _physics(self, rpm, nth_drone):
            job = self.job
            forces = np.array(rpm ** 2) * self.KF * job["rotor_scale"]
            torques = np.array(rpm ** 2) * self.KM * job["rotor_scale"]
            z_torque = -torques[0] + torques[1] - torques[2] + torques[3]
            at = [-float(job["com"][0]), -float(job["com"][1]), 0.0]
            body = self.DRONE_IDS[nth_drone]
            for i in range(4):
                p.applyExternalForce(body, i, forceObj=[0, 0, forces[i]], posObj=at,
                                     flags=p.LINK_FRAME, physicsClientId=self.CLIENT)
            t = self.step_counter * self.PYB_TIMESTEP
            torque = np.array([0.0, 0.0, z_torque]) \
                + job["torque"] * np.sin(2 * np.pi * job["torque_hz"] * t)
            p.applyExternalTorque(body, 4, torqueObj=torque.tolist(), flags=p.LINK_FRAME,
                                  physicsClientId=self.CLIENT)
            if job["force"]:
                push = job["force"] * np.sin(2 * np.pi * job["force_hz"] * t)
                p.applyExternalForce(body, 4, forceObj=[0, 0, push], posObj=[0, 0, 0],
                                     flags=p.LINK_FRAME, physicsClientId=self.CLIENT)

        def _drag(self, rpm, nth_drone):
            rot = np.array(p.getMatrixFromQuaternion(self.quat[nth_drone, :])).reshape(3, 3)
            factors = -self.job["drag_scale"] * self.DRAG_COEFF \
                * np.sum(np.array(2 * np.pi * rpm / 60))
            drag = rot.T @ (factors * (np.array(self.vel[nth_drone, :]) - self.job["wind"]))
            p.applyExternalForce(self.DRONE_IDS[nth_drone], 4, forceObj=drag, posObj=[0, 0, 0],
                                 flags=p.LINK_FRAME, physicsClientId=self.CLIENT)

    return CaseAviary


def _fly(args) -> dict:
    """One flight (module doc): true states at :data:`PHYSICS_HZ` after the lead-in."""
    spec, job = args
    import pybullet as p
    from gym_pybullet_drones.control.DSLPIDControl import DSLPIDControl
    from gym_pybullet_drones.utils.enums import DroneModel, Physics

    dt = 1.0 / PHYSICS_HZ
    every = PHYSICS_HZ // CONTROL_HZ
    lead, n = round(LEAD_IN * PHYSICS_HZ), round(spec.duration * PHYSICS_HZ)
    t = np.arange(lead + n + 1) * dt
    sp_pos, sp_vel, sp_yaw, sp_yaw_rate = path(t, spec.seed, spec.speed)
    with contextlib.redirect_stdout(io.StringIO()):       # the aviary prints its URDF values
        env = _aviary_class()(job, drone_model=DroneModel.CF2X, num_drones=1,
                              physics=Physics.PYB_GND_DRAG_DW, pyb_freq=PHYSICS_HZ,
                              ctrl_freq=PHYSICS_HZ, gui=False,
                              initial_xyzs=sp_pos[:1].copy(),
                              initial_rpys=np.array([[0.0, 0.0, sp_yaw[0]]]))
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            env.reset()
        body, client = env.DRONE_IDS[0], env.CLIENT
        p.changeDynamics(body, -1, mass=float(job["mass"]),
                         localInertiaDiagonal=[float(v) for v in job["inertia"]],
                         physicsClientId=client)
        p.resetBaseVelocity(body, sp_vel[0].tolist(), [0.0, 0.0, 0.0], physicsClientId=client)
        env._updateAndStoreKinematicInformation()
        ctrl = DSLPIDControl(drone_model=DroneModel.CF2X)
        states = np.empty((lead + n + 1, 13))
        rpms = np.zeros((lead + n + 1, 4))
        rpm = np.full(4, env.HOVER_RPM)

        def record(k):
            q = env.quat[0]                                           # x, y, z, w
            rot = np.array(p.getMatrixFromQuaternion(q)).reshape(3, 3)
            states[k] = np.concatenate([env.pos[0], env.vel[0], [q[3], q[0], q[1], q[2]],
                                        rot.T @ env.ang_v[0]])

        record(0)
        for k in range(lead + n):
            if k % every == 0:
                rpm, _, _ = ctrl.computeControl(
                    control_timestep=every * dt, cur_pos=env.pos[0], cur_quat=env.quat[0],
                    cur_vel=env.vel[0], cur_ang_vel=env.ang_v[0], target_pos=sp_pos[k],
                    target_rpy=np.array([0.0, 0.0, sp_yaw[k]]), target_vel=sp_vel[k],
                    target_rpy_rates=np.array([0.0, 0.0, sp_yaw_rate[k]]))
            env.step(np.reshape(rpm, (1, 4)))
            rpms[k + 1] = env.last_clipped_action[0]
            record(k + 1)
            if not np.all(np.isfinite(states[k + 1])) or states[k + 1, 6] ** 2 < 0.5 \
                    or states[k + 1, 2] < 0.05:
                raise ModelError(f"gym-pybullet-drones flight (seed {spec.seed}) lost control "
                                 f"at t = {t[k]:.2f} s")
        max_rpm = float(env.MAX_RPM)
    finally:
        env.close()
    return {"states": states[lead:], "speeds": rpms[lead:] * RPM,
            "commands": rpms[lead:] / max_rpm}


def gpd_flights(specs: list[FlightSpec], workers: int | None = 1
                ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec (``workers`` processes; default one: in this process) and return
    ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth sidecar
    (effects, the flight's parameters, seed, speed)."""
    if not gpd_available():
        raise ModelError("gym-pybullet-drones is not installed (pip install pybullet==3.2.7 "
                         "gymnasium transforms3d; pip install --no-deps "
                         "swarm-drone-gym==2.0.0.3)")
    jobs = [_flight_job(s) for s in specs]
    return fly_all(_fly, to_flight_log, specs, jobs, source="gym-pybullet-drones",
                   model="gpd-cf2x", rates=(PHYSICS_HZ, LOG_HZ), workers=workers)


def to_flight_log(raw: dict, spec: FlightSpec, com: np.ndarray) -> FlightLog:
    """The true states (CoM position and world velocity, w-first quaternion, body rate) at
    :data:`PHYSICS_HZ` and the rotor speed and command of each step -> a quadsim
    :class:`FlightLog` of the body origin with the sensor model of ``spec.sensors`` (seeded
    by ``spec.seed``)."""
    x = raw["states"]
    dt = 1.0 / PHYSICS_HZ
    acc = np.diff(x[:, 3:6], axis=0) / dt
    ang_acc = np.diff(x[:, 10:13], axis=0) / dt
    keep = np.arange(0, len(x) - 1, PHYSICS_HZ // LOG_HZ)
    states = SimStates(rate_hz=LOG_HZ, pos=x[keep, 0:3], vel=x[keep, 3:6], quat=x[keep, 6:10],
                       ang_vel=x[keep, 10:13], ang_acc=ang_acc[keep], acc=acc[keep],
                       rotor_speed=raw["speeds"][keep + 1], command=raw["commands"][keep + 1])
    return body_origin_log(states, com, spec.sensors, spec.seed, hover_speed=hover_speed_of(),
                           gravity=MODEL["gravity"])
