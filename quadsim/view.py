"""``python -m quadsim.view``: make a rerun recording of a model flight, or of a real log
against a model.

Without ``--log``: a short LQR hover-and-step flight (steps on x, z and yaw) of the model in
both engines (MuJoCo and the analytic Newton-Euler model), logged together::

    python -m quadsim.view --model physical --rerun out/view.rrd
    rerun out/view.rrd                     # or: rerun --web-viewer out/view.rrd

With ``--log LOG.csv(.gz)`` (flight-log schema, docs/flightlog.md): the model is driven by the
log's measured rotor speeds, restarted from the measured state every ``--horizon`` seconds
(multiple shooting: an open-loop quadrotor drifts away within a second or two, so a single
open-loop run over a whole flight shows little), and the recording holds the model, the
measured flight and the residuals (model minus measured) of all 12 states::

    python -m quadsim.view --model crazyflie21 --log flight_00.csv.gz --rerun out/log.rrd

``--rerun-spawn`` also opens the native viewer where a display exists. Errors are one line on
stderr with exit status 2; nothing is written then.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .core.args import ArgumentParser
from .core.errors import InputError, ModelError, QuadsimError, run_cli
from .sim.replay import ENGINES, replay_log, step_flight, step_reference
from .vehicle.params import VehicleParams, load_params
from .vehicle.state import Trajectory

__all__ = ["main", "replay_log", "step_flight", "step_reference"]

def _parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="python -m quadsim.view",
        description="Write a rerun recording (.rrd) of a model flight in both engines, or of a "
                    "real flight log against the model, with residuals.",
        epilog="View the file with `rerun FILE.rrd`, headless with `rerun --web-viewer "
               "FILE.rrd` (docs/viewer.md).")
    parser.add_argument("--model", required=True,
                        help="parameter set: a name in models/ (physical, computational, ...) "
                             "or a path to a parameter TOML")
    parser.add_argument("--log", type=Path,
                        help="flight log (.csv, .csv.gz or .parquet, flight-log schema, rotor "
                             "speeds in rad/s); without it a hover-and-step LQR flight is "
                             "simulated")
    parser.add_argument("--rerun", type=Path, metavar="OUT.rrd",
                        help="recording to write (atomically)")
    parser.add_argument("--rerun-spawn", action="store_true",
                        help="also open the native rerun viewer (needs a display)")
    parser.add_argument("--engine", default="mujoco,analytic",
                        help="comma-separated engines to run (default: mujoco,analytic)")
    parser.add_argument("--duration", type=float,
                        help="step flight length (s); with --log: use at most this many "
                             "seconds of the log from its start (default: step 7 s, log all)")
    parser.add_argument("--horizon", type=float, default=1.0,
                        help="with --log: restart the model from the measured state every "
                             "HORIZON s (0: one open-loop run over the whole log); default 1")
    parser.add_argument("--tab", choices=("states", "rotors", "residuals"), default=None,
                        help="plot tab shown first (default: residuals with --log, else states)")
    parser.add_argument("--cad", type=Path,
                        help="CAD folder whose meshes draw the vehicle (default: the model's "
                             "from_cad folder if it has one, else simple shapes)")
    return parser


def _engines(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in ENGINES]
    if bad or not names:
        raise InputError(f"--engine: unknown engine(s) {bad or text!r}; valid: "
                         f"{', '.join(ENGINES)}")
    return names


def _load_model(name: str, engines: tuple[str, ...]) -> VehicleParams:
    try:
        return load_params(name)
    except ModelError as exc:
        if "mujoco" in engines:
            raise ModelError(f"{exc} (run with --engine analytic to view the analytic model "
                             "only)") from None
        return load_params(name, check=False)


def _measured(path: Path, duration: float | None, params=None) -> Trajectory:
    from .logs.checks import check_log  # channels against each other; NaN runs cut or refused
    from .logs.flightlog import load_log

    log, notes = check_log(load_log(path), params, joined=True)   # every stretch
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)
    measured = log.to_trajectory()
    if duration is not None:
        keep = measured.t <= measured.t[0] + duration
        if np.count_nonzero(keep) < 3:
            raise InputError(f"--duration {duration}: fewer than 3 samples of {path}")
        measured = Trajectory(measured.t[keep], measured.position[keep],
                              measured.velocity[keep], measured.quat[keep],
                              measured.body_rate[keep], measured.rotor_speed[keep], None,
                              measured.engine,
                              {**measured.meta, "command": None if measured.meta.get("command")
                               is None else measured.meta["command"][keep]})
    return measured


@run_cli
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from .core.args import check_inputs, check_number  # every argument before any work

    check_number("--duration", args.duration, low=0.0, unit="s")
    check_number("--horizon", args.horizon, low=0.0, low_inclusive=True, unit="s")
    check_inputs("--log", [args.log] if args.log is not None else None)
    if args.cad is not None and not args.cad.is_dir():
        raise InputError(f"{args.cad}: --cad: not a folder")
    if args.rerun is None and not args.rerun_spawn:
        raise InputError("give --rerun OUT.rrd and/or --rerun-spawn (nothing to do otherwise)")
    from .viewer import assembly_for, check_output_path, save_recording

    if args.rerun is not None:
        check_output_path(args.rerun)  # fail before simulating, not after
    engines = _engines(args.engine)
    params = _load_model(args.model, engines)
    if args.cad is not None:
        from .cad.assembly import load_assembly

        assembly = load_assembly(args.cad)
    else:
        assembly = assembly_for(params)
    if args.log is None:
        measured = None
        trajectories = step_flight(params, engines=engines, duration=args.duration or 7.0)
        title = f"{params.name}: LQR hover and steps"
    else:
        measured = _measured(args.log, args.duration, params)
        try:
            trajectories = replay_log(params, measured, engines=engines, horizon=args.horizon)
        except QuadsimError as exc:  # name the log when the message does not
            if str(args.log) in str(exc):
                raise
            raise type(exc)(f"{args.log}: {exc}") from None
        title = f"{params.name} vs {args.log.name}"
    written = save_recording(args.rerun, params=params, trajectories=trajectories,
                             measured=measured, spawn=args.rerun_spawn, assembly=assembly,
                             title=title, tab=args.tab or ("states" if args.log is None
                                                           else "residuals"))
    if written is not None:
        print(f"wrote {written} ({written.stat().st_size / 1e6:.2f} MB); view it with "
              f"`rerun {written}`")
    return 0


if __name__ == "__main__":
    sys.exit(main())
