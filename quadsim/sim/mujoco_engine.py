"""MuJoCo runner: the MJCF of :mod:`quadsim.sim.mjcf`, stepped with RK4, one or many at once.

All simulations of a call are stepped together by :class:`mujoco.batch.Batch` (one thread per
CPU; bit-identical to a plain loop). Inputs are rotor speed commands held over each control
period; the runner turns them into actuator controls ``ctrl = Omega^2`` (rad^2/s^2). The
model is compiled without a floor (the analytic reference has no ground) and with MuJoCo's
fluid drag off. Use :func:`quadsim.sim.engines.simulate` as the front door.

State convention (checked against mujoco 4.0 by ``tests/test_mujoco_engine.py``): the free
joint's ``qpos = [x, y, z, qw, qx, qy, qz]`` is the body-origin position (world) and the
body-to-world quaternion; ``qvel[0:3]`` is the body-origin velocity in the world frame and
``qvel[3:6]`` the angular velocity in the body frame, i.e. the shared :mod:`quadsim.vehicle.state`
convention, so no conversion is needed.

Effects (generic, through the hooks of :mod:`quadsim.effects.base`)
------------------------------------------------------------------
Without effects a control period is one ``Batch.step(nstep=n)`` call. With effects the runner
steps one timestep at a time and, once per step for the whole batch,

* integrates the rotor-speed dynamics (if an effect defines them) over the step with RK4 on
  the held command, and drives the actuators with the step's mean ``Omega^2`` (Simpson), so
  that thrust is not half a step late;
* evaluates ``air_velocity`` and ``loads`` at the step's midpoint (time, rotor speed, and the
  body state predicted from the last accelerations);
* integrates the internal states of effects that have them (e.g. a cable payload) over the
  step with two RK4 half steps along the body state predicted from the last accelerations,
  and evaluates ``loads`` with the mid-step states;
* applies the thrust scale through the controls (``ctrl = scale * mean Omega^2``: the
  actuators are linear in ctrl, so thrust and drag torque scale exactly, in the body frame, at
  every RK4 stage), and everything else the effects add (thrust offsets, world force, body
  torque) as the free joint's generalised force ``qfrc_applied`` (:func:`joint_load`: world
  force, body-frame torque about the body origin).

Per-simulation parameter sets (effects such as mass_offset change the vehicle) compile one
model per distinct set and run them through ``Batch.set_models``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

import mujoco
import numpy as np
from mujoco import batch as mjbatch

from ..core.errors import InputError, ModelError, SimulationError
from ..core.frames import quat_derivative, quat_normalize, quat_to_rotmat
from ..vehicle.params import VehicleParams, inertia_problems
from .analytic import STATE_BOUND, BatchEffects, body_arrays, extra_wrench
from .mjcf import BODY_NAME, vehicle_xml

__all__ = ["compile_model", "run_mujoco", "default_timestep", "DEFAULT_MAX_TIMESTEP"]

#: Largest MuJoCo timestep (s) used by default; the timestep always divides the control period.
DEFAULT_MAX_TIMESTEP = 1e-3


#: Arena of each MjData (bytes). MuJoCo's default for this model is 13.6 MB, of which a step
#: uses 1.2 kB (no floor, no contacts): 1 MB keeps big batches in memory (1024 sims: 1 GB).
ARENA_BYTES = 1 << 20


def default_timestep(control_period: float, max_timestep: float = DEFAULT_MAX_TIMESTEP) -> float:
    """The largest timestep <= ``max_timestep`` that divides ``control_period`` exactly."""
    substeps = max(1, int(np.ceil(control_period / max_timestep - 1e-9)))
    return control_period / substeps


def compile_model(params: VehicleParams, timestep: float) -> mujoco.MjModel:
    """Compile the vehicle for simulation (RK4, no floor, controls not clamped).

    Raises :class:`ModelError` naming the value MuJoCo refuses (e.g. an inertia that breaks
    the triangle inequality, as the report's published one does)."""
    where = params.path or params.name
    problems = inertia_problems(params.inertia)
    if problems:
        raise ModelError(f"MuJoCo refuses parameter set {where}: body.inertia "
                         + "; ".join(problems))
    try:
        spec = mujoco.MjSpec.from_string(
            vehicle_xml(params, timestep=timestep, integrator="RK4", floor=False))
        spec.memory = ARENA_BYTES
        model = spec.compile()
    except ValueError as exc:
        raise ModelError(f"MuJoCo refuses parameter set {where}: {' '.join(str(exc).split())}"
                         ) from None
    # Commands are clipped to the rotor range before they get here; effects may scale thrust
    # beyond it (ctrl = scale * Omega^2), which MuJoCo must not clamp.
    model.actuator_ctrllimited[:] = 0
    return model


#: Compiled models of recent calls, keyed by (MJCF text, timestep): compiling costs ~2-3 ms,
#: as much as thousands of steps; the engine never changes a model after compile_model.
_MODEL_CACHE: dict[tuple[str, float], mujoco.MjModel] = {}
_MODEL_CACHE_SIZE = 32
_MODEL_LOCK = threading.Lock()


def _cached_model(params: VehicleParams, timestep: float) -> mujoco.MjModel:
    key = (vehicle_xml(params, timestep=timestep, integrator="RK4", floor=False), timestep)
    with _MODEL_LOCK:
        model = _MODEL_CACHE.pop(key, None)
    if model is None:
        model = compile_model(params, timestep)
    with _MODEL_LOCK:
        _MODEL_CACHE[key] = model              # most recent last
        while len(_MODEL_CACHE) > _MODEL_CACHE_SIZE:
            del _MODEL_CACHE[next(iter(_MODEL_CACHE))]
    return model


def compiled_models(params: Sequence[VehicleParams], timestep: float) -> list[mujoco.MjModel]:
    """One compiled model per simulation (shared between simulations with the same set, and
    with earlier calls for the same vehicle and timestep)."""
    models: dict[int, mujoco.MjModel] = {}
    for p in params:
        if id(p) not in models:
            models[id(p)] = _cached_model(p, timestep)
    return [models[id(p)] for p in params]


#: Fraction of the available memory a batch may plan to use before it is refused.
MEMORY_FRACTION = 0.5


def check_memory(model: mujoco.MjModel, batch: int, periods: int, rotors: int) -> int:
    """Estimate the bytes a batch needs (one MjData per simulation plus the samples) and
    raise :class:`InputError` before allocating if it exceeds ``MEMORY_FRACTION`` of the
    available memory. Returns the estimate (bytes)."""
    import os

    per_sim = model.narena + model.nbuffer + 8 * (periods + 1) * (2 * 13 + 4 * rotors)
    need = batch * per_sim
    try:
        free = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):      # not available on this platform
        return need
    if need > MEMORY_FRACTION * free:
        raise InputError(f"batch of {batch} simulations needs about {need / 1e9:.3g} GB "
                         f"({per_sim / 1e6:.3g} MB each), more than {MEMORY_FRACTION:g} of the "
                         f"{free / 1e9:.3g} GB available: split the batch")
    return need


def _make_batch(params: Sequence[VehicleParams], compiled: Sequence[mujoco.MjModel],
                nthread: int) -> tuple[mjbatch.Batch, int]:
    models = {id(p): m for p, m in zip(params, compiled)}
    first = models[id(params[0])]
    threads = 1 if len(params) == 1 else nthread
    batch = mjbatch.Batch(first, nsim=len(params), nthread=threads)
    if len(models) > 1:
        batch.set_models([models[id(p)] for p in params])
    return batch, mujoco.mj_name2id(first, mujoco.mjtObj.mjOBJ_BODY, BODY_NAME)


def _rotor_step(effects: BatchEffects, t: float, dt: float, command: np.ndarray,
                omega: np.ndarray):
    """Rotor speeds at mid-step and end of step (two RK4 half steps), the step's mean
    Omega^2 (Simpson) and the mid-step rotor acceleration."""
    batch = command.shape[0]
    rate = lambda tt, w: effects.rotor_speed_rate(np.full(batch, tt), command, w)  # noqa: E731
    mid = _rk4(rate, t, omega, dt / 2)
    end = _rk4(rate, t + dt / 2, mid, dt / 2)
    mean_sq = (omega**2 + 4 * mid**2 + end**2) / 6
    return mid, end, mean_sq, rate(t + dt / 2, mid)


def _rk4(rate, t0: float, y0: np.ndarray, h: float) -> np.ndarray:
    """One classic Runge–Kutta step of ``dy/dt = rate(t, y)`` over ``h`` (s)."""
    k1 = rate(t0, y0)
    k2 = rate(t0 + h / 2, y0 + h / 2 * k1)
    k3 = rate(t0 + h / 2, y0 + h / 2 * k2)
    k4 = rate(t0 + h, y0 + h * k3)
    return y0 + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _midpoint_state(qpos, qvel, qacc, dt, h=None):
    """Body state half a step (or ``h``) ahead, predicted from the last accelerations."""
    h = dt / 2 if h is None else h
    position = qpos[:, 0:3] + qvel[:, 0:3] * h + 0.5 * qacc[:, 0:3] * h * h
    velocity = qvel[:, 0:3] + qacc[:, 0:3] * h
    body_rate = qvel[:, 3:6] + qacc[:, 3:6] * h
    quat = quat_normalize(qpos[:, 3:7]
                          + quat_derivative(qpos[:, 3:7], qvel[:, 3:6] + qacc[:, 3:6] * h / 2) * h)
    return position, velocity, quat, body_rate


def _effect_state_step(effects, qpos, qvel, qacc, t, dt, mid, accel, state):
    """Internal effect states at mid-step and end of step: two RK4 half steps along the body
    state predicted from the last accelerations."""
    times = np.full(len(state), 0.0)

    def rate(h, s):
        vehicle = _midpoint_state(qpos, qvel, qacc, dt, h)
        return effects.state_rate(times + t + h, *vehicle, mid, accel, s)

    half = _rk4(rate, 0.0, state, dt / 2)
    return half, _rk4(rate, dt / 2, half, dt / 2)


def joint_load(rot: np.ndarray, force_body: np.ndarray, torque_body: np.ndarray,
               force_world: np.ndarray, com: np.ndarray) -> np.ndarray:
    """(B, 6) generalised force of the vehicle's free joint for an effect wrench: body-frame
    force and torque about the CoM plus a world-frame force at the CoM, with ``rot`` (B, 3, 3)
    body to world and ``com`` (B, 3) the CoM in the body frame. MuJoCo's free joint takes a
    world force on its translational DOFs and a body-frame torque about the body origin on its
    rotational DOFs (its angular velocity is body-frame), so

        q_f = [F, tau_body + com x R^T F],   F = R f_body + f_world.

    The same load through ``xfrc_applied`` would cost MuJoCo a Jacobian product at every RK4
    stage (about 1 us of a 10 us step); here it is held over the step in the body frame (the
    xfrc form holds the world torque), both zero-order holds of the mid-step load."""
    force = np.einsum("bij,bj->bi", rot, force_body) + force_world
    local = force_body + np.einsum("bji,bj->bi", rot, force_world)
    out = np.empty((len(rot), 6))
    out[:, 0:3] = force
    out[:, 3:6] = torque_body + np.cross(com, local)
    return out


def _effect_step(batch, bound, body_id, body, effects, t, dt, command, omega, state=None):
    """One timestep with effects; returns the rotor speeds (and the internal effect states)
    at the end of the step."""
    qpos, qvel, qacc = bound["qpos"], bound["qvel"], bound["qacc"]
    dof = bound["dof"]
    if effects.rotor_dynamics:
        mid, end, mean_sq, accel = _rotor_step(effects, t, dt, command, omega)
    else:
        mid, end, mean_sq, accel = command, command, command**2, np.zeros_like(command)
    scale = np.ones_like(command)
    state_mid = state_end = state
    if effects.state_size:
        state_mid, state_end = _effect_state_step(effects, qpos, qvel, qacc, t, dt, mid, accel,
                                                  state)
    if effects.active:
        position, velocity, quat, body_rate = _midpoint_state(qpos, qvel, qacc, dt)
        loads = effects.loads(np.full(len(command), t + dt / 2), position, velocity, quat,
                              body_rate, mid, accel, state_mid)
        force_body, torque_body = extra_wrench(body, loads, mid, include_scale=False)
        bound["qfrc_applied"][:, dof:dof + 6] = joint_load(
            quat_to_rotmat(quat), force_body, torque_body, loads.force_world, body.com)
        scale = loads.thrust_scale
    bound["ctrl"][:] = scale * mean_sq
    _step(batch, 1)
    return end if state is None else (end, state_end)


def _step(batch, nstep):
    try:
        batch.step(nstep=nstep)
    except mjbatch.SimulationError as exc:
        raise SimulationError(f"mujoco engine: {' '.join(str(exc).split())}") from None


def _check(qpos, qvel, time, expected_t):
    bad = ~np.all(np.isfinite(qpos), 1) | ~np.all(np.isfinite(qvel), 1) \
        | (np.abs(time - expected_t) > 1e-6) \
        | (np.abs(qpos[:, 0:3]).max(1) > STATE_BOUND) | (np.abs(qvel).max(1) > STATE_BOUND)
    if bad.any():
        raise SimulationError(
            f"mujoco engine: simulation(s) {np.flatnonzero(bad).tolist()} diverged before "
            f"t = {expected_t:.4g} s (NaN, MuJoCo reset after a bad acceleration, or state "
            f"beyond {STATE_BOUND:g})")


def run_mujoco(params: Sequence[VehicleParams], effects: BatchEffects, initial: dict,
               command_fn: Callable[[int, dict], np.ndarray], periods: int,
               control_period: float, *, timestep: float | None = None,
               nthread: int = 0) -> dict:
    """Advance B simulations ``periods`` control periods in MuJoCo (same contract and output
    as :func:`quadsim.sim.analytic.run_analytic`). ``timestep`` must divide ``control_period``
    (default :func:`default_timestep`); ``nthread`` 0 uses every CPU.

    This is the step-by-step reference path; :func:`quadsim.sim.engines.simulate` runs the
    compiled path of :mod:`quadsim.sim.compiled` instead when it can (same physics)."""
    dt = timestep or default_timestep(control_period)
    substeps = int(round(control_period / dt))
    if abs(substeps * dt - control_period) > 1e-9 * control_period:
        raise ValueError(f"timestep {dt} does not divide control period {control_period}")
    models = compiled_models(params, dt)
    check_memory(models[0], len(params), periods, params[0].rotor_count)
    body = body_arrays(params)
    batch, body_id = _make_batch(params, models, nthread)
    batch.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
    qpos, qvel = batch.bind("qpos"), batch.bind("qvel")
    qpos[:, 0:3], qpos[:, 3:7] = initial["position"], quat_normalize(initial["quat"])
    qvel[:, 0:3], qvel[:, 3:6] = initial["velocity"], initial["body_rate"]
    batch.forward()
    stepwise = effects.active or effects.rotor_dynamics
    bound = {name: batch.bind(name) for name in ("qpos", "qvel", "qacc", "qfrc_applied", "ctrl")}
    bound["dof"] = int(models[0].body_dofadr[body_id])
    omega = np.array(initial["rotor_speed"], dtype=float)
    extra = effects.initial_state(initial) if effects.state_size else None
    samples, command = [], None
    for k in range(periods + 1):
        state = {"t": np.full(len(params), k * control_period), "position": qpos[:, 0:3].copy(),
                 "velocity": qvel[:, 0:3].copy(), "quat": qpos[:, 3:7].copy(),
                 "body_rate": qvel[:, 3:6].copy(), "rotor_speed": omega.copy()}
        if k < periods:
            command = np.array(command_fn(k, state), dtype=float)
            if not effects.rotor_dynamics:
                state["rotor_speed"] = omega = command.copy()
        samples.append((state, command))
        if k == periods:
            break
        if stepwise:
            for j in range(substeps):
                omega = _effect_step(batch, bound, body_id, body, effects,
                                     k * control_period + j * dt, dt, command, omega, extra)
                if extra is not None:
                    omega, extra = omega
        else:
            batch.bind("ctrl")[:] = command**2
            _step(batch, substeps)
        _check(qpos, qvel, batch.bind("time"), (k + 1) * control_period)
    out = {name: np.stack([s[name] for s, _ in samples], axis=1)
           for name in ("position", "velocity", "quat", "body_rate", "rotor_speed")}
    out["rotor_command"] = np.stack([c for _, c in samples], axis=1)
    return out
