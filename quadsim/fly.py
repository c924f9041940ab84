"""Flight generator: fly a parameter set in closed loop with hidden effects, log like a sensor.

``python -m quadsim.fly`` (the CLI of :func:`quadsim.logs.generate.generate_flight`) flies a
reference path (:mod:`quadsim.sim.paths`) with a tracking controller that knows only the *nominal*
parameter set, in the MuJoCo engine (or the analytic one), while the simulated vehicle carries any
set of effects (:mod:`quadsim.effects`). The states are logged in the flight-log schema
(:mod:`quadsim.logs.flightlog`) through sensor models (:mod:`quadsim.logs.sensors`), and the ground
truth (effects and values, sensors, path, seed) goes to a separate sidecar ``<log>.truth.json`` so
that a diagnosis can be run blind. Same inputs -> same bytes.

The logged signals and their units are listed in :mod:`quadsim.logs.generate`.

Example::

    python -m quadsim.fly --model physical --path figure8 --speed 1.0 --duration 20 \\
        --effect ground_effect:gain=1.5 --effect wind:vx=2,gust=0.5 \\
        --effect body_drag:cd_area=0.02 --sensor-noise position=1e-3,gyro=0.01 \\
        --seed 0 -o out/flight.csv.gz

    >>> from quadsim.logs.generate import generate_flight
    >>> log, truth = generate_flight(params, "figure8", effects, sensors, seed=0, duration=10)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .core.args import ArgumentParser
from .core.errors import InputError, run_cli
from .core.files import atomic_write_bytes, atomic_write_text
from .effects import effect_set_from_specs
from .logs.flightlog import LOG_SUFFIXES, log_file_bytes
from .logs.generate import CONTROLLERS, describe_report, generate_flight, truth_path
from .logs.sensors import SensorModel, parse_signal_values
from .sim.engines import ENGINES
from .sim.paths import PATHS
from .vehicle.params import load_params

__all__ = ["main"]


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
                        help="log file (.csv, .csv.gz or .parquet); truth goes to "
                             "<output>.truth.json")
    return parser


def _check_args(args) -> None:
    """Every argument before any work (:mod:`quadsim.core.args`)."""
    from .core.args import check_number, check_output

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


def _check_effective(params, effects, specs) -> None:
    """The vehicle with the effects applied is a body: positive mass, positive-definite
    inertia (``mass_offset:mass=-1`` on a 0.84 kg vehicle is not)."""
    import numpy as np

    changed = effects.apply_to_params(params)
    what = "--effect " + " ".join(specs)
    if not changed.mass > 0:
        raise InputError(f"{what}: makes the vehicle's mass {changed.mass:.4g} kg (the "
                         f"parameter set has {params.mass:.4g} kg): no vehicle")
    if not np.all(np.linalg.eigvalsh(np.asarray(changed.inertia)) > 0):
        raise InputError(f"{what}: makes the vehicle's inertia not positive definite")


@run_cli
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    output = Path(args.output)
    if not output.name.endswith(LOG_SUFFIXES):
        raise InputError(f"{output}: output must end in {', '.join(LOG_SUFFIXES)}")
    _check_args(args)
    params = load_params(args.model)
    effects = effect_set_from_specs(args.effect)
    _check_effective(params, effects, args.effect)
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
                f"{params.path or params.name}: {describe_report(report)}; nothing written (lower "
                "--speed/--size or pass --allow-saturation)")
        print(f"warning: path beyond the vehicle: {describe_report(report)} (recorded in the truth "
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
