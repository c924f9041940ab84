"""Analytic Newton–Euler reference model of a multirotor, integrated with ``solve_ivp``.

Pure numpy: a 13-state rigid body per simulation (body-origin position and velocity in the
world frame, unit quaternion wxyz body-to-world, body rates), optionally followed by the R
actual rotor speeds when an effect gives the rotors dynamics. Batched: B simulations are one
flat ODE, so one ``solve_ivp`` call advances all of them.

Physics (per simulation, see :mod:`quadsim.vehicle.rotors` for the rotor conventions)::

    F_body   = sum_i (s_i b Omega_i^2 + o_i) a_i                  rotor thrust (+ effects)
    tau_com  = sum_i (r_i - c) x f_i - spin_i d s_i Omega_i^2 a_i  rotor torques about the CoM
    m a_com  = R F_body + F_ext,world + m g
    I dw/dt  = tau_com + tau_ext,body - w x (I w)                 Euler's equations, full I
    a_origin = a_com - R (dw/dt x c + w x (w x c))                the CoM c may be off-origin
    dq/dt    = 0.5 q (x) (0, w)

with thrust scale s_i and thrust offset o_i from the effects (1 and 0 without them), c the CoM
in body axes and I the inertia about the CoM. Effects are evaluated at every right-hand-side
evaluation, in one vectorised call for the batch (hooks of :mod:`quadsim.effects.base`).

Rotor speed commands are held constant over each control period (zero-order hold); each hold
interval is one ``solve_ivp`` call (DOP853, rtol 1e-11, atol 1e-12 by default). Use
:func:`quadsim.sim.engines.simulate` as the front door; this module is the machinery::

    >>> from quadsim.vehicle.params import load_params
    >>> from quadsim.sim.engines import simulate, initial_state
    >>> p = load_params("physical")
    >>> traj = simulate(p, engine="analytic", initial=initial_state(p, position=(0, 0, 1)),
    ...                 duration=1.0, control_period=0.01)

The same functions (:func:`body_arrays`, :class:`BatchEffects`, :func:`extra_wrench`) are
used by the MuJoCo runner so that effects act identically in both engines.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from ..core.errors import SimulationError
from ..core.frames import cross, quat_normalize
from ..core.frames import quat_derivative as _quat_rate
from ..core.frames import quat_to_rotmat as _rotmat
from ..effects.base import EffectContext, EffectLoads, EffectSet
from ..vehicle.params import VehicleParams
from ..vehicle.rotors import allocation_matrix

__all__ = [
    "BodyArrays",
    "body_arrays",
    "rigid_body_accelerations",
    "BatchEffects",
    "extra_wrench",
    "state_derivative",
    "integrate_hold",
    "run_analytic",
    "pack_state",
    "unpack_state",
    "RTOL",
    "ATOL",
    "STATE_BOUND",
]

RTOL = 1e-11
ATOL = 1e-12
#: |position| (m), |velocity| (m/s) or |body rate| (rad/s) beyond which a run has diverged.
STATE_BOUND = 1e6


@dataclass(frozen=True)
class BodyArrays:
    """Per-simulation physical constants, stacked on a leading axis B (SI units).

    mass (B,), com (B, 3), inertia / inertia_inv (B, 3, 3) about the CoM, allocation (B, 6, R) about
    the CoM (:func:`quadsim.vehicle.rotors.allocation_matrix`), rotor_arm (B, R, 3) = hub - CoM,
    rotor_axis (B, R, 3), rotor_spin (R,), thrust_factor / drag_factor (B,), gravity (B,).
    """

    mass: np.ndarray
    com: np.ndarray
    inertia: np.ndarray
    inertia_inv: np.ndarray
    allocation: np.ndarray
    rotor_arm: np.ndarray
    rotor_axis: np.ndarray
    rotor_spin: np.ndarray
    thrust_factor: np.ndarray
    drag_factor: np.ndarray
    gravity: np.ndarray


def body_arrays(params: Sequence[VehicleParams]) -> BodyArrays:
    """Stack the constants of B parameter sets (same rotor count) into :class:`BodyArrays`.
    Each distinct set object is evaluated once (a batch usually repeats one set)."""
    first: dict[int, int] = {}
    index = np.array([first.setdefault(id(p), len(first)) for p in params])
    unique = [None] * len(first)
    for p in params:
        unique[first[id(p)]] = p

    def stack(f):
        return np.array([f(p) for p in unique], dtype=float)[index]

    return BodyArrays(
        mass=stack(lambda p: p.mass),
        com=stack(lambda p: p.com),
        inertia=stack(lambda p: p.inertia),
        inertia_inv=stack(lambda p: np.linalg.inv(p.inertia)),
        allocation=stack(allocation_matrix),
        rotor_arm=stack(lambda p: p.rotor_positions - p.com),
        rotor_axis=stack(lambda p: p.rotor_axes),
        rotor_spin=np.asarray(params[0].rotor_spins, dtype=float),
        thrust_factor=stack(lambda p: p.thrust_factor),
        drag_factor=stack(lambda p: p.drag_factor),
        gravity=stack(lambda p: p.gravity),
    )


def _matvec(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    return (m @ v[..., None])[..., 0]


def rigid_body_accelerations(body: BodyArrays, quat: np.ndarray, body_rate: np.ndarray,
                             force_body: np.ndarray, torque_body: np.ndarray,
                             force_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Newton–Euler at the CoM, returned at the body origin.

    force_body (B, 3) and torque_body (B, 3, about the CoM) in body axes, force_world (B, 3)
    at the CoM (gravity is added here). Returns the world acceleration of the body origin
    (B, 3) (m/s^2) and the body angular acceleration (B, 3) (rad/s^2)."""
    rot = _rotmat(quat)
    gravity = np.zeros_like(force_world)
    gravity[:, 2] = -body.gravity * body.mass
    accel_com = (_matvec(rot, force_body) + force_world + gravity) \
        / body.mass[:, None]
    momentum = _matvec(body.inertia, body_rate)
    alpha = _matvec(body.inertia_inv, torque_body - cross(body_rate, momentum))
    lever = cross(alpha, body.com) + cross(body_rate, cross(body_rate, body.com))
    return accel_com - _matvec(rot, lever), alpha


class BatchEffects:
    """The effects of B simulations, evaluated in one call per group of simulations.

    ``sets`` is one :class:`EffectSet` for all simulations or one per simulation; ``params``
    the (effect-modified) parameter set of each simulation. Simulations sharing the same
    EffectSet object (and parameter set) are evaluated together, so the common case (one set
    for the batch) is a single vectorised call per hook."""

    def __init__(self, sets: EffectSet | Sequence[EffectSet] | None,
                 params: Sequence[VehicleParams]):
        batch = len(params)
        if sets is None:
            sets = EffectSet()
        if isinstance(sets, EffectSet):
            sets = [sets] * batch
        groups: dict[tuple[int, int], list[int]] = {}
        for i, (effect_set, p) in enumerate(zip(sets, params)):
            groups.setdefault((id(effect_set), id(p)), []).append(i)
        self.groups = [(sets[idx[0]], params[idx[0]], np.array(idx)) for idx in groups.values()]
        self.batch = batch
        self.active = any(s.effects for s, _, _ in self.groups)
        dynamics = [s.has_rotor_dynamics() for s, _, _ in self.groups]
        if any(dynamics) and not all(dynamics):
            raise ValueError("either every simulation of a batch has rotor dynamics or none")
        self.rotor_dynamics = bool(dynamics) and all(dynamics)
        #: internal effect states per simulation (the largest group's; others padded)
        self.state_size = max((s.state_size() for s, _, _ in self.groups), default=0)

    def initial_state(self, vehicle: dict) -> np.ndarray:
        """(B, state_size) internal effect states at the start (vehicle snapshot dict)."""
        out = np.zeros((self.batch, self.state_size))
        for effect_set, params, idx in self.groups:
            size = effect_set.state_size()
            if size:
                part = {k: np.asarray(v)[idx] for k, v in vehicle.items()}
                out[idx, :size] = effect_set.initial_state(params, part)
        return out

    def _contexts(self, t, position, velocity, quat, body_rate, rotor_speed, rotor_accel,
                  effect_state):
        for effect_set, params, idx in self.groups:
            if not effect_set.effects:
                continue
            wind = effect_set.air_velocity(t[idx], position[idx])
            size = effect_set.state_size()
            state = None if effect_state is None else effect_state[idx, :size]
            yield effect_set, idx, size, EffectContext(
                t=t[idx], position=position[idx], velocity=velocity[idx], quat=quat[idx],
                body_rate=body_rate[idx], air_velocity=velocity[idx] - wind,
                rotor_speed=rotor_speed[idx], rotor_accel=rotor_accel[idx], params=params,
                effect_state=state)

    def state_rate(self, t, position, velocity, quat, body_rate, rotor_speed, rotor_accel,
                   effect_state) -> np.ndarray:
        """d/dt of the internal effect states (B, state_size)."""
        rate = np.zeros_like(effect_state)
        for effect_set, idx, size, ctx in self._contexts(
                t, position, velocity, quat, body_rate, rotor_speed, rotor_accel, effect_state):
            if size:
                rate[idx, :size] = effect_set.state_rate(ctx)
        return rate

    def rotor_speed_rate(self, t: np.ndarray, commanded: np.ndarray,
                         actual: np.ndarray) -> np.ndarray:
        """dOmega/dt (B, R) of the actual rotor speeds (zeros without rotor dynamics)."""
        rate = np.zeros_like(actual)
        for effect_set, _, idx in self.groups:
            part = effect_set.rotor_speed_rate(t[idx], commanded[idx], actual[idx])
            if part is not None:
                rate[idx] = part
        return rate

    def loads(self, t: np.ndarray, position: np.ndarray, velocity: np.ndarray,
              quat: np.ndarray, body_rate: np.ndarray, rotor_speed: np.ndarray,
              rotor_accel: np.ndarray, effect_state: np.ndarray | None = None) -> EffectLoads:
        """Wind first (``air_velocity``), then ``loads(ctx)``; (B, ...) arrays in, loads out."""
        rotors = rotor_speed.shape[1]       # written into per group: arrays of its own
        total = EffectLoads(np.ones((self.batch, rotors)), np.zeros((self.batch, rotors)),
                            np.zeros((self.batch, 3)), np.zeros((self.batch, 3)),
                            np.zeros((self.batch, rotors)))
        for effect_set, idx, _, ctx in self._contexts(
                t, position, velocity, quat, body_rate, rotor_speed, rotor_accel, effect_state):
            part = effect_set.loads(ctx)
            for name in ("thrust_scale", "thrust_offset", "force_world", "torque_body",
                         "curve_offset"):
                getattr(total, name)[idx] = getattr(part, name)
        return total


def extra_wrench(body: BodyArrays, loads: EffectLoads, rotor_speed: np.ndarray, *,
                 include_scale: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame force and torque about the CoM that the effects add to the nominal rotors.

    A thrust scale s multiplies a rotor's thrust and drag torque (extra: (s - 1) times the
    nominal); a thrust offset o (and a curve offset, times s: ``loads.rotor_offset``) adds o
    along the rotor axis at the hub (moment arm, no drag torque). ``loads.torque_body`` is
    added; ``loads.force_world`` is not (it is world-frame).
    With ``include_scale=False`` the scale part is left out (the MuJoCo runner applies it
    through the actuator controls instead)."""
    omega2 = np.square(rotor_speed)
    thrust = loads.rotor_offset.copy()
    drag = np.zeros_like(omega2)
    if include_scale:
        thrust += (loads.thrust_scale - 1.0) * body.thrust_factor[:, None] * omega2
        drag = (loads.thrust_scale - 1.0) * body.drag_factor[:, None] * omega2
    forces = thrust[..., None] * body.rotor_axis                      # (B, R, 3)
    torque = cross(body.rotor_arm, forces).sum(1) \
        - np.einsum("br,r,brk->bk", drag, body.rotor_spin, body.rotor_axis)
    return forces.sum(1), torque + loads.torque_body


def _unpack(y: np.ndarray, batch: int, rotors: int, with_rotors: bool):
    y = y.reshape(batch, -1)
    omega = y[:, 13:13 + rotors] if with_rotors else None
    return y[:, 0:3], y[:, 3:6], y[:, 6:10], y[:, 10:13], omega


def state_derivative(t: float, y: np.ndarray, *, body: BodyArrays, effects: BatchEffects,
                     command: np.ndarray) -> np.ndarray:
    """d/dt of the flat batched state ``y`` (B * (13 [+ R])) under held ``command`` (B, R)."""
    batch, rotors = command.shape
    rotor_dynamics = effects.rotor_dynamics
    position, velocity, quat, body_rate, omega = _unpack(y, batch, rotors, rotor_dynamics)
    times = np.full(batch, t)
    omega_dot = np.zeros_like(command)
    extra = y.reshape(batch, -1)[:, y.size // batch - effects.state_size:]
    if rotor_dynamics:
        omega_dot = effects.rotor_speed_rate(times, command, omega)
    else:
        omega = command
    force_body, torque_body = np.zeros((batch, 3)), np.zeros((batch, 3))
    force_world = np.zeros((batch, 3))
    if effects.active:
        loads = effects.loads(times, position, velocity, quat, body_rate, omega, omega_dot,
                              extra)
        force_body, torque_body = extra_wrench(body, loads, omega)
        force_world = loads.force_world
    wrench = _matvec(body.allocation, np.square(omega))
    accel, alpha = rigid_body_accelerations(body, quat, body_rate, wrench[:, :3] + force_body,
                                            wrench[:, 3:] + torque_body, force_world)
    parts = [velocity, accel, _quat_rate(quat, body_rate), alpha]
    if rotor_dynamics:
        parts.append(omega_dot)
    if effects.state_size:
        parts.append(effects.state_rate(times, position, velocity, quat, body_rate, omega,
                                        omega_dot, extra))
    return np.concatenate(parts, axis=1).ravel()


def integrate_hold(y0: np.ndarray, t0: float, t1: float,
                   rhs: Callable[[float, np.ndarray], np.ndarray], *, rtol: float = RTOL,
                   atol: float = ATOL, batch: int) -> np.ndarray:
    """Integrate one hold interval [t0, t1] with DOP853; renormalise the quaternions after.

    Raises :class:`SimulationError` if the solver fails or the state leaves the bounds."""
    solution = solve_ivp(rhs, (t0, t1), y0, method="DOP853", rtol=rtol, atol=atol)
    y1 = solution.y[:, -1] if solution.success else np.full_like(y0, np.nan)
    state = y1.reshape(batch, -1)
    bad = ~np.all(np.isfinite(state), axis=1) | (np.abs(state[:, :13]).max(1) > STATE_BOUND)
    if bad.any():
        raise SimulationError(
            f"analytic engine: simulation(s) {np.flatnonzero(bad).tolist()} diverged at "
            f"t = {t1:.4g} s (state NaN or beyond {STATE_BOUND:g}; {solution.message})")
    state[:, 6:10] = quat_normalize(state[:, 6:10])
    return state.ravel()


def pack_state(initial: dict, rotor_dynamics: bool) -> np.ndarray:
    """Flat ODE state from a snapshot dict of (B, ...) arrays (see :func:`unpack_state`)."""
    parts = [initial["position"], initial["velocity"], quat_normalize(initial["quat"]),
             initial["body_rate"]]
    if rotor_dynamics:
        parts.append(initial["rotor_speed"])
    return np.concatenate(parts, axis=1).ravel()


def unpack_state(y: np.ndarray, t: float, batch: int, rotor_speed: np.ndarray,
                 rotor_dynamics: bool) -> dict:
    """Snapshot dict (t, position, velocity, quat, body_rate, rotor_speed; (B, ...) each)."""
    rotors = rotor_speed.shape[1]
    position, velocity, quat, body_rate, omega = _unpack(y, batch, rotors, rotor_dynamics)
    return {"t": np.full(batch, t), "position": position.copy(), "velocity": velocity.copy(),
            "quat": quat.copy(), "body_rate": body_rate.copy(),
            "rotor_speed": (omega if rotor_dynamics else rotor_speed).copy()}


def run_analytic(params: Sequence[VehicleParams], effects: BatchEffects, initial: dict,
                 command_fn: Callable[[int, dict], np.ndarray], periods: int,
                 control_period: float, *, rtol: float = RTOL, atol: float = ATOL,
                 rhs: Callable | None = None) -> dict:
    """Advance B simulations ``periods`` control periods; commands held over each period.

    ``initial``: snapshot dict of (B, ...) arrays; ``command_fn(k, snapshot) -> (B, R)``
    rotor speed commands (rad/s) for period k. Returns the samples at the period boundaries:
    dict of (B, periods + 1, ...) arrays ``position, velocity, quat, body_rate, rotor_speed,
    rotor_command`` (rotor_speed is the actual speed; without rotor dynamics the command
    held from that instant).

    ``rhs``: None (default) evaluates :func:`state_derivative`; a compiled right-hand side
    with the same equations (:func:`quadsim.sim.compiled.analytic_fast_rhs`, which
    :func:`quadsim.sim.engines.simulate` passes when numba is installed and every effect has a
    fast form) is used instead."""
    body = body_arrays(params)
    compiled = rhs
    batch = len(params)
    dynamics = effects.rotor_dynamics
    y = pack_state(initial, dynamics)
    if effects.state_size:
        y = np.concatenate([y.reshape(batch, -1), effects.initial_state(initial)], 1).ravel()
    state = unpack_state(y, 0.0, batch, initial["rotor_speed"], dynamics)
    samples = []
    command = None
    for k in range(periods + 1):
        t0 = k * control_period
        if k < periods:
            command = np.array(command_fn(k, state), dtype=float)
            if not dynamics:
                state["rotor_speed"] = command.copy()
        samples.append((state, command))
        if k == periods:
            break
        def rhs(t, yy, held=command):
            if compiled is not None:
                return compiled(t, yy, held)
            return state_derivative(t, yy, body=body, effects=effects, command=held)

        y = integrate_hold(y, t0, t0 + control_period, rhs, rtol=rtol, atol=atol, batch=batch)
        state = unpack_state(y, t0 + control_period, batch, command, dynamics)
    out = {name: np.stack([s[name] for s, _ in samples], axis=1)
           for name in ("position", "velocity", "quat", "body_rate", "rotor_speed")}
    out["rotor_command"] = np.stack([c for _, c in samples], axis=1)
    return out
