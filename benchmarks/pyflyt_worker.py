"""PyFlyt flights in a fresh interpreter (the part of :mod:`.pyflyt_source` that imports PyFlyt).

pybullet writes to the process's stdout from C ("pybullet build time ...", "argv[0]=") and
PyFlyt prints a cursor-control line and warns about any physics rate but 240 Hz; none of
that may reach quadsim's user, so the flights are flown in a child process
(:func:`benchmarks.pyflyt_source.pyflyt_flights` starts ``python .../pyflyt_worker.py
JOB.npz OUT.npz`` in a temporary folder with its output captured); this module imports
nothing of quadsim.

What runs here is PyFlyt's own simulation (``PyFlyt.core.Aviary``, tested with 0.29.0):
pybullet's rigid-body step at ``physics_hz``, PyFlyt's QuadX (``cf2x`` model: its URDF and
yaml, its first-order motors with their multiplicative noise, its quadratic body drag and
angular-rate damping ``drag_coef_pqr``) and its PID cascade in mode 7 (setpoint x, y, yaw, z)
at ``control_hz``. Each flight is one Aviary with one drone, seeded by its own generator.
The loop is PyFlyt's ``Aviary.step`` inner loop written out per physics step (control,
physics, disturbance, ``stepSimulation``, state update) so that every physics step is logged
and the disturbances are added between PyFlyt's forces and the step.

An effect is a change of PyFlyt's own vehicle files or parameters, never a quadsim hook:
``mass``, ``com`` (m, the URDF base inertial origin), ``inertia`` (kg m^2, principal
moments) go into a copy of ``cf2x.urdf``; ``tau`` (s), ``drag_coef_pqr`` (N m s^2/rad^2)
into a copy of ``cf2x.yaml``; per-motor thrust/torque scale into ``drone.motors`` (its
coefficient arrays); wind through PyFlyt's wind-field hook (``register_wind_field_function``,
acting on its body drag). Outside its library, through pybullet itself: a periodic body
torque ``torque sin(2 pi torque_hz t)`` (``applyExternalTorque``, world frame after rotating
the body vector) and a thrust change with airspeed ``+4 lift |v_h|^2`` along body z on the
geometric centre (``applyExternalForce``, v_h the in-plane body-frame airspeed).

Job (``JOB.npz``), F flights: ``setpoints`` (F, C, 4) mode-7 setpoints ``[x y yaw z]`` (m,
rad) per control step; per flight ``mass`` (F,) kg, ``com`` (F, 3) m, ``inertia`` (F, 3)
kg m^2, ``tau`` (F,) s, ``drag_coef_pqr`` (F,), ``motor_scale`` (F, 4), ``wind`` (F, 3)
m/s, ``lift`` (F,) N/(m/s)^2, ``torque`` (F, 3) N m body, ``torque_hz`` (F,) Hz, ``start``
(F, 4) x y z yaw, ``throttle0`` (F,) initial throttle, ``seed`` (F,); ``physics_hz``,
``control_hz``.

Output (``OUT.npz``), per physics step k (state at t_k; the motor state, command and
accelerations that act from t_k to t_k+1): ``pos`` (CoM, world) ``vel`` ``quat`` (xyzw,
body -> world) ``ang_vel`` (world) ``throttle`` (PyFlyt's motor state, 0..1 of max rpm)
``pwm`` (motor command) ``acc`` (world, ``(v_k+1 - v_k) / dt``) ``ang_acc`` (world).
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile

OUTPUTS = ("pos", "vel", "quat", "ang_vel", "throttle", "pwm", "acc", "ang_acc")


def _write_model(root: str, name: str, flight: dict) -> str:
    """A copy of PyFlyt's ``cf2x`` model folder under ``root`` with this flight's mass
    properties (URDF) and motor/damping parameters (yaml); returns the model_dir."""
    import xml.etree.ElementTree as ET

    import PyFlyt
    import yaml

    src = os.path.join(os.path.dirname(PyFlyt.__file__), "models", "vehicles", "cf2x")
    model_dir = os.path.join(root, name)
    dst = os.path.join(model_dir, "cf2x")
    shutil.copytree(src, dst)
    tree = ET.parse(os.path.join(dst, "cf2x.urdf"))
    base = tree.getroot().find("./link[@name='base_link']/inertial")
    base.find("origin").set("xyz", " ".join(repr(float(v)) for v in flight["com"]))
    base.find("mass").set("value", repr(float(flight["mass"])))
    inertia = base.find("inertia")
    for axis, value in zip(("ixx", "iyy", "izz"), flight["inertia"]):
        inertia.set(axis, repr(float(value)))
    tree.write(os.path.join(dst, "cf2x.urdf"))
    with open(os.path.join(dst, "cf2x.yaml")) as handle:
        params = yaml.safe_load(handle)
    params["motor_params"]["tau"] = float(flight["tau"])
    params["drag_params"]["drag_coef_pqr"] = float(flight["drag_coef_pqr"])
    with open(os.path.join(dst, "cf2x.yaml"), "w") as handle:
        yaml.safe_dump(params, handle)
    return model_dir


def fly_one(flight: dict, physics_hz: int, control_hz: int, workdir: str, name: str) -> dict:
    import numpy as np
    from PyFlyt.core import Aviary

    model_dir = _write_model(workdir, name, flight)
    start = np.asarray(flight["start"], dtype=float)
    env = Aviary(start_pos=start[None, :3], start_orn=np.array([[0.0, 0.0, start[3]]]),
                 render=False, drone_type="quadx", physics_hz=physics_hz,
                 drone_options={"model_dir": model_dir, "drone_model": "cf2x",
                                "control_hz": control_hz},
                 np_random=np.random.default_rng([int(flight["seed"]), 11]))
    wind = np.asarray(flight["wind"], dtype=float)
    if np.any(wind != 0.0):
        env.register_wind_field_function(
            lambda time, position: np.tile(wind, (np.asarray(position).shape[0], 1)))
    drone = env.drones[0]
    scale = np.asarray(flight["motor_scale"], dtype=float)
    drone.motors.thrust_coef = drone.motors.thrust_coef * scale[:, None]
    drone.motors.torque_coef = drone.motors.torque_coef * scale[:, None]
    drone.set_mode(7)
    drone.motors.throttle[:] = float(flight["throttle0"])
    setpoints = np.asarray(flight["setpoints"], dtype=float)
    ratio = physics_hz // control_hz
    steps = setpoints.shape[0] * ratio
    dt = 1.0 / physics_hz
    lift, torque = float(flight["lift"]), np.asarray(flight["torque"], dtype=float)
    torque_hz = float(flight["torque_hz"])
    out = {k: np.zeros((steps + 1, 4 if k in ("quat", "throttle", "pwm") else 3))
           for k in OUTPUTS}

    def record(k: int) -> None:
        pos, quat = env.getBasePositionAndOrientation(drone.Id)
        vel, ang_vel = env.getBaseVelocity(drone.Id)
        out["pos"][k], out["quat"][k] = pos, quat
        out["vel"][k], out["ang_vel"][k] = vel, ang_vel

    record(0)
    for k in range(steps):
        if k % ratio == 0:
            drone.setpoint = setpoints[k // ratio].copy()
        drone.update_control(env.physics_steps)
        drone.update_physics()
        out["throttle"][k], out["pwm"][k] = drone.motors.throttle, drone.pwm
        if lift or np.any(torque != 0.0):
            _, quat = env.getBasePositionAndOrientation(drone.Id)
            rot = np.array(env.getMatrixFromQuaternion(quat)).reshape(3, 3)   # body -> world
            if lift:
                air = rot.T @ (np.asarray(env.getBaseVelocity(drone.Id)[0]) - wind)
                env.applyExternalForce(drone.Id, 4, [0.0, 0.0, 4.0 * lift * (air[0] ** 2
                                                                            + air[1] ** 2)],
                                       [0.0, 0.0, 0.0], env.LINK_FRAME)
            if np.any(torque != 0.0):
                body = torque * np.sin(2.0 * np.pi * torque_hz * env.elapsed_time)
                env.applyExternalTorque(drone.Id, -1, rot @ body, env.WORLD_FRAME)
        env.stepSimulation()
        drone.update_state()
        env.physics_steps += 1
        env.elapsed_time = env.physics_steps / physics_hz
        record(k + 1)
    env.disconnect()
    out["acc"][:-1] = np.diff(out["vel"], axis=0) / dt
    out["ang_acc"][:-1] = np.diff(out["ang_vel"], axis=0) / dt
    return {k: v[:-1] for k, v in out.items()}


def run(job_path: str, out_path: str) -> None:
    import warnings

    import numpy as np

    warnings.simplefilter("ignore")
    job = dict(np.load(job_path))
    physics_hz, control_hz = int(job["physics_hz"]), int(job["control_hz"])
    keys = ("setpoints", "mass", "com", "inertia", "tau", "drag_coef_pqr", "motor_scale",
            "wind", "lift", "torque", "torque_hz", "start", "throttle0", "seed")
    results = {k: [] for k in OUTPUTS}
    with tempfile.TemporaryDirectory(prefix="pyflyt-models-") as workdir:
        for f in range(job["setpoints"].shape[0]):
            flight = {k: job[k][f] for k in keys}
            one = fly_one(flight, physics_hz, control_hz, workdir, f"flight{f}")
            for name in OUTPUTS:
                results[name].append(one[name])
    tmp = out_path + ".tmp.npz"
    np.savez(tmp, **{k: np.stack(v) for k, v in results.items()})
    os.replace(tmp, out_path)


if __name__ == "__main__":
    run(sys.argv[1], sys.argv[2])
