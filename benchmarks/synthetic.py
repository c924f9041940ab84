"""Inverse-dynamics flight logs: exact, fast test and benchmark data for the gap diagnosis.

A smooth reference path (figure-8 with height and yaw variation, dipping close to the
ground) is flown *exactly*: differential flatness gives the attitude, Newton–Euler the
thrust and torque the rotors must produce, and the rotor speeds are solved from the
geometry-derived allocation (:mod:`quadsim.vehicle.rotors`) **with the hidden effects acting**
(through the same hooks the engines call: ``apply_to_params``, ``air_velocity``, ``loads``,
``rotor_speed_rate``). A few fixed-point passes resolve effects that depend on the rotor
speeds (drag, thrust curve). Commands are the speeds that the motor dynamics turn into the
logged speeds. Sensor noise (seeded) is added to every logged signal.

Unlike the closed-loop flight generator (``quadsim.fly``) there is no controller and no
integration error, so the only differences between the log and the nominal model are the
hidden effects and the noise: the right data to test that the diagnosis finds them.

Example::

    >>> from quadsim.vehicle.params import load_params
    >>> from quadsim.effects import make_effect
    >>> from benchmarks.synthetic import synthetic_flight
    >>> log = synthetic_flight(load_params("crazyflie21"), [make_effect("mass_offset", mass=0.004)],
    ...                        seed=3)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np

from quadsim.core.frames import quat_multiply, quat_normalize, rotate_inverse
from quadsim.effects.base import Effect, EffectContext, EffectSet
from quadsim.gap.residual import rate_owner, rotor_wrench
from quadsim.logs.flightlog import FlightLog
from quadsim.logs.generate import logged_command
from quadsim.vehicle.params import VehicleParams, hover_speed
from quadsim.vehicle.rotors import allocation_matrix

__all__ = ["NotFlyable", "SLOWER", "SLOWER_TRIES", "SPEED_BOUNDS", "SensorNoise",
           "commands_through_map", "flown_slower", "flyable_flight", "reference_path",
           "synthetic_flight"]

T = TypeVar("T")


class NotFlyable(ValueError):
    """A generated path the vehicle's rotors cannot fly exactly (:func:`synthetic_flight`,
    ``flyable_only``)."""


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of white sensor noise (SI): position (m), velocity (m/s),
    attitude (rad, small rotation), gyro (rad/s), accelerometer (m/s^2), rotor speed
    (fraction of hover speed), vbat (V)."""

    position: float = 5e-4
    velocity: float = 0.01
    attitude: float = 2e-3
    gyro: float = 0.02
    accel: float = 0.1
    rotor: float = 0.005
    vbat: float = 0.005


#: peak vertical acceleration of the heave (m/s^2).
HEAVE_ACCEL = 0.7


def _smooth_step(u: np.ndarray) -> np.ndarray:
    """0 for u <= 0, 1 for u >= 1, infinitely smooth in between (the attitude depends on the
    path's 2nd derivative and the torque on its 4th: a ramp with a jump in any of them
    would put a torque spike into the log)."""
    u = np.clip(u, 0.0, 1.0)
    a = np.where(u > 0, np.exp(-1.0 / np.maximum(u, 1e-12)), 0.0)
    b = np.where(u < 1, np.exp(-1.0 / np.maximum(1 - u, 1e-12)), 0.0)
    return a / (a + b)


def reference_path(t: np.ndarray, params: VehicleParams, rng: np.random.Generator,
                   speed: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Position (N, 3) and yaw (N,) of a figure-8 whose height dips to ~1.5 rotor radii.

    Size scales with the vehicle's arm length; ``speed`` (m/s) is the typical path speed."""
    arm = float(np.max(np.linalg.norm(params.rotor_positions, axis=1)))
    size = max(0.5, 10 * arm) * rng.uniform(0.8, 1.2)
    omega = speed / size
    radius = params.rotor_radius or arm / 2
    low, high = 1.5 * radius, max(0.6, 12 * radius)
    phase = rng.uniform(0, 2 * np.pi)
    ramp = _smooth_step(t / 3.0)  # starts at rest; all derivatives continuous
    # A small fast wiggle (1.5-2.5 Hz on a Crazyflie-sized vehicle, 1.5 m/s^2) excites the
    # attitude dynamics (rates of a few rad/s).
    agility = min(1.0, 0.06 / arm)  # larger vehicles: slower wiggle
    wiggle_f = rng.uniform(1.5, 2.5) * 2 * np.pi * np.sqrt(agility)
    wiggle = 1.5 / wiggle_f ** 2 * np.sin(wiggle_f * t) * ramp
    # ... and a vertical one spreads the rotor speeds (separates b, mass and thrust curve).
    heave_f = 0.6 * wiggle_f
    heave = HEAVE_ACCEL / heave_f ** 2 * np.sin(heave_f * t + phase) * ramp
    x = size * np.sin(omega * t) * ramp + wiggle
    y = 0.5 * size * np.sin(2 * omega * t) * ramp - 0.7 * wiggle
    # The lowest point is 1.5 rotor radii above the ground plus the heave amplitude.
    low = low + HEAVE_ACCEL / heave_f ** 2
    z = low + (high - low) * 0.5 * (1 + np.cos(0.7 * omega * t + phase) ** 3) + heave
    yaw = (0.6 * np.sin(0.5 * omega * t + phase) + 0.1 * np.sin(0.3 * wiggle_f * t)) * ramp
    return np.stack([x, y, z], -1), yaw


def _attitude(thrust_world: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) with body z along the thrust and the given yaw."""
    zb = thrust_world / np.linalg.norm(thrust_world, axis=1, keepdims=True)
    xc = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], -1)
    yb = np.cross(zb, xc)
    yb /= np.linalg.norm(yb, axis=1, keepdims=True)
    xb = np.cross(yb, zb)
    return np.stack([xb, yb, zb], -1)


def _align_body_force(rot: np.ndarray, force_dir: np.ndarray) -> np.ndarray:
    """``rot`` (N, 3, 3) turned in the body frame so that the body direction ``force_dir``
    (N, 3, unit) lands where ``rot`` put body z: R' = R C with C force_dir = z (Rodrigues).
    Rotors tilted from body z (a canted rotor) push partly sideways; the attitude must put
    the rotors' total force, not body z, along the force the path needs."""
    z = np.array([0.0, 0.0, 1.0])
    k = np.cross(force_dir, z)
    s2 = np.sum(k * k, axis=1)
    if not np.any(s2 > 0.0):
        return rot
    c = force_dir[:, 2]
    kx = np.zeros((len(k), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    kx[:, 1, 0], kx[:, 2, 0], kx[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    scale = np.divide(1.0 - c, s2, out=np.zeros_like(c), where=s2 > 0.0)
    turn = np.eye(3)[None] + kx + np.einsum("nij,njk->nik", kx, kx) * scale[:, None, None]
    return np.einsum("nij,njk->nik", rot, turn)


def _rotor_force_dir(vehicle, loads, speed) -> np.ndarray:
    """Unit direction (N, 3), body frame, of the rotors' total force at ``speed``."""
    force = rotor_wrench(vehicle, loads, speed)[:, :3]
    return force / np.linalg.norm(force, axis=1, keepdims=True)


def _rotmat_to_quat(rot: np.ndarray) -> np.ndarray:
    w = np.sqrt(np.maximum(1 + rot[:, 0, 0] + rot[:, 1, 1] + rot[:, 2, 2], 1e-12)) / 2
    q = np.stack([w, (rot[:, 2, 1] - rot[:, 1, 2]) / (4 * w),
                  (rot[:, 0, 2] - rot[:, 2, 0]) / (4 * w),
                  (rot[:, 1, 0] - rot[:, 0, 1]) / (4 * w)], -1)
    return quat_normalize(q)


def _body_rate(t: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """omega = vee(R^T dR/dt), central differences."""
    skew = np.einsum("nji,njk->nik", rot, np.gradient(rot, t, axis=0))
    return np.stack([skew[:, 2, 1] - skew[:, 1, 2], skew[:, 0, 2] - skew[:, 2, 0],
                     skew[:, 1, 0] - skew[:, 0, 1]], -1) / 2


def _solve_rotors(vehicle, loads, thrust, torque, speed):
    """Squared rotor speeds giving [thrust, torque] with per-rotor scale and offsets."""
    alloc = allocation_matrix(vehicle)[[2, 3, 4, 5]]                       # (4, R)
    axes = vehicle.rotor_axes
    offset_map = np.hstack([axes, np.cross(vehicle.rotor_positions - vehicle.com, axes)])
    offsets = loads.rotor_offset @ offset_map[:, [2, 3, 4, 5]]            # (N, 4)
    rhs = np.concatenate([thrust[:, None], torque], 1) - offsets
    matrix = alloc[None] * loads.thrust_scale[:, None, :]                # (N, 4, R)
    omega2 = np.einsum("nij,nj->ni", np.linalg.pinv(matrix), rhs)
    low, high = SPEED_BOUNDS
    return np.sqrt(np.clip(omega2, (low * speed) ** 2, (high * speed) ** 2))


def _rotor_wrench(vehicle, effect_set, ctx, speed):
    """[thrust along body z, torque (3)] (N, 4) of rotors + speed-dependent effect loads."""
    ctx = EffectContext(ctx.t, ctx.position, ctx.velocity, ctx.quat, ctx.body_rate,
                        ctx.air_velocity, speed, ctx.rotor_accel, ctx.params, ctx.vbat)
    loads = effect_set.loads(ctx)
    wrench = rotor_wrench(vehicle, loads, speed)[:, 2:]
    wrench[:, 1:] += loads.torque_body
    return wrench


def _speed_dependent(effect_set, ctx) -> bool:
    """Whether the effects' loads change with the rotor speeds (then Newton is needed)."""
    if not effect_set.effects:
        return False
    a = effect_set.loads(ctx)
    b = effect_set.loads(EffectContext(ctx.t, ctx.position, ctx.velocity, ctx.quat,
                                       ctx.body_rate, ctx.air_velocity, ctx.rotor_speed * 1.01,
                                       ctx.rotor_accel, ctx.params, ctx.vbat))
    return not all(np.array_equal(getattr(a, k), getattr(b, k)) for k in
                   ("thrust_scale", "thrust_offset", "force_world", "torque_body",
                    "curve_offset"))


def _newton_rotors(vehicle, effect_set, ctx, loads, thrust, inertial_torque, speed, hover,
                   iterations: int = 4):
    """Speeds whose rotor + effect wrench equals [thrust, inertial torque], per sample."""
    target = np.concatenate([thrust[:, None], inertial_torque], 1)
    step = 1e-4 * hover
    for _ in range(iterations):
        base = _rotor_wrench(vehicle, effect_set, ctx, speed)
        jac = np.stack([(_rotor_wrench(vehicle, effect_set, ctx, speed + step * e) - base) / step
                        for e in np.eye(speed.shape[1])], -1)                # (N, 4, R)
        delta = np.einsum("nij,nj->ni", np.linalg.pinv(jac), target - base)
        speed = np.clip(speed + delta, SPEED_BOUNDS[0] * hover, SPEED_BOUNDS[1] * hover)
    return speed


def _accel_sensitivity(effect_set, ctx) -> np.ndarray | None:
    """d(torque_body)/d(dOmega_r/dt) (N, 3, R) by probing the effects (None if zero)."""
    base = effect_set.loads(ctx).torque_body
    rotors = ctx.rotor_speed.shape[1]
    columns = []
    for r in range(rotors):
        probe = np.zeros_like(ctx.rotor_speed)
        probe[:, r] = 1.0
        shifted = EffectContext(ctx.t, ctx.position, ctx.velocity, ctx.quat, ctx.body_rate,
                                ctx.air_velocity, ctx.rotor_speed, ctx.rotor_accel + probe,
                                ctx.params, ctx.vbat)
        columns.append(effect_set.loads(shifted).torque_body - base)
    sens = np.stack(columns, -1)
    return sens if np.abs(sens).max() > 0 else None


def _march_rotors(vehicle, loads, thrust, torque, sens, accel_used, speed, dt):
    """Rotor speeds when the effect torque depends (linearly) on dOmega/dt: implicit Euler in
    time (dOmega/dt = (Omega_k - Omega_{k-1}) / dt), Newton at each sample."""
    alloc = allocation_matrix(vehicle)[[2, 3, 4, 5]]
    axes = vehicle.rotor_axes
    offset_map = np.hstack([axes, np.cross(vehicle.rotor_positions - vehicle.com, axes)])
    rhs = (np.concatenate([thrust[:, None], torque], 1) - loads.rotor_offset @ offset_map[:, 2:])
    # torque here already subtracted the probed term at accel_used; put it back as unknown.
    rhs[:, 1:] += np.einsum("nir,nr->ni", sens, accel_used)
    out = speed.copy()
    square = alloc.shape[0] == alloc.shape[1]
    for k in range(1, len(out)):
        x = out[k].copy()
        matrix = alloc * loads.thrust_scale[k]
        coupling = np.vstack([np.zeros((1, x.size)), sens[k]]) / dt      # (4, R)
        for _ in range(3):  # warm start from the previous pass: a few Newton steps suffice
            f = matrix @ (x * x) + coupling @ (x - out[k - 1]) - rhs[k]
            jac = matrix * (2 * x) + coupling
            x = x - (np.linalg.solve(jac, f) if square else np.linalg.lstsq(jac, f, rcond=None)[0])
        out[k] = np.maximum(x, SPEED_BOUNDS[0] * speed[k])
    return out


#: the rotor speeds the solvers hold a sample within, as fractions of the hover speed
#: (:func:`_solve_rotors`, :func:`_newton_rotors`; :func:`_march_rotors` floors at this
#: fraction of the previous pass's speed): a sample held at a bound is not flown exactly
SPEED_BOUNDS = (0.05, 3.0)


def _exact_flight(t, params, effect_set, com_path, yaw, vbat, passes: int = 10):
    """States and rotor speeds of the exact flight, and (N,) whether the last pass held a
    sample's rotor speeds at a bound (:data:`SPEED_BOUNDS`: the path asks more than the
    rotors give, so the logged speeds do not produce the logged motion there); ``com_path``
    is the CoM's path (so the thrust direction does not depend on the angular
    acceleration)."""
    vehicle = effect_set.apply_to_params(params)
    accel_com = np.gradient(np.gradient(com_path, t, axis=0), t, axis=0)
    hover = hover_speed(params)
    dt = float(t[1] - t[0])
    speed = np.full((len(t), params.rotor_count), hover)
    lift = accel_com + [0, 0, vehicle.gravity]
    rot = _attitude(lift, yaw)
    if not effect_set.effects:
        passes = 2  # nothing feeds back: one pass for the attitude, one for the speeds
    force_dir = np.tile([0.0, 0.0, 1.0], (len(t), 1))   # body direction of the rotor force
    for done in range(passes):
        quat = _rotmat_to_quat(rot)
        rate = _body_rate(t, rot)
        rate_dot = np.gradient(rate, t, axis=0)
        position = com_path - np.einsum("nij,j->ni", rot, vehicle.com)   # body origin
        velocity = np.gradient(position, t, axis=0)
        wind = effect_set.air_velocity(t, position)
        rotor_accel = np.vstack([np.zeros((1, speed.shape[1])), np.diff(speed, axis=0) / dt])
        ctx = EffectContext(t, position, velocity, quat, rate, velocity - wind, speed,
                            rotor_accel, vehicle, vbat)
        loads = effect_set.loads(ctx)
        thrust_world = vehicle.mass * lift - loads.force_world
        rot = _align_body_force(_attitude(thrust_world, yaw), force_dir)
        inertia = vehicle.inertia
        torque = rate_dot @ inertia.T + np.cross(rate, rate @ inertia.T) - loads.torque_body
        # the rotors' force along body z (all of it unless a rotor is tilted)
        thrust = np.linalg.norm(thrust_world, axis=1) * force_dir[:, 2]
        sens = _accel_sensitivity(effect_set, ctx)
        if sens is None or done < passes - 2:
            # Early passes leave out the dOmega/dt torque (cheap); the last two march in time.
            if sens is not None:
                torque = torque + np.einsum("nir,nr->ni", sens, rotor_accel)
            solved = _solve_rotors(vehicle, loads, thrust, torque, hover)
            if done > 0 and _speed_dependent(effect_set, ctx):
                # Loads that depend on the speeds (rotor-drag torque, a canted rotor) are
                # solved for together with the speeds (Newton, Jacobian by probing).
                solved = _newton_rotors(vehicle, effect_set, ctx, loads, thrust,
                                        torque + loads.torque_body, solved, hover)
            speed = solved
            low, high = (f * hover for f in SPEED_BOUNDS)
            held = (speed <= low * (1 + 1e-9)) | (speed >= high * (1 - 1e-9))
        else:
            before = speed
            speed = _march_rotors(vehicle, loads, thrust, torque, sens, rotor_accel, speed, dt)
            held = speed == SPEED_BOUNDS[0] * before
        force_dir = _rotor_force_dir(vehicle, loads, speed)
    specific = rotate_inverse(quat, np.gradient(velocity, t, axis=0) + [0, 0, vehicle.gravity])
    return position, velocity, quat, rate, specific, speed, np.any(held, axis=1)


def _commanded_speeds(t, speed, effect_set, hover, vbat):
    """Commanded rotor speeds (N, R) (rad/s) whose motor dynamics give ``speed`` (Newton on
    the rate). A speed factor alone (a battery) is static, as the diagnosis models it:
    commanded = speed / factor (the engines' 5 ms SPEED_RESPONSE_S smoothing is a numerical
    convenience, not a lag of the battery)."""
    rate_needed = np.gradient(speed, t, axis=0)
    cmd = speed.copy()
    if rate_owner(effect_set.effects) is None:
        factor = effect_set.command_factor(t, vbat, cmd.shape[1])
        return cmd if factor is None else cmd / factor
    if effect_set.has_rotor_dynamics():
        for _ in range(8):
            rate = effect_set.rotor_speed_rate(t, cmd, speed)
            step = 1e-3 * hover
            slope = (effect_set.rotor_speed_rate(t, cmd + step, speed) - rate) / step
            cmd = cmd - (rate - rate_needed) / np.where(np.abs(slope) > 1e-12, slope, 1.0)
    return cmd


def synthetic_flight(params: VehicleParams, effects: Sequence[Effect] = (), *,
                     duration: float = 10.0, rate_hz: float = 500.0, speed: float = 1.0,
                     seed: int = 0, noise: SensorNoise | None = SensorNoise(),
                     full_voltage: float = 4.2, load_share: float = 0.0,
                     name: str = "synthetic", commands: str = "fly",
                     flyable_only: bool = False) -> FlightLog:
    """An exact log of ``params`` + hidden ``effects`` flying :func:`reference_path`.

    Deterministic for a seed. ``vbat`` falls linearly 0.15 V over the flight (or follows a
    ``battery_sag`` effect's voltage model). ``commands``: how the log writes the commanded
    rotor speeds w (rad/s) --

    * ``"fly"`` (the default): as ``quadsim.fly`` writes them, its own code
      (:func:`quadsim.logs.generate.logged_command`): the set's motor map at the battery
      voltage before the vbat sensor's noise (``MotorMap.command_at``, normalised 0-1), so
      ``MotorMap.speed_at(command, vbat)`` gives w back; ``w / max_speed`` for a set without
      a map;
    * ``"max_speed"``: ``w / max_speed``, whatever the set (the default before; a set's map
      is then not the law its commands follow).

    ``load_share``: the motors are DC motors whose load torque takes this share s of the
    back EMF at hover (commanded speeds ``w (1 + s w / hover) / (1 + s)``, the same at
    hover, before the convention); 0: speed-controlled motors, commanded speed the speed.
    Its propeller reading's exponent is then ``alpha = s / (1 + s)`` with commands
    proportional to the commanded speed (:func:`quadsim.gap.residual.load_exponent`).

    ``flyable_only``: raise :class:`NotFlyable` where the path asks the rotors for a speed
    outside :data:`SPEED_BOUNDS` within the logged span (the solvers hold such a sample at
    the bound, so its logged speeds do not produce its logged motion: a log no vehicle could
    write, whatever its effects); False (the default, as before): such samples are kept as
    held."""
    rng = np.random.default_rng(seed)
    pad = round(float(0.5 * rate_hz))  # differentiate on a longer grid, trim the ends
    t = (np.arange(round(float(duration * rate_hz)) + 1 + 2 * pad) - pad) / rate_hz
    position, yaw = reference_path(t, params, rng, speed)
    effect_set = EffectSet(tuple(effects))
    sag = [e for e in effects if getattr(e, "name", "") == "battery_sag"]
    vbat = sag[0].voltage(t) if sag else full_voltage - 0.15 * t / max(duration, 1e-9)
    position, velocity, quat, rate, specific, speed_, held = _exact_flight(
        t, params, effect_set, position, yaw, vbat)
    if flyable_only and np.any(held[pad:len(t) - pad]):
        span = t[pad:len(t) - pad][held[pad:len(t) - pad]]
        raise NotFlyable(f"synthetic_flight {name!r} (seed {seed}, speed {speed:g} m/s): the "
                         f"path asks the rotors for speeds outside {SPEED_BOUNDS[0]:g}-"
                         f"{SPEED_BOUNDS[1]:g}x hover at {span.size} samples "
                         f"(t {span.min():.3f}-{span.max():.3f} s)")
    hover = hover_speed(params)
    if commands not in ("max_speed", "fly"):
        raise ValueError(f"synthetic_flight: commands {commands!r}: 'max_speed' or 'fly'")
    command = _commanded_speeds(t, speed_, effect_set, hover, vbat)      # rad/s
    unit = 1.0
    if commands == "max_speed":
        command, unit = command / params.max_speed, params.max_speed
    if load_share:
        # a DC motor: u V = k Omega + (R d / k) Omega^2, s = R d h / k^2 at hover h
        # (quadsim.gap.residual.load_exponent), scaled to the same command at hover
        command = command * (1.0 + load_share * command * unit / hover) / (1.0 + load_share)
    if commands == "fly":       # quadsim.fly's convention, through its own code
        command, _ = logged_command(params, command, vbat)
    keep = slice(pad, len(t) - pad)
    t, position, velocity, quat, rate, specific, speed_, command, vbat = (
        a[keep] for a in (t, position, velocity, quat, rate, specific, speed_, command, vbat))
    if noise is not None:
        n = len(t)
        position = position + noise.position * rng.standard_normal((n, 3))
        velocity = velocity + noise.velocity * rng.standard_normal((n, 3))
        tilt = np.concatenate([np.ones((n, 1)),
                               0.5 * noise.attitude * rng.standard_normal((n, 3))], 1)
        quat = quat_normalize(quat_multiply(quat, tilt))
        rate = rate + noise.gyro * rng.standard_normal((n, 3))
        specific = specific + noise.accel * rng.standard_normal((n, 3))
        speed_ = speed_ + noise.rotor * hover * rng.standard_normal(speed_.shape)
        vbat = vbat + noise.vbat * rng.standard_normal(n)
    quat = np.where(quat[:, :1] < 0, -quat, quat)
    return FlightLog(t, position, quat, velocity, rate, specific, speed_, command, vbat, None)


#: a path the rotors cannot fly is flown again this much slower (:func:`flown_slower`), up to
#: :data:`SLOWER_TRIES` times: its log would otherwise hold rotor speeds that do not produce
#: its motion, which no effect explains
SLOWER = 0.9
SLOWER_TRIES = 5


def flown_slower(fly: Callable[[float], T], speed: float) -> tuple[T, float]:
    """``(fly(v), v)`` for the first path speed v (m/s) of ``speed``, ``SLOWER`` x ``speed``,
    ... (:data:`SLOWER_TRIES` tries) at which ``fly`` raises no :class:`NotFlyable`; ``fly``
    flies one case's flights at a path speed with ``flyable_only=True``. The same seeds fly
    the same path shapes slower, so a benchmark's other cases and draws stay as they were.
    Raises the last :class:`NotFlyable` where no try flies."""
    for _ in range(SLOWER_TRIES):
        try:
            return fly(speed), speed
        except NotFlyable:
            speed *= SLOWER
    return fly(speed), speed


def flyable_flight(params: VehicleParams, effects: Sequence[Effect] = (), *, speed: float,
                   **kwargs) -> FlightLog:
    """:func:`synthetic_flight` of ``effects`` at path ``speed`` (m/s) with ``flyable_only``,
    flown slower where the rotors cannot fly that path (:func:`flown_slower`: the same seed,
    the same path's shape; a path they can fly is the flight ``synthetic_flight`` gives);
    ``kwargs`` are ``synthetic_flight``'s. Raises :class:`NotFlyable` where the last speed
    too is refused."""
    return flown_slower(lambda v: synthetic_flight(params, effects, speed=v, flyable_only=True,
                                                   **kwargs), speed)[0]


def commands_through_map(log, params):
    """``log`` with its commands replaced by those ``params``' motor map turns into its logged
    rotor speeds: the map inverted per rotor at the logged battery voltage (its voltage law)
    after a first-order lead of the map's time constant (the command model lags by it), so
    ``quadsim.gap.logcheck.command_model_from_params(params)`` gives the speeds back. What a
    vehicle whose motors follow the set's map *with its time constant* would log, for a run
    that reads the commands through the set's own command model, lag included (command-only,
    CHANGELOG.md, the speed benchmark). :func:`synthetic_flight` (as
    ``quadsim.logs.generate``) writes the map's command of the commanded speed itself by
    default (``commands="fly"``; no lead: its vehicle has no motor lag unless a
    ``motor_lag`` effect is flown), ``speed / max_speed`` with ``commands="max_speed"``.
    The inverse is the set's own,
    ``MotorMap.command_at`` (normalised as ``quadsim.gap.residual.command_of_speed``)."""
    mm = params.motor_map
    speed = np.asarray(log.rotor_speed, float)
    steady = speed + mm.time_constant * np.gradient(speed, log.t, axis=0)
    command = mm.normalised(mm.command_at(steady, log.vbat))
    return replace(log, rotor_command=command)
