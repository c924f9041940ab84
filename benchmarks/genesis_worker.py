"""Genesis flights in a child process (the part of :mod:`.genesis_source` that imports
Genesis): ``PYTHON genesis_worker.py JOB.npz OUT.npz``, run by the interpreter that has
Genesis (``QUADSIM_GENESIS_PYTHON``; Genesis needs torch, which quadsim's own environment
need not have). Genesis prints its banner and compile progress; the caller captures them.

What runs here is Genesis' own rigid-body simulation (``genesis.morphs.Drone``, tested with
genesis-world 1.4.5 on its CPU backend in double precision): the vehicle file's base link,
its propeller links and Genesis' own propeller model (thrust ``KF rpm^2`` and torque
``KM rpm^2`` on each propeller link, ``set_propellers_rpm``), stepped by its rigid solver.
One scene per process, built once; each flight resets it (pose, velocity) and sets its own
mass, CoM and inertia through Genesis' setters (``set_links_mass``, ``set_links_COM``,
``set_links_inertia``: the base link, ``align=False`` so that its inertia frame is the
link's). quadsim adds, each physics step: the DC motors (RK4 over the step at the held duty,
the step's mean speed sent as rpm; a weak rotor's rpm x sqrt(scale): its thrust and torque x
scale), the file's rotor drag with the wind, and the case's added torque and force, as one
external wrench on the base link at its CoM (``apply_external_wrench``, body axes).

Job (``JOB.npz``), F flights: per flight ``mass`` (F,) kg, ``com`` (F, 3) m, ``inertia``
(F, 3, 3) kg m^2, ``rotor_scale`` (F, 4), ``motor_inertia`` (F,) kg m^2, ``wind`` (F, 3) m/s,
``rate_damping`` (F, 3) N m s/rad, ``torque`` (F, 3) N m, ``torque_hz`` (F,), ``force`` (F,)
N, ``force_hz`` (F,), ``seed`` (F,), ``speed`` (F,), ``steps`` (F,) physics steps after the
lead-in; ``lead`` steps, ``physics_hz``, ``control_hz``.

Output (``OUT.npz``): per flight ``states_K`` (N + 1, 13) at the physics rate: the base link
origin's position and world velocity, quaternion (w-first, body -> world), body rate;
``speeds_K`` (N + 1, 4) rad/s (each step's mean motor speed, the speed that made its thrust;
row 0 the start); ``commands_K`` (N + 1, 4) duty cycles.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # quadsim, pure modules only

from benchmarks.genesis_source import (
    MODEL,
    MOTOR,
    URDF,
    duty_for,
    hover_speed_of,
    rotor_drag_force,
    vehicle_params,
)
from benchmarks.geometric import Geometric
from benchmarks.qcsim_source import path
from quadsim.core.frames import quat_to_rotmat

RPM = 60.0 / (2.0 * np.pi)        # rad/s -> rev/min


def _scene(dt: float):
    import genesis as gs

    gs.init(backend=gs.cpu, precision="64", logging_level="warning")
    gravity = (0.0, 0.0, -MODEL["gravity"])
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt, gravity=gravity),
                     show_viewer=False)
    drone = scene.add_entity(gs.morphs.Drone(file=URDF, model="RACE", pos=(0.0, 0.0, 1.5),
                                             align=False))
    scene.build()
    return gs, scene, drone


def _fly(gs, scene, drone, job: dict, k: int, lead: int, physics_hz: int, control_hz: int
         ) -> dict:
    dt = 1.0 / physics_hz
    every = physics_hz // control_hz
    n = int(job["steps"][k])
    t = np.arange(lead + n + 1) * dt
    sp_pos, sp_vel, sp_acc, sp_yaw, sp_rate = path(t, int(job["seed"][k]), float(job["speed"][k]))
    base = drone.base_link
    drone.set_links_mass(np.array([job["mass"][k]]), links_idx_local=[0])
    drone.set_links_COM(np.asarray(job["com"][k], float)[None], links_idx_local=[0])
    drone.set_links_inertia(np.asarray(job["inertia"][k], float)[None], links_idx_local=[0])
    drone.set_pos(sp_pos[0], zero_velocity=True)
    drone.set_quat(np.array([1.0, 0.0, 0.0, 0.0]), zero_velocity=True)
    drone.zero_all_dofs_velocity()
    scale = np.asarray(job["rotor_scale"][k], float)
    root, k_drag = np.sqrt(scale), MODEL["d"] * scale
    j_motor = float(job["motor_inertia"][k])
    wind = np.asarray(job["wind"][k], float)
    ctrl = Geometric(every * dt, vehicle_params(), duty_for)
    w = np.full(4, hover_speed_of(float(job["mass"][k]))) / root
    states = np.empty((lead + n + 1, 13))
    speeds = np.empty((lead + n + 1, 4))
    commands = np.empty((lead + n + 1, 4))

    def read():
        pos = drone.get_pos().cpu().numpy().astype(float)
        vel = drone.get_vel().cpu().numpy().astype(float)
        quat = drone.get_quat().cpu().numpy().astype(float)
        rot = quat_to_rotmat(quat)
        rate = rot.T @ drone.get_ang().cpu().numpy().astype(float)
        return pos, vel, quat, rate, rot

    pos, vel, quat, rate, rot = read()
    states[0], speeds[0] = np.concatenate([pos, vel, quat, rate]), w
    duty = duty_for(w)
    commands[0] = duty
    for i in range(lead + n):
        if i % every == 0:
            duty = ctrl.step(pos, vel, quat, rate, sp_pos[i], sp_vel[i], sp_acc[i], sp_yaw[i],
                             sp_rate[i])
        # the motors over the step (RK4 at the held duty): the step's mean speed acts
        acc = MOTOR.acceleration
        a1 = acc(w, duty, k_drag, j_motor)
        a2 = acc(w + dt / 2 * a1, duty, k_drag, j_motor)
        a3 = acc(w + dt / 2 * a2, duty, k_drag, j_motor)
        a4 = acc(w + dt * a3, duty, k_drag, j_motor)
        new = w + dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        mean = 0.5 * (w + new)
        drone.set_propellers_rpm(mean * root * RPM)
        air = rot.T @ (vel - wind)
        force = rotor_drag_force(air, mean)
        force[2] += job["force"][k] * np.sin(2 * np.pi * job["force_hz"][k] * t[i])
        torque = -job["rate_damping"][k] * rate \
            + job["torque"][k] * np.sin(2 * np.pi * job["torque_hz"][k] * t[i])
        base.apply_external_wrench(force=force, torque=torque, ref=gs.link_ref_frame.link_COM,
                                   local=True)
        scene.step()
        w = new
        pos, vel, quat, rate, rot = read()
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(rate))) or quat[0] ** 2 < 0.5:
            raise RuntimeError(f"flight {k} (seed {int(job['seed'][k])}) lost control at "
                               f"t = {t[i]:.2f} s")
        states[i + 1] = np.concatenate([pos, vel, quat, rate])
        speeds[i + 1] = mean
        commands[i + 1] = duty
    return {f"states_{k}": states, f"speeds_{k}": speeds, f"commands_{k}": commands}


def main(job_path: str, out_path: str) -> int:
    job = dict(np.load(job_path))
    physics_hz, control_hz = int(job["physics_hz"]), int(job["control_hz"])
    gs, scene, drone = _scene(1.0 / physics_hz)
    out = {}
    for k in range(len(job["mass"])):
        out.update(_fly(gs, scene, drone, job, k, int(job["lead"]), physics_hz, control_hz))
    np.savez(out_path, **out)
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
