"""Synthetic flight logs: fly a parameter set in closed loop with hidden effects, log like a sensor.

:func:`generate_flight` flies a reference path (:mod:`quadsim.sim.paths`) with a tracking
controller that knows only the *nominal* parameter set, in the MuJoCo engine (or the analytic
one), while the simulated vehicle carries any set of effects (:mod:`quadsim.effects`). The
states are logged in the flight-log schema (:mod:`quadsim.logs.flightlog`) through sensor
models (:mod:`quadsim.logs.sensors`); the ground truth (effects and values, sensors, path,
seed, :func:`flight_report`) is returned separately so that a diagnosis can be run blind.
Same inputs -> same bytes. The command ``python -m quadsim.fly`` is its CLI.

Logged signals: position, velocity, attitude, body rate, rotor speeds (actual), commands
(:func:`logged_command`: normalised 0-1; ``commanded speed / max_speed``, or, where the
parameter set carries a motor map, the command its map gives for the commanded speed at the
logged battery voltage), battery voltage (from ``battery_sag`` if present, else the
vehicle's full voltage, :func:`quadsim.effects.battery_sag.nominal_voltage`, constant; a
``battery_sag`` made without a ``full_voltage`` starts from that same vehicle's voltage, not
from the effect's one-cell default, :func:`on_pack`) and the
accelerometer's specific force in the body frame at the body origin, ``R^T (a + g e3)``
(about +g on z at rest), computed exactly from the Newton-Euler forces (rotors + effects) at
each sample.

Example::

    >>> from quadsim.logs.generate import generate_flight
    >>> log, truth = generate_flight(params, "figure8", effects, sensors, seed=0, duration=10)
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..core.errors import InputError
from ..core.frames import quat_to_rotmat
from ..effects import EffectSet, describe_effects
from ..effects.base import EffectContext
from ..effects.battery_sag import BatterySag, nominal_voltage
from ..sim.analytic import BatchEffects, body_arrays, extra_wrench, rigid_body_accelerations
from ..sim.controllers import GeometricController
from ..sim.engines import simulate
from ..sim.paths import Reference, make_reference
from ..vehicle.params import VehicleParams
from ..vehicle.state import Trajectory
from .flightlog import FlightLog
from .sensors import SensorModel

__all__ = ["CONTROLLERS", "TRUTH_SCHEMA", "command_convention", "describe_report",
           "effect_states", "flight_report", "generate_flight", "logged_command", "on_pack",
           "specific_force", "truth_path"]

CONTROLLERS = ("geometric", "lqr")
TRUTH_SCHEMA = "quadsim.flight-truth/1"


def specific_force(params: VehicleParams, effects: EffectSet, traj: Trajectory) -> np.ndarray:
    """Accelerometer specific force (N, 3) in the body frame (m/s^2) of a (single) flight:
    all non-gravitational forces per unit mass, at the body origin, from the same
    Newton-Euler terms and effect hooks the engines use (``params`` already effect-modified)."""
    n = len(traj.t)
    one = body_arrays([params])
    body = type(one)(**{k: (v if k == "rotor_spin" else np.repeat(v, n, axis=0))
                        for k, v in vars(one).items()})
    command = traj.rotor_command if traj.rotor_command is not None else traj.rotor_speed
    hooks = BatchEffects(effects, [params] * n)
    rate = (hooks.rotor_speed_rate(traj.t, command, traj.rotor_speed) if hooks.rotor_dynamics
            else np.zeros_like(traj.rotor_speed))
    states = effect_states(params, effects, traj) if effects.state_size() else None
    loads = hooks.loads(traj.t, traj.position, traj.velocity, traj.quat, traj.body_rate,
                        traj.rotor_speed, rate, states)
    force_body, torque_body = extra_wrench(body, loads, traj.rotor_speed)
    wrench = np.einsum("bkr,br->bk", body.allocation, np.square(traj.rotor_speed))
    accel, _ = rigid_body_accelerations(body, traj.quat, traj.body_rate,
                                        wrench[:, :3] + force_body, wrench[:, 3:] + torque_body,
                                        loads.force_world)
    accel[:, 2] += params.gravity
    return np.einsum("nji,nj->ni", quat_to_rotmat(traj.quat), accel)


#: step (s) at most of the RK4 integration of effect states along a flown trajectory (a
#: cable's axial bounce at 20 Hz: omega h = 0.3, well inside RK4's stability limit 2.8).
STATE_STEP_S = 2.5e-3


def effect_states(params: VehicleParams, effects: EffectSet, traj: Trajectory) -> np.ndarray:
    """Internal effect states (N, S) along a single flown trajectory (a cable payload's
    position and velocity), for the accelerometer model: they are not part of the
    trajectory, but their rate depends only on the vehicle's motion and on themselves, so
    they are integrated again along it (RK4, steps of at most :data:`STATE_STEP_S`, the
    vehicle state linearly interpolated between samples, the quaternion renormalised), from
    the same start as the engines (``initial_state``). The difference from the engine's own
    state is the interpolation error of the motion: on a 5 s figure-8 of the Crazyflie with
    a 7.4 g payload on a 0.5 m cable, the world acceleration the logged accelerometer gives
    matches the central difference of the logged velocity as closely as with a rigid 7.4 g
    mass (RMS 2e-3 m/s^2, the difference's own error; ``tests/test_payload_evidence.py``)."""
    n = len(traj.t)
    steps = max(1, int(np.ceil(np.max(np.diff(traj.t)) / STATE_STEP_S - 1e-9)))
    # the vehicle at every RK4 stage time: fractions u of each interval (n - 1, 2 steps + 1)
    u = np.linspace(0.0, 1.0, 2 * steps + 1)

    def stages(x):
        return (x[:-1, None] * (1 - u)[:, None] + x[1:, None] * u[:, None]
                if x.ndim == 2 else x[:-1, None] * (1 - u) + x[1:, None] * u)

    t = stages(traj.t)
    pos, vel, rate = stages(traj.position), stages(traj.velocity), stages(traj.body_rate)
    quat = stages(traj.quat)
    quat = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    still = np.zeros((1, traj.rotor_speed.shape[1]))
    vbat = np.full(1, np.nan)

    def derivative(k, j, y):
        ctx = EffectContext(t[k, j:j + 1], pos[k, j:j + 1], vel[k, j:j + 1], quat[k, j:j + 1],
                            rate[k, j:j + 1], vel[k, j:j + 1], still, still, params, vbat, y)
        return effects.state_rate(ctx)

    state = effects.initial_state(params, {"position": traj.position[:1],
                                           "velocity": traj.velocity[:1],
                                           "quat": traj.quat[:1],
                                           "body_rate": traj.body_rate[:1]})
    out = np.empty((n, state.shape[1]))
    out[0] = state[0]
    for k in range(n - 1):
        h = float(traj.t[k + 1] - traj.t[k]) / steps
        for j in range(0, 2 * steps, 2):
            k1 = derivative(k, j, state)
            k2 = derivative(k, j + 1, state + 0.5 * h * k1)
            k3 = derivative(k, j + 1, state + 0.5 * h * k2)
            k4 = derivative(k, j + 2, state + h * k3)
            state = state + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        out[k + 1] = state[0]
    return out


#: Limits of :func:`flight_report` beyond which ``fly`` refuses the path (see its docstring).
MAX_SATURATED_FRACTION = 0.05
MAX_TILT_DEG = 60.0


def flight_report(params: VehicleParams, reference: Reference, traj: Trajectory) -> dict:
    """What the vehicle actually did on a (single) flight, in numbers.

    * ``saturated_fraction``: share of samples with any rotor command at the end of the
      speed range (``>= (1 - 1e-6) max_speed`` or ``<= min_speed``); the controller asked for
      more than the rotors can give.
    * ``peak_tilt_deg``: largest angle between body z and world z, ``acos(1 - 2 (x^2 + y^2))``
      of the quaternion (deg).
    * ``tracking_error_rms_m`` / ``tracking_error_max_m``: distance to the reference
      position (m).
    * ``diverged``: a non-finite state, a tilt beyond 90 deg, or a final tracking error above
      ``max(1 m, path size)``.
    * ``feasible``: not diverged, saturated below :data:`MAX_SATURATED_FRACTION` and peak
      tilt below :data:`MAX_TILT_DEG`.
    """
    command = traj.rotor_command if traj.rotor_command is not None else traj.rotor_speed
    top = command >= (1 - 1e-6) * params.max_speed
    bottom = command <= params.min_speed * (1 + 1e-6) if params.min_speed > 0 else command <= 0
    saturated = float(np.mean(np.any(top | bottom, axis=-1)))
    q = traj.quat
    cos_tilt = np.clip(1 - 2 * (q[..., 1] ** 2 + q[..., 2] ** 2), -1, 1)
    tilt = float(np.degrees(np.max(np.arccos(cos_tilt)))) if np.all(np.isfinite(q)) else 180.0
    error = np.linalg.norm(traj.position - reference(traj.t).position, axis=-1)
    finite = bool(np.all(np.isfinite(traj.position)) and np.all(np.isfinite(q)))
    size = float(reference.settings.get("size", 1.0) or 1.0)
    diverged = (not finite) or tilt > 90.0 or float(error[-1]) > max(1.0, size)
    return {
        "saturated_fraction": round(saturated, 6),
        "peak_tilt_deg": round(tilt, 4),
        "tracking_error_rms_m": round(float(np.sqrt(np.mean(error ** 2))), 6) if finite else None,
        "tracking_error_max_m": round(float(np.max(error)), 6) if finite else None,
        "final_height_m": round(float(traj.position[-1, 2]), 6) if finite else None,
        "diverged": bool(diverged),
        "feasible": bool(not diverged and saturated < MAX_SATURATED_FRACTION
                         and tilt < MAX_TILT_DEG),
        "limits": {"saturated_fraction": MAX_SATURATED_FRACTION, "peak_tilt_deg": MAX_TILT_DEG},
    }


def describe_report(report: dict) -> str:
    error = report["tracking_error_max_m"]
    return (f"{100 * report['saturated_fraction']:.0f} % of samples saturated, peak tilt "
            f"{report['peak_tilt_deg']:.0f} deg, max tracking error "
            f"{'inf' if error is None else f'{error:.3g}'} m, final height "
            f"{report['final_height_m']:.3g} m" + (", diverged" if report["diverged"] else ""))


def _lqr(params: VehicleParams, reference: Reference):
    from ..sim.linear import LQRController

    def target(t):
        s = reference(np.atleast_1d(t))
        cy, sy = np.cos(s.yaw), np.sin(s.yaw)
        ax = cy * s.acceleration[..., 0] + sy * s.acceleration[..., 1]
        ay = -sy * s.acceleration[..., 0] + cy * s.acceleration[..., 1]
        g = params.gravity
        euler = np.stack([-ay / g, ax / g, s.yaw], -1)   # small-angle attitude for a_d
        rates = np.stack([np.zeros_like(s.yaw)] * 2 + [s.yaw_rate], -1)
        return np.concatenate([s.position, s.velocity, euler, rates], -1)

    return LQRController(params, reference=target)


def on_pack(effects: EffectSet, params: VehicleParams) -> EffectSet:
    """``effects`` with each ``battery_sag`` made without a ``full_voltage`` given that of the
    vehicle's pack (:func:`quadsim.effects.battery_sag.nominal_voltage`: 12.6 V for the 0.84 kg
    testbed's 3S pack), so that a sag flight's logged voltage starts where the vehicle's
    nominal flights log theirs; the effect's default (4.2 V, one cell) is kept only for a
    one-cell vehicle, where the two agree. A given ``full_voltage`` is kept as given."""
    out = []
    for effect in effects.effects:
        if isinstance(effect, BatterySag) and "full_voltage" not in effect.given():
            effect = BatterySag(**{k: v for k, v in effect.values().items() if k in effect.given()},
                                full_voltage=nominal_voltage(params))
        out.append(effect)
    return dataclasses.replace(effects, effects=tuple(out)) if out else effects


def _battery_voltage(effects: EffectSet, t: np.ndarray, params: VehicleParams) -> np.ndarray:
    for effect in effects.effects:
        if isinstance(effect, BatterySag):
            return effect.voltage(t)
    return np.full(len(t), nominal_voltage(params))


def logged_command(params: VehicleParams, speed: np.ndarray,
                   vbat: np.ndarray) -> tuple[np.ndarray, dict]:
    """The normalised commands (N, R) a log records for commanded rotor speeds ``speed``
    (N, R) (rad/s) flown at battery voltages ``vbat`` (N,) (V), and the truth sidecar's
    record of the convention (:func:`command_convention` reads it back).

    * A set without a motor map: ``speed / max_speed``; recorded as
      ``command_normalisation`` (max_speed, rad/s), as in every sidecar before.
    * A set with one (``VehicleParams.motor_map``): the command the set's own map gives for
      the speed at ``vbat`` (``MotorMap.command_at``, the inverse of ``MotorMap.speed_at``,
      normalised as :func:`quadsim.gap.residual.command_of_speed` does it), the voltage the
      log records before its vbat sensor's noise, bias and quantisation; so
      ``speed_at(command, vbat)`` gives the commanded speed back, and a reader of the log
      with the same set (``gap --model``, ``identify --logs``, command-only diagnosis) reads
      the vehicle that flew it. Recorded as ``command_map`` (the set, the map's source, its
      voltage law, the range of the voltages it was read at). InputError where a rotor's
      map speed falls as its command rises (no inverse)."""
    mm = params.motor_map
    if mm is None:
        return (speed / params.max_speed,
                {"command_normalisation": {"max_speed": params.max_speed, "unit": "rad/s"}})
    falling = np.flatnonzero(np.any(np.diff(mm.speed, axis=1) < 0, axis=1))
    if len(falling):
        raise InputError(f"{params.path or params.name}: motor_map.speed: rotor "
                         f"{falling[0] + 1}'s speed falls along the command axis: the map has "
                         "no inverse to log the commands of a speed")
    vbat = np.asarray(vbat, float)
    record = {"convention": "motor_map", "model": params.name, "source": mm.source,
              "command_unit": mm.command_unit,
              "reference_voltage_v": mm.reference_voltage, "voltage_gain_per_v": mm.voltage_gain,
              "voltage": "the log's vbat before the vbat sensor's noise, bias and quantisation",
              "vbat_range_v": [round(float(np.min(vbat)), 6), round(float(np.max(vbat)), 6)]}
    return mm.normalised(mm.command_at(speed, vbat)), {"command_map": record}


def command_convention(truth: dict) -> dict:
    """How a generated log's commands were written, from its truth sidecar: ``{"convention":
    "motor_map", ...}`` (:func:`logged_command`'s ``command_map``) or ``{"convention":
    "max_speed", "max_speed": rad/s}`` (``command_normalisation``: every sidecar written
    before the motor-map convention, whatever its set). InputError if it has neither."""
    if "command_map" in truth:
        return dict(truth["command_map"])
    if "command_normalisation" in truth:
        return {"convention": "max_speed",
                "max_speed": float(truth["command_normalisation"]["max_speed"])}
    raise InputError("truth sidecar: command_normalisation / command_map: missing (not a "
                     f"{TRUTH_SCHEMA} sidecar?)")


def generate_flight(params: VehicleParams, path: str | Reference, effects: EffectSet | None,
                    sensors: SensorModel | None, seed: int, *, engine: str = "mujoco",
                    duration: float = 20.0, control_period: float = 0.005, speed: float = 1.0,
                    height: float = 1.0, size: float = 1.0,
                    controller: str = "geometric",
                    progress=None) -> tuple[FlightLog, dict]:
    """Fly ``params`` (nominal, what the controller knows) with ``effects`` (what the
    simulated vehicle has) along ``path``; return the sensor log and the ground truth.

    The truth carries ``flight_report`` (:func:`flight_report`): what the vehicle did.
    ``progress(t)`` (optional) is called with the simulated time after each control step."""
    effects = on_pack(effects or EffectSet(), params)
    sensors = sensors or SensorModel()
    reference = path if isinstance(path, Reference) else make_reference(
        path, speed=speed, height=height, size=size, duration=duration)
    if controller not in CONTROLLERS:
        raise InputError(f"unknown controller {controller!r}; valid: {', '.join(CONTROLLERS)}")
    geometric = GeometricController(params, reference)
    control = geometric if controller == "geometric" else _lqr(params, reference)
    if progress is not None:
        inner = control

        def control(t, state):  # same controller, reports the time
            progress(float(np.max(t)))
            return inner(t, state)
    traj = simulate(params, engine=engine, initial=geometric.initial_state(), controller=control,
                    duration=duration, control_period=control_period, effects=effects)
    truth_params = effects.apply_to_params(params)
    accel = specific_force(truth_params, effects, traj)
    vbat = _battery_voltage(effects, traj.t, params)
    command, convention = logged_command(params, traj.rotor_command, vbat)
    true_log = FlightLog(t=traj.t, position=traj.position, quat=traj.quat,
                         velocity=traj.velocity, body_rate=traj.body_rate, accel=accel,
                         rotor_speed=traj.rotor_speed, rotor_command=command, vbat=vbat)
    log = sensors.apply(true_log, seed=seed)
    truth = {
        "schema": TRUTH_SCHEMA, "model": params.name, "engine": engine,
        "controller": controller, "seed": int(seed), "duration_s": duration,
        "control_period_s": control_period,
        "path": {"name": reference.name, **reference.settings},
        "effects": describe_effects(effects), "sensors": sensors.to_json(),
        **convention,
        "flight_report": flight_report(params, reference, traj),
    }
    return log, truth


def truth_path(log_path: str | Path) -> Path:
    """``out/flight.csv.gz`` -> ``out/flight.csv.gz.truth.json``."""
    log_path = Path(log_path)
    return log_path.with_name(log_path.name + ".truth.json")
