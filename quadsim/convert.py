"""``python -m quadsim.convert LOG -o OUT.csv.gz|.csv|.parquet``: a PX4 ULog, Crazyflie uSD or
ArduPilot DataFlash file (or one of our own logs) -> the quadsim flight-log schema.

The format comes from the first bytes of the file, else the name (``--format`` forces it);
the importers are :mod:`quadsim.logs` (resampling, frames, units: see there and
docs/logs.md). The result is validated exactly like a CSV log (:mod:`quadsim.logs.flightlog`) and
written atomically.

    python -m quadsim.convert sample_px4_events.ulg -o px4.csv.gz
    python -m quadsim.convert eckart00 -o flight_00.parquet --rotor-map 1,2,3,4
    python -m quadsim.convert f.ulg -o f.csv.gz --rate 250 --start 19 --end 26
    python -m quadsim.convert copter.bin -o copter.csv.gz --pwm-range 1100,1900
    python -m quadsim.convert f.ulg -o f.csv.gz --topic body_rate=vehicle_angular_velocity \\
        --field body_rate=xyz --model crazyflie21

Options: ``--topic SIGNAL=TOPIC`` and ``--field SIGNAL=FIELD`` (ULog; SIGNAL one of
position, velocity, quat, body_rate, accel, rotor_speed, rotor_command, vbat; for uSD
``--topic event=NAME`` picks the event), ``--rotor-map`` (our rotor i <- log motor m_i,
1-based; our own CSV/Parquet logs too), ``--pwm-range LO,HI`` (us), ``--model`` (below),
``--start``/``--end`` (s: keep only that part, e.g. the airborne part; time restarts at 0).
Errors: one line naming the file and the topic/field, exit 2, nothing written.

``--model NAME`` checks the converted log as ``gap`` and ``view`` will read it, with the same
function (:func:`quadsim.logs.checks.check_log`, on the log's airborne span): a multirotor
with the set's rotor count, the gyro against the attitude (unit, sign, axes, a body rate
logged in the world frame), the accelerometer, ``b sum(Omega^2)`` against the weight and the
rotor order by the torque balance under every permutation of the rotor columns. A log those
checks refuse is refused here too (``gap`` would refuse it): a wrong rotor order names the
``--rotor-map`` that fixes it. Their notes (a flight too gentle to check the gyro) are
``warning:`` lines; the log is written whole (the spans ``gap`` cuts stay in it).
"""

from __future__ import annotations

import argparse
import dataclasses
import warnings
from pathlib import Path

import numpy as np

from .core.args import ArgumentParser, check_number, check_output
from .core.errors import InputError, QuadsimWarning, run_cli
from .logs import FORMATS, detect_format, parse_rotor_map, read_columns
from .logs.attitude import CONVENTIONS
from .logs.checks import check_log
from .logs.common import map_rotors
from .logs.flightlog import LOG_SUFFIXES, log_from_columns, read_log_columns, write_log
from .logs.ulog import TOPICS

#: highest --rate (Hz): above any flight controller's logging rate.
MAX_RATE_HZ = 100_000.0


def _pairs(items: list[str], flag: str, allowed) -> dict[str, str]:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not value or key not in allowed:
            raise InputError(f"{flag}: {item!r}: expected SIGNAL=NAME with SIGNAL one of "
                             f"{', '.join(allowed)}")
        out[key] = value
    return out


def _range(text: str | None) -> tuple[float, float] | None:
    if not text:
        return None
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--pwm-range: {text!r}: expected LO,HI in us, e.g. 1000,2000"
                         ) from None
    if not lo < hi:
        raise InputError(f"--pwm-range: {text!r}: LO must be below HI")
    return lo, hi


def convert(source: str | Path, output: str | Path, *, fmt: str | None = None,
            rotor_map=None, topics=None, fields=None, pwm_range=None, model=None,
            start: float | None = None, end: float | None = None, rate_hz: float | None = None,
            euler: str | None = None):
    """Read, validate and write; returns the FlightLog. Nothing is written on error, and
    never over the input (``output`` may not be ``source``). ``start``/``end`` (s, on the
    converted log's time axis) keep only that part; time then restarts at 0. The importer's
    notes (spans lost, a vehicle that is not a multirotor) are warned as
    :class:`~quadsim.core.errors.QuadsimWarning`; ``model`` refuses a log that ``gap`` would
    refuse with that set (see the module doc)."""
    source, output = Path(source), Path(output)
    check_output("-o", output, LOG_SUFFIXES, inputs=[source])
    check_number("--rate", rate_hz, low=0.0, high=MAX_RATE_HZ, unit="Hz")
    check_number("--start", start, low=0.0, low_inclusive=True, unit="s")
    check_number("--end", end, low=0.0, unit="s")
    if start is not None and end is not None and not start < end:
        raise InputError(f"--start {start:g} s, --end {end:g} s: --start must be before --end")
    if fmt is None:
        fmt = detect_format(source) or "csv"
    if fmt == "csv":
        columns = read_log_columns(source)
    else:
        columns = read_columns(source, fmt=fmt, rotor_map=rotor_map, topics=topics,
                               fields=fields, pwm_range=pwm_range, rate_hz=rate_hz,
                               euler=euler)
    if start is not None or end is not None:
        t = columns["t"]
        keep = (t >= (start if start is not None else -np.inf)) & \
               (t <= (end if end is not None else np.inf))
        if keep.sum() < 2:
            raise InputError(f"{source}: t: --start/--end keep {int(keep.sum())} sample(s) "
                             f"of {t[0]:g}..{t[-1]:g} s")
        columns = {k: v[keep] for k, v in columns.items()}
        columns["t"] = columns["t"] - columns["t"][0]
    log = log_from_columns(source, columns, warn=False)
    if fmt == "csv" and rotor_map is not None:     # the importers map the foreign formats
        log = dataclasses.replace(
            log, rotor_speed=map_rotors(source, "rotor_*", log.rotor_speed, rotor_map),
            rotor_command=map_rotors(source, "cmd_*", log.rotor_command, rotor_map))
    notes = list(log.notes)
    if model is not None:       # gap's and view's checks; the notes of what they cut are theirs
        from .vehicle.params import load_params
        checked, found = check_log(log, load_params(model))
        notes += [n for n in found if n not in checked.notes]
    for note in notes:
        warnings.warn(note, QuadsimWarning, stacklevel=2)
    write_log(output, log)
    return log


def _parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="python -m quadsim.convert",
        description="Convert a PX4 ULog, Crazyflie uSD or ArduPilot DataFlash log to the "
                    "quadsim flight-log schema (CSV, gzipped CSV or Parquet).")
    parser.add_argument("log", help="input log file")
    parser.add_argument("-o", "--output", required=True, help="OUT.csv, OUT.csv.gz or "
                        "OUT.parquet")
    parser.add_argument("--format", choices=FORMATS + ("csv",), default=None,
                        help="force the input format (default: from magic bytes / name)")
    parser.add_argument("--topic", action="append", default=[], metavar="SIGNAL=TOPIC",
                        help="ULog topic of a signal (repeatable); uSD: event=NAME, "
                        "pose=estPose (motion-capture pose)")
    parser.add_argument("--field", action="append", default=[], metavar="SIGNAL=FIELD",
                        help="ULog field (prefix) of a signal (repeatable)")
    parser.add_argument("--rotor-map", default=None, metavar="M1,M2,...",
                        help="log motor number of our rotor 1, 2, ... (1-based)")
    parser.add_argument("--pwm-range", default=None, metavar="LO,HI",
                        help="PWM pulse range in us for normalising motor outputs")
    parser.add_argument("--rate", type=float, default=None, metavar="HZ",
                        help="ULog: uniform time base at HZ (default: attitude instants)")
    parser.add_argument("--start", type=float, default=None, metavar="S",
                        help="keep samples from this time (s, converted log's time)")
    parser.add_argument("--end", type=float, default=None, metavar="S",
                        help="keep samples up to this time (s)")
    parser.add_argument("--euler", choices=CONVENTIONS, default=None,
                        help="uSD: convention of stateEstimate.roll/pitch/yaw when no "
                        "quaternion is logged (default crazyflie: FLU, pitch logged nose-up "
                        "positive; flu; frd); checked against the gyro")
    parser.add_argument("--model", default=None, help="parameter set to check the log "
                        "against as gap does: rotor count, gyro (unit, axes, frame), "
                        "accelerometer, rotor speeds vs weight, rotor order")
    return parser


@run_cli
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    signals = tuple(TOPICS) + ("event", "pose")
    log = convert(args.log, args.output, fmt=args.format,
                  rotor_map=parse_rotor_map(args.rotor_map),
                  topics=_pairs(args.topic, "--topic", signals),
                  fields=_pairs(args.field, "--field", tuple(TOPICS)),
                  pwm_range=_range(args.pwm_range), model=args.model, start=args.start,
                  end=args.end, rate_hz=args.rate, euler=args.euler)
    what = "" if log.has_pose else (
        "; IMU + motors with the attitude, no position: identify --logs and gap use the "
        "body-frame balance and the attitude, nothing that needs the speed or height"
        if log.has_attitude else "; IMU + motors, no pose: identify --logs and gap use the "
        "body-frame balance, nothing that needs the world frame")
    print(f"wrote {args.output} ({len(log)} samples, {log.t[-1]:.2f} s, "
          f"{log.rotor_count} rotors{what})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
