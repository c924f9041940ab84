"""Crazyflow flights in a fresh interpreter (the part of :mod:`.crazyflow_source` that imports JAX).

Crazyflow needs SciPy's array-API mode (``SCIPY_ARRAY_API=1``), which must be set before
SciPy is first imported and changes SciPy for the whole process; quadsim's own code runs
without it. So the flights are flown in a child process
(:func:`benchmarks.crazyflow_source.fly_batch` starts ``python .../crazyflow_worker.py JOB.npz
OUT.npz`` in a temporary folder); this module imports nothing of quadsim.

What runs here is Crazyflow's own simulation (``crazyflow.Sim``, tested with 0.4.0): its
first-principles dynamics (:func:`crazyflow.dynamics.first_principles.dynamics`: quadratic
thrust and torque curves in RPM, nonlinear first-order rotor dynamics, linear body drag,
propeller gyroscopic and reaction torques), its RK4 integrator at ``freq`` Hz, its Mellinger
state controller (state 100 Hz, attitude and force/torque 500 Hz, with its own gains and its
own -- deliberately wrong -- controller mass) and its command clipping. Each flight is one
world (``n_worlds=1``, float64), the whole flight one ``jax.lax.scan`` over the setpoints;
the parameters of the flight replace ``sim.data.params`` (so one compiled scan serves every
flight; a flight never shares a batch, so its bytes never depend on the others).

Job (``JOB.npz``): ``cmd`` (F, T, 16) Mellinger state setpoints
``[x y z vx vy vz ax ay az qx qy qz qw wx wy wz]`` (m, m/s, m/s^2, xyzw, rad/s); per flight
``mass`` (F,) kg, ``J`` (F, 3, 3) kg m^2, ``rpm2thrust``/``rpm2torque`` (F, 4, 3) (N and N m
per RPM powers 0, 1, 2), ``rotor_dyn_coef`` (F, 4, 4), ``mixing_matrix`` (F, 3, 4),
``drag_matrix`` (F, 3, 3) N/(m/s), ``wind`` (F, 3) m/s world, ``lift`` (F,) N/(m/s)^2,
``flap`` (F,) N m/(RPM m/s), ``torque`` (F, 3) N m and ``torque_hz`` (F,) Hz; ``start`` (F, 13)
initial pos, vel, quat (xyzw), ang_vel; ``freq`` Hz, ``drone`` name.

Disturbances, added through Crazyflow's own disturbance inputs (``states.force``, world
frame, and ``states.torque``, world frame, rotated to the body by its dynamics):

* wind: the drag of Crazyflow's own drag matrix on the air velocity minus the vehicle's:
  ``F = R C R^T (v - w) - R C R^T v = -R C R^T w`` (C negative definite), so the total drag
  acts on the airspeed ``v - w``;
* translational lift (outside quadsim's library): ``+lift |v_h|^2`` per rotor along body z,
  v_h the in-plane (body x-y) airspeed;
* blade flapping moment (outside): ``tau = -flap (sum_i Omega_i) (e_z x v_h)`` (body, Omega
  in RPM);
* periodic torque (outside): ``torque * sin(2 pi torque_hz t)`` in the body frame.

Output (``OUT.npz``), per sample k (state at t_k; the command and accelerations that act from
t_k): ``pos vel quat(xyzw) ang_vel rotor_vel(RPM) rotor_cmd(RPM) acc ang_acc`` (F, T, ...).
"""

from __future__ import annotations

import os
import sys

os.environ["SCIPY_ARRAY_API"] = "1"
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false "
                                   "intra_op_parallelism_threads=1")

OUTPUTS = ("pos", "vel", "quat", "ang_vel", "rotor_vel", "rotor_cmd", "acc", "ang_acc")


def _build(drone: str, freq: int):
    import logging
    import warnings

    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    import crazyflow  # noqa: F401  (sets the array-API flag before SciPy)
    import jax
    import jax.numpy as jnp
    from crazyflow import Sim
    from crazyflow.sim import functional as F
    from crazyflow.sim.dynamics import first_principles_dynamics
    from jax.scipy.spatial.transform import Rotation

    jax.config.update("jax_enable_x64", True)
    sim = Sim(n_worlds=1, n_drones=1, drone=drone, dynamics="first_principles", control="state",
              integrator="rk4", freq=freq, state_freq=100, attitude_freq=freq,
              force_torque_freq=freq)
    stages = list(sim.step_pipeline.items())
    cut = [name for name, _ in stages].index("integration")
    before = tuple(fn for _, fn in stages[:cut])
    after = tuple(fn for _, fn in stages[cut:])
    dt = 1.0 / freq

    def disturbance(data, job):
        states = data.states
        rot = Rotation.from_quat(states.quat)
        mat = rot.as_matrix()                                      # body -> world
        drag = data.params.drag_matrix
        force = -(mat @ (drag @ (jnp.swapaxes(mat, -1, -2) @ job["wind"][..., None])))[..., 0]
        air_body = rot.apply(states.vel - job["wind"], inverse=True)
        vh = air_body.at[..., 2].set(0.0)
        lift = job["lift"] * 4.0 * jnp.sum(vh ** 2, axis=-1, keepdims=True)
        force = force + rot.apply(jnp.concatenate([jnp.zeros_like(lift), jnp.zeros_like(lift),
                                                   lift], axis=-1))
        spin = jnp.sum(states.rotor_vel, axis=-1, keepdims=True)
        ez_cross_v = jnp.stack([-vh[..., 1], vh[..., 0], jnp.zeros_like(vh[..., 0])], axis=-1)
        t = data.core.steps[..., None] * dt
        torque_body = (-job["flap"] * spin * ez_cross_v
                       + job["torque"] * jnp.sin(2 * jnp.pi * job["torque_hz"] * t))
        return states.replace(force=force, torque=rot.apply(torque_body))

    def fly(data, job, cmds):
        params = data.params.replace(
            mass=job["mass"], J=job["J"], J_inv=jnp.linalg.inv(job["J"]),
            rpm2thrust=job["rpm2thrust"], rpm2torque=job["rpm2torque"],
            rotor_dyn_coef=job["rotor_dyn_coef"], mixing_matrix=job["mixing_matrix"],
            drag_matrix=job["drag_matrix"])
        start = job["start"]
        states = data.states.replace(pos=start[..., 0:3], vel=start[..., 3:6],
                                     quat=start[..., 6:10], ang_vel=start[..., 10:13],
                                     rotor_vel=job["rotor0"])
        data = data.replace(params=params, states=states)

        def body(data, cmd):
            data = F.state_control(data, cmd)
            data = data.replace(states=disturbance(data, job))
            for fn in before:
                data = fn(data)
            deriv = first_principles_dynamics(data)
            s = data.states
            out = (s.pos, s.vel, s.quat, s.ang_vel, s.rotor_vel, data.controls.rotor_vel,
                   deriv.acc, deriv.ang_acc)
            for fn in after:
                data = fn(data)
            return data, out

        return jax.lax.scan(body, data, cmds)[1]

    return sim, jax.jit(fly), jnp


def run(job_path: str, out_path: str) -> None:
    import numpy as np

    job = dict(np.load(job_path))
    sim, fly, jnp = _build(str(job["drone"]), int(job["freq"]))
    keys = ("mass", "J", "rpm2thrust", "rpm2torque", "rotor_dyn_coef", "mixing_matrix",
            "drag_matrix", "wind", "lift", "flap", "torque", "torque_hz", "start", "rotor0")
    results = {k: [] for k in OUTPUTS}
    for f in range(job["cmd"].shape[0]):
        sim.reset()
        one = {k: jnp.asarray(np.asarray(job[k][f], dtype=float)[None, None]) for k in keys}
        one["mass"] = one["mass"][..., None]
        one["lift"], one["flap"], one["torque_hz"] = (one[k][..., None]
                                                      for k in ("lift", "flap", "torque_hz"))
        cmds = jnp.asarray(job["cmd"][f][:, None, None, :])
        out = fly(sim.data, one, cmds)
        for name, value in zip(OUTPUTS, out):
            results[name].append(np.asarray(value)[:, 0, 0])
    tmp = out_path + ".tmp.npz"
    np.savez(tmp, **{k: np.stack(v) for k, v in results.items()})
    os.replace(tmp, out_path)


if __name__ == "__main__":
    run(sys.argv[1], sys.argv[2])
