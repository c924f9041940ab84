"""Flight generator: fly a parameter set in closed loop with hidden effects, log like a sensor.

``python -m quadsim.fly`` (and the library function :func:`generate_flight`) flies a
reference path (:mod:`quadsim.trajectories`) with a tracking controller that knows only the
*nominal* parameter set, in the MuJoCo engine (or the analytic one), while the simulated
vehicle carries any set of effects (:mod:`quadsim.effects`). The states are logged in the
flight-log schema (:mod:`quadsim.flightlog`) through sensor models (:mod:`quadsim.sensors`),
and the ground truth (effects and values, sensors, path, seed) goes to a separate sidecar
``<log>.truth.json`` so that a diagnosis can be run blind. Same inputs -> same bytes.

Logged signals: position, velocity, attitude, body rate, rotor speeds (actual), commands
(``cmd_i = commanded speed / max_speed``, normalised 0-1), battery voltage (from
``battery_sag`` if present, else its full voltage, constant) and the accelerometer's specific
force in the body frame at the body origin, ``R^T (a + g e3)`` (about +g on z at rest),
computed exactly from the Newton-Euler forces (rotors + effects) at each sample.

Example::

    python -m quadsim.fly --model physical --path figure8 --speed 1.0 --duration 20 \\
        --effect ground_effect:gain=1.5 --effect wind:vx=2,gust=0.5 \\
        --effect body_drag:cd_area=0.02 --sensor-noise position=1e-3,gyro=0.01 \\
        --seed 0 -o out/flight.csv.gz

    >>> from quadsim.fly import generate_flight
    >>> log, truth = generate_flight(params, "figure8", effects, sensors, seed=0, duration=10)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .analytic import BatchEffects, body_arrays, extra_wrench, rigid_body_accelerations
from .cliargs import ArgumentParser
from .controllers import GeometricController
from .effects import EffectSet, describe_effects, effect_set_from_specs
from .effects.battery_sag import BatterySag
from .engines import ENGINES, simulate
from .errors import InputError, run_cli
from .fileio import atomic_write_bytes, atomic_write_text
from .flightlog import LOG_SUFFIXES, FlightLog, log_file_bytes
from .frames import quat_to_rotmat
from .params import VehicleParams, load_params
from .sensors import SensorModel, parse_signal_values
from .trajectories import PATHS, Reference, make_reference
from .trajectory import Trajectory

__all__ = [
    "CONTROLLERS",
    "TRUTH_SCHEMA",
    "flight_report",
    "generate_flight",
    "main",
    "specific_force",
    "truth_path",
]

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
    loads = hooks.loads(traj.t, traj.position, traj.velocity, traj.quat, traj.body_rate,
                        traj.rotor_speed, rate)
    force_body, torque_body = extra_wrench(body, loads, traj.rotor_speed)
    wrench = np.einsum("bkr,br->bk", body.allocation, np.square(traj.rotor_speed))
    accel, _ = rigid_body_accelerations(body, traj.quat, traj.body_rate,
                                        wrench[:, :3] + force_body, wrench[:, 3:] + torque_body,
                                        loads.force_world)
    accel[:, 2] += params.gravity
    return np.einsum("nji,nj->ni", quat_to_rotmat(traj.quat), accel)


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


def _describe(report: dict) -> str:
    error = report["tracking_error_max_m"]
    return (f"{100 * report['saturated_fraction']:.0f} % of samples saturated, peak tilt "
            f"{report['peak_tilt_deg']:.0f} deg, max tracking error "
            f"{'inf' if error is None else f'{error:.3g}'} m, final height "
            f"{report['final_height_m']:.3g} m" + (", diverged" if report["diverged"] else ""))


def _lqr(params: VehicleParams, reference: Reference):
    from .linear import LQRController

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


def _battery_voltage(effects: EffectSet, t: np.ndarray) -> np.ndarray:
    for effect in effects.effects:
        if isinstance(effect, BatterySag):
            return effect.voltage(t)
    return np.full(len(t), BatterySag().full_voltage)


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
    effects = effects or EffectSet()
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
    command = traj.rotor_command / params.max_speed
    true_log = FlightLog(t=traj.t, position=traj.position, quat=traj.quat,
                         velocity=traj.velocity, body_rate=traj.body_rate, accel=accel,
                         rotor_speed=traj.rotor_speed, rotor_command=command,
                         vbat=_battery_voltage(effects, traj.t))
    log = sensors.apply(true_log, seed=seed)
    truth = {
        "schema": TRUTH_SCHEMA, "model": params.name, "engine": engine,
        "controller": controller, "seed": int(seed), "duration_s": duration,
        "control_period_s": control_period,
        "path": {"name": reference.name, **reference.settings},
        "effects": describe_effects(effects), "sensors": sensors.to_json(),
        "command_normalisation": {"max_speed": params.max_speed, "unit": "rad/s"},
        "flight_report": flight_report(params, reference, traj),
    }
    return log, truth


def truth_path(log_path: str | Path) -> Path:
    """``out/flight.csv.gz`` -> ``out/flight.csv.gz.truth.json``."""
    log_path = Path(log_path)
    return log_path.with_name(log_path.name + ".truth.json")


def _parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="python -m quadsim.fly", description=__doc__.split("\n\n")[0],
        epilog="Effects: NAME:param=value,... (see docs/effects.md; e.g. "
               "ground_effect:gain=1.5, motor_lag:time_constant=0.03). Sensor signals: "
               "position, velocity, attitude, gyro, accel, rotor, vbat (SI units).")
    parser.add_argument("--model", default="physical", help="built-in parameter set name or "
                        "TOML file (the nominal vehicle the controller knows; default physical)")
    parser.add_argument("--path", default="figure8", choices=PATHS, help="reference path")
    parser.add_argument("--speed", type=float, default=1.0, help="path speed (m/s)")
    parser.add_argument("--height", type=float, default=1.0, help="flight height (m)")
    parser.add_argument("--size", type=float, default=1.0, help="path size (m)")
    parser.add_argument("--duration", type=float, default=20.0, help="flight time (s)")
    parser.add_argument("--control-period", type=float, default=0.005,
                        help="controller period = log sample period before sensors (s)")
    parser.add_argument("--engine", default="mujoco", choices=ENGINES)
    parser.add_argument("--controller", default="geometric", choices=CONTROLLERS)
    parser.add_argument("--effect", action="append", default=[], metavar="SPEC",
                        help="effect on the simulated vehicle, repeatable")
    parser.add_argument("--sensor-noise", default="", metavar="SIG=STD,...",
                        help="white noise standard deviation per signal")
    parser.add_argument("--sensor-bias", default="", metavar="SIG=VALUE,...",
                        help="constant bias per signal (every axis)")
    parser.add_argument("--sensor-quantization", default="", metavar="SIG=STEP,...",
                        help="quantisation step per signal")
    parser.add_argument("--sensor-rate", type=float, default=None, help="log sample rate (Hz)")
    parser.add_argument("--sensor-delay", type=float, default=0.0, help="sensor delay (s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")
    parser.add_argument("--allow-saturation", action="store_true",
                        help="write the flight even when the path is beyond the vehicle "
                             "(saturated rotors, tilt > 60 deg, divergence); warns and records "
                             "it in the truth sidecar's flight_report")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("-o", "--output", required=True,
                        help="log file (.csv, .csv.gz or .parquet); truth goes to <output>.truth.json")
    return parser


def _check_args(args) -> None:
    """Every argument before any work (:mod:`quadsim.cliargs`)."""
    from .cliargs import check_number, check_output

    check_number("--duration", args.duration, low=0.0, high=24 * 3600.0, unit="s")
    check_number("--control-period", args.control_period, low=0.0, high=args.duration,
                 unit="s")
    check_number("--speed", args.speed, low=0.0, low_inclusive=True, high=1000.0, unit="m/s")
    check_number("--size", args.size, low=0.0, high=1e4, unit="m")
    check_number("--height", args.height, low=-1e4, high=1e4, unit="m")
    check_number("--sensor-rate", args.sensor_rate, low=0.0, high=1e6, unit="Hz")
    check_number("--sensor-delay", args.sensor_delay, low=0.0, low_inclusive=True,
                 high=args.duration, unit="s")
    check_output("-o/--output", args.output, LOG_SUFFIXES)
    check_output("-o/--output", truth_path(args.output))


@run_cli
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    output = Path(args.output)
    if not output.name.endswith(LOG_SUFFIXES):
        raise InputError(f"{output}: output must end in {', '.join(LOG_SUFFIXES)}")
    _check_args(args)
    params = load_params(args.model)
    effects = effect_set_from_specs(args.effect)
    sensors = SensorModel(
        noise=parse_signal_values(args.sensor_noise, flag="--sensor-noise"),
        bias=parse_signal_values(args.sensor_bias, flag="--sensor-bias", signed=True),
        quantization=parse_signal_values(args.sensor_quantization, flag="--sensor-quantization"),
        rate=args.sensor_rate, delay=args.sensor_delay)
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        # disable=None: no bar when stderr is not a terminal (logs, CI)
        bar = tqdm(total=round(args.duration, 3), desc="flying", unit="sim s", file=sys.stderr,
                   leave=False, disable=None,
                   bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} sim s "
                              "[{elapsed}<{remaining}]")

    def progress(t):
        if bar is not None:
            bar.update(round(t, 3) - bar.n)

    try:
        log, truth = generate_flight(params, args.path, effects, sensors, args.seed,
                                     engine=args.engine, duration=args.duration,
                                     control_period=args.control_period, speed=args.speed,
                                     height=args.height, size=args.size,
                                     controller=args.controller, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    report = truth["flight_report"]
    if not report["feasible"]:
        if not args.allow_saturation:
            raise InputError(
                f"--path {args.path} --speed {args.speed:g}: beyond vehicle "
                f"{params.path or params.name}: {_describe(report)}; nothing written (lower "
                "--speed/--size or pass --allow-saturation)")
        print(f"warning: path beyond the vehicle: {_describe(report)} (recorded in the truth "
              "sidecar's flight_report)", file=sys.stderr)
    data = log_file_bytes(output, log)
    truth_text = json.dumps(truth, indent=2, sort_keys=True) + "\n"
    atomic_write_bytes(output, data)
    atomic_write_text(truth_path(output), truth_text)
    print(f"wrote {output} ({len(log)} samples, {log.rotor_count} rotors) and "
          f"{truth_path(output).name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
