"""Residual wrench: the force and torque a parameter set is missing, per sample of a flight log.

The model says the rotors (and any effects it includes) push the vehicle with a wrench
``(F_model, M_model)``; the log says what the vehicle actually did. Newton–Euler turns the
measured motion into the wrench that must have acted::

    F_meas = m * f_com                (body frame, N; f = specific force at the CoM)
    M_meas = I w_dot + w x (I w)      (body frame, about the CoM, N m)

and the residual is ``F_meas - F_model``, ``M_meas - M_model``: zero (up to sensor noise) when
the model is complete. ``f`` comes from the accelerometer when the log has one (it measures
the specific force at the body origin; the CoM offset adds ``w_dot x c + w x (w x c)``),
otherwise from kinematics ``R^T (a_world + g z)`` with ``a_world`` the second derivative of
position (or first of velocity).

Differentiator
--------------
The log is first resampled onto a uniform grid (median step; linear interpolation,
normalised-linear for quaternions), then every signal that enters the balance (accelerometer,
body rate, velocity/position, rotor speeds) is smoothed and differentiated with the same
Savitzky–Golay filter (``scipy.signal.savgol_filter``; default window 0.1 s, cubic). The
filter is a symmetric FIR, so it is zero-phase: **no lag** between the differentiated motion
and the rotor speeds, and because all signals pass the same filter the balance is not
distorted by different delays. Its amplitude response is flat at low frequency and falls to
-3 dB near ``1.1 / window`` for the smoothed value (about 11 Hz for 0.1 s, cubic; the long
window keeps the noise of differentiated gyro and rotor speeds, which would bias inertia and
rotor-inertia estimates low, small); content
above that is attenuated in both sides of the balance alike (see docs/gap.md for the table).

Example::

    >>> from quadsim.logs.flightlog import load_log
    >>> from quadsim.vehicle.params import load_params
    >>> from quadsim.gap.residual import flight_states, measured_wrench, model_wrench
    >>> params = load_params("crazyflie21")
    >>> states = flight_states(load_log("flight.csv.gz"), gravity=params.gravity)
    >>> force, torque, vehicle = model_wrench(states, params)   # (N, 3) each, body frame
    >>> measured = measured_wrench(states, vehicle)
    >>> measured[0] - force, measured[1] - torque               # the residual, N and N m

Conventions: body x forward, y left, z up; quaternions scalar-first body-to-world; rotor
speeds rad/s; all arrays have the sample axis first.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

from ..core.errors import InputError
from ..core.frames import cross, quat_normalize, rotate_inverse
from ..effects.base import Effect, EffectContext, EffectSet
from ..logs.flightlog import FlightLog, body_rate_from_quat
from ..vehicle.params import VehicleParams
from ..vehicle.rotors import allocation_matrix
from .memo import acting, identity, kept

__all__ = [
    "CHANNELS",
    "DEFAULT_WINDOW_S",
    "FlightStates",
    "channel_unit",
    "flight_states",
    "measured_wrench",
    "model_wrench",
    "resample_uniform",
    "rotor_matrices",
    "rotor_wrench",
    "window_samples",
]

#: Savitzky–Golay window (s) used unless told otherwise.
DEFAULT_WINDOW_S = 0.1
CHANNELS = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


def channel_unit(name: str) -> str:
    """Unit of a residual channel: Fx..Fz N, Mx..Mz N m, a rotor-speed channel rad/s."""
    return {"F": "N", "M": "N m"}.get(name[0], "rad/s")


@dataclass(frozen=True)
class FlightStates:
    """A log on a uniform grid with smoothed values and derivatives (all SI, sample axis first).

    t (N,); position, velocity, accel_world (N, 3) world; quat (N, 4); body_rate,
    body_accel (N, 3) body (rad/s, rad/s^2); specific_force (N, 3) body at the origin (m/s^2);
    rotor_speed, rotor_accel (N, R) or None; command (N, R) normalised or None; vbat (N,) or
    None; accel_source: "accelerometer" or "kinematics"; window_s, polyorder: the filter;
    name: where the log came from; pose: False for a log without a pose (IMU and motors
    only): position, velocity and accel_world are then zero and quat the identity, stand-ins
    that no effect weighed on it reads (:attr:`quadsim.effects.facts.EffectFacts.needs_pose`,
    :mod:`quadsim.gap.posefree`).
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    accel_world: np.ndarray
    quat: np.ndarray
    body_rate: np.ndarray
    body_accel: np.ndarray
    specific_force: np.ndarray
    rotor_speed: np.ndarray | None
    rotor_accel: np.ndarray | None
    command: np.ndarray | None
    vbat: np.ndarray | None
    accel_source: str
    window_s: float
    polyorder: int
    name: str = ""
    pose: bool = True

    def __len__(self) -> int:
        return len(self.t)

    def take(self, index: np.ndarray) -> FlightStates:
        """The states at the sample indices (or boolean mask) ``index``."""
        def pick(value):
            return None if value is None else value[index]

        return FlightStates(self.t[index], self.position[index], self.velocity[index],
                            self.accel_world[index], self.quat[index], self.body_rate[index],
                            self.body_accel[index], self.specific_force[index],
                            pick(self.rotor_speed), pick(self.rotor_accel), pick(self.command),
                            pick(self.vbat), self.accel_source, self.window_s, self.polyorder,
                            self.name, self.pose)


# ----------------------------------------------------------------------------- resampling


def _quat_continuous(quat: np.ndarray) -> np.ndarray:
    """Flip signs so that neighbouring quaternions are in the same hemisphere."""
    quat = np.array(quat, dtype=float)
    flips = np.sign(np.sum(quat[1:] * quat[:-1], axis=-1))
    quat[1:] *= np.cumprod(np.where(flips == 0, 1.0, flips))[:, None]
    return quat


def resample_uniform(log: FlightLog, dt: float | None = None) -> FlightLog:
    """``log`` on a uniform time grid (step ``dt``, default the median step), by linear
    interpolation (quaternions: interpolated componentwise after a sign fix, renormalised)."""
    t = np.asarray(log.t, dtype=float)
    if len(t) < 2:
        raise InputError(f"{log.path or 'log'}: t: fewer than 2 samples")
    step = float(np.median(np.diff(t))) if dt is None else float(dt)
    grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step + 1e-9)) + 1)

    def interp(value):
        if value is None:
            return None
        value = np.asarray(value, dtype=float)
        if value.ndim == 1:
            return np.interp(grid, t, value)
        return np.stack([np.interp(grid, t, value[:, i]) for i in range(value.shape[1])], -1)

    quat = quat_normalize(interp(_quat_continuous(log.quat)))
    return FlightLog(grid, interp(log.position), quat, interp(log.velocity),
                     interp(log.body_rate), interp(log.accel), interp(log.rotor_speed),
                     interp(log.rotor_command), interp(log.vbat), log.path)


def window_samples(window_s: float, dt: float, polyorder: int = 3) -> int:
    """The Savitzky–Golay window in samples: ``window_s / dt`` (s / s) rounded, made odd,
    and at least the shortest window of order ``polyorder``."""
    n = round(window_s / dt)
    n += 1 - n % 2  # odd
    return max(n, polyorder + 2 + (polyorder + 1) % 2)


# ----------------------------------------------------------------------------- states


def flight_states(log: FlightLog, *, window_s: float = DEFAULT_WINDOW_S, polyorder: int = 3,
                  use_accelerometer: bool = True, gravity: float = 9.81,
                  dt: float | None = None) -> FlightStates:
    """Resample ``log`` and smooth/differentiate it with one Savitzky–Golay filter.

    Raises :class:`InputError` if the log is shorter than the filter window."""
    log = resample_uniform(log, dt)
    step = float(log.t[1] - log.t[0])
    window = window_samples(window_s, step, polyorder)
    if len(log.t) < window + 2:
        raise InputError(f"{log.path or 'log'}: t: {len(log.t)} samples, fewer than the "
                         f"{window}-sample smoothing window ({window_s} s)")

    def smooth(x, deriv=0):
        return savgol_filter(x, window, polyorder, deriv=deriv, delta=step, axis=0,
                             mode="interp")

    quat = quat_normalize(smooth(_quat_continuous(log.quat)))
    rate_raw = log.body_rate if log.body_rate is not None else body_rate_from_quat(log.t, log.quat)
    body_rate, body_accel = smooth(rate_raw), smooth(rate_raw, 1)
    if log.velocity is not None:
        velocity, accel_world = smooth(log.velocity), smooth(log.velocity, 1)
    else:
        velocity, accel_world = smooth(log.position, 1), smooth(log.position, 2)
    if use_accelerometer and log.accel is not None and np.all(np.isfinite(log.accel)):
        specific_force, source = smooth(log.accel), "accelerometer"
    else:
        specific_force = rotate_inverse(quat, accel_world + np.array([0.0, 0.0, gravity]))
        source = "kinematics"
    rotor_speed = rotor_accel = None
    if log.rotor_speed is not None:
        rotor_speed, rotor_accel = smooth(log.rotor_speed), smooth(log.rotor_speed, 1)
    command = None if log.rotor_command is None else smooth(log.rotor_command)
    vbat = None if log.vbat is None else smooth(log.vbat)
    return FlightStates(log.t, smooth(log.position), velocity, accel_world, quat, body_rate,
                        body_accel, specific_force, rotor_speed, rotor_accel, command, vbat,
                        source, float(window_s), int(polyorder),
                        str(log.path) if log.path is not None else "")


# ----------------------------------------------------------------------------- the balance


def _effect_set(effects: Iterable[Effect] | EffectSet | None) -> EffectSet:
    if effects is None:
        return EffectSet(())
    if isinstance(effects, EffectSet):
        return effects
    return EffectSet(tuple(effects))


def _require_rotors(states: FlightStates, params: VehicleParams) -> np.ndarray:
    if states.rotor_speed is None:
        raise InputError(f"{states.name or 'log'}: rotor_1..rotor_N: the log has no measured "
                         "rotor speeds; the residual wrench needs them")
    if states.rotor_speed.shape[1] != params.rotor_count:
        raise InputError(f"{states.name or 'log'}: rotor_1..rotor_N: "
                         f"{states.rotor_speed.shape[1]} rotor columns, the model "
                         f"{params.name!r} has {params.rotor_count} rotors")
    return states.rotor_speed


def rotor_wrench(vehicle: VehicleParams, loads, speed: np.ndarray,
                 matrices: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Body-frame wrench (N, 6) of the rotors alone: force (N) and torque about the CoM (N m)
    of speeds ``speed`` (N, R) rad/s with the effects' per-rotor ``loads.thrust_scale`` and
    ``loads.rotor_offset`` (a thrust offset o_i acts along axis a_i at hub r_i: force
    o_i a_i, torque o_i (r_i - c) x a_i). The effects' other loads are not included.
    ``matrices``: :func:`rotor_matrices` of ``vehicle`` when the caller keeps them."""
    allocation_t, offset_wrench = rotor_matrices(vehicle) if matrices is None else matrices
    neutral = getattr(loads, "is_neutral", lambda name: False)
    squared = np.square(speed)
    if not neutral("thrust_scale"):         # a scale of one changes nothing
        squared = squared * loads.thrust_scale
    wrench = squared @ allocation_t
    if neutral("thrust_offset") and neutral("curve_offset"):
        return wrench                       # no offsets: nothing to add
    return wrench + loads.rotor_offset @ offset_wrench


def rotor_matrices(vehicle: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """The (R, 6) maps of :func:`rotor_wrench`: squared speeds to the wrench (the allocation
    matrix, transposed) and thrust offsets (N) to the wrench."""
    axes = vehicle.rotor_axes
    offset = np.hstack([axes, np.cross(vehicle.rotor_positions - vehicle.com, axes)])
    return allocation_matrix(vehicle).T, offset


def model_wrench(states: FlightStates, params: VehicleParams,
                 effects: Iterable[Effect] | EffectSet | None = None,
                 *, rotor_speed: np.ndarray | None = None, rotation: np.ndarray | None = None,
                 flight_memo: dict | None = None
                 ) -> tuple[np.ndarray, np.ndarray, VehicleParams]:
    """Body-frame force (N, 3) and torque about the CoM (N, 3) that the model (``params``
    plus ``effects``) predicts from the measured states and rotor speeds; also the effective
    parameter set (after the effects' ``apply_to_params``). ``rotation``: the states'
    body-to-world matrices (N, 3, 3) when the caller keeps them; ``flight_memo``: handed to
    the effects as :attr:`quadsim.effects.base.EffectContext.flight_memo` (values that depend
    only on the logged motion of ``states``), where the vehicle, the air velocity and each
    effect's loads are also kept (:func:`quadsim.gap.memo.kept`: the same numbers, computed
    once per effect, vehicle, air velocity and rotor speeds, or per effect and what it
    declares its loads read, :attr:`quadsim.effects.base.EffectBase.loads_reads`)."""
    effect_set = _effect_set(effects)
    speed = _require_rotors(states, params) if rotor_speed is None else rotor_speed
    accel = states.rotor_accel if states.rotor_accel is not None else np.zeros_like(speed)
    if flight_memo is None:
        vehicle = effect_set.apply_to_params(params)
        air = states.velocity - effect_set.air_velocity(states.t, states.position)
        vbat = states.vbat if states.vbat is not None else np.full(len(states.t), np.nan)
        matrices = keep = None
    else:
        vehicle_key = (id(params), acting(effect_set.effects, ("apply_to_params",)))
        vehicle, matrices = kept(
            flight_memo, "vehicle", vehicle_key, (params,),
            lambda: _vehicle_matrices(effect_set.apply_to_params(params)))
        air_key = acting(effect_set.effects, ("air_velocity",))
        air = kept(flight_memo, "air", air_key, (),
                   lambda: states.velocity - effect_set.air_velocity(states.t, states.position))
        vbat = states.vbat if states.vbat is not None else kept(
            flight_memo, "no_vbat", (), (), lambda: np.full(len(states.t), np.nan))
        refs = (vehicle, air, speed, accel, vbat)
        context_key = tuple(map(id, refs))
        inputs = {"air_velocity": air, "rotor_speed": speed, "rotor_accel": accel,
                  "vbat": vbat}

        def keep(effect, compute):
            reads = getattr(type(effect), "loads_reads", None)
            if reads is None:       # it may read anything: keyed by the whole context
                return kept(flight_memo, "loads", (identity(effect),) + context_key, refs,
                            compute)
            fields, attributes = reads
            own = tuple(inputs[name] for name in fields)
            key = (identity(effect), fields, tuple(map(id, own)),
                   _vehicle_values(flight_memo, vehicle, attributes))
            return kept(flight_memo, "loads", key, own, compute)
    ctx = EffectContext(states.t, states.position, states.velocity, states.quat,
                        states.body_rate, air, speed, accel, vehicle, vbat,
                        rotation=rotation, flight_memo=flight_memo)
    loads = effect_set.loads(ctx, kept=keep)
    wrench = rotor_wrench(vehicle, loads, speed, matrices)
    force, torque = wrench[:, :3], wrench[:, 3:]
    if not loads.is_neutral("force_world"):     # a zero external load adds nothing
        force = force + ctx.to_body(loads.force_world)
    if not loads.is_neutral("torque_body"):
        torque = torque + loads.torque_body
    return force, torque, vehicle


def _vehicle_matrices(vehicle: VehicleParams):
    return vehicle, rotor_matrices(vehicle)


def _vehicle_values(flight_memo: dict, vehicle: VehicleParams, attributes: tuple) -> tuple:
    """The values (float64 bytes) of ``vehicle``'s ``attributes``, kept per vehicle object:
    an effect's loads that read only these stay the same when a fit moves another part of
    the vehicle (an inertia, a thrust factor)."""
    if not attributes:
        return ()
    return kept(flight_memo, "vehicle_values", (id(vehicle), attributes), (vehicle,),
                lambda: tuple(np.asarray(getattr(vehicle, name), dtype=float).tobytes()
                              for name in attributes))


def measured_wrench(states: FlightStates, params: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame force (N, 3) and torque about the CoM (N, 3) implied by the measured motion
    for a vehicle with ``params``' mass, CoM and inertia (Newton–Euler)."""
    w, w_dot, com = states.body_rate, states.body_accel, params.com
    if np.any(com):
        lever = cross(w_dot, com) + cross(w, cross(w, com))
        force = params.mass * (states.specific_force + lever)
    else:                                   # the CoM at the origin: no lever arm
        force = params.mass * states.specific_force
    inertia = params.inertia
    torque = w_dot @ inertia.T + cross(w, w @ inertia.T)
    return force, torque
