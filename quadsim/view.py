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
from .vehicle.params import VehicleParams, load_params
from .vehicle.state import Trajectory

__all__ = ["main", "step_flight", "replay_log", "step_reference"]

ENGINES = ("mujoco", "analytic")


def step_reference(t: np.ndarray, *, start=(0.0, 0.0, 1.0), step_x: float = 0.5,
                   step_z: float = 0.5, step_yaw: float = 0.5) -> np.ndarray:
    """Desired 12-state (B, 12) at times t (B,): hover at ``start``, x step (m) at 1 s, z step
    (m) at 3 s, yaw step (rad) at 5 s."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    target = np.zeros((len(t), 12))
    target[:, :3] = start
    target[:, 0] += np.where(t >= 1.0, step_x, 0.0)
    target[:, 2] += np.where(t >= 3.0, step_z, 0.0)
    target[:, 8] = np.where(t >= 5.0, step_yaw, 0.0)
    return target


def step_flight(params: VehicleParams, *, engines=ENGINES, duration: float = 7.0,
                control_period: float = 0.01) -> dict[str, Trajectory]:
    """LQR hover-and-step flight (:func:`step_reference`) in each engine."""
    from .sim.engines import initial_state, simulate
    from .sim.linear import LQRController

    controller = LQRController(params, position=(0.0, 0.0, 1.0), reference=step_reference)
    start = initial_state(position=(0.0, 0.0, 1.0))
    return {engine: simulate(params, engine=engine, initial=start, controller=controller,
                             duration=duration, control_period=control_period)
            for engine in engines}


def _segments(t: np.ndarray, horizon: float, period: float) -> tuple[np.ndarray, int]:
    """Start times of the shooting segments and the number of control periods in each."""
    span = t[-1] - t[0]
    horizon = span if horizon <= 0 or horizon > span else horizon
    steps = max(1, int(round(horizon / period)))
    count = max(1, int(np.floor(span / (steps * period) + 1e-9)))
    return t[0] + np.arange(count) * steps * period, steps


def _interp(t_from: np.ndarray, values: np.ndarray, t_to: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t_to, t_from, values[:, k]) for k in range(values.shape[1])], -1)


def replay_log(params: VehicleParams, measured: Trajectory, *, engines=ENGINES,
               horizon: float = 1.0) -> dict[str, Trajectory]:
    """Drive the model with the measured rotor speeds (zero-order hold at the log's median
    sample period), restarting from the measured state every ``horizon`` s (<= 0: one run
    over the whole log). All segments run as one batch; the result is stitched back into one
    trajectory per engine (segment ends dropped where the next segment starts)."""
    from .sim.engines import initial_state, simulate

    t = np.asarray(measured.t, dtype=float)
    if measured.rotor_speed.shape[-1] != params.rotor_count:
        raise InputError(f"log has {measured.rotor_speed.shape[-1]} rotor speed columns, model "
                         f"{params.name!r} has {params.rotor_count} rotors (rotor_1..rotor_"
                         f"{params.rotor_count} in rad/s are needed to drive it)")
    period = float(np.median(np.diff(t)))
    starts, steps = _segments(t, horizon, period)
    grid = starts[:, None] + np.arange(steps)[None, :] * period  # (B, steps)
    series = _interp(t, measured.rotor_speed, grid.ravel()).reshape(len(starts), steps, -1)
    quat = _interp(t, measured.quat, starts)
    start = initial_state(position=_interp(t, measured.position, starts),
                          velocity=_interp(t, measured.velocity, starts),
                          quat=quat / np.linalg.norm(quat, axis=-1, keepdims=True),
                          body_rate=_interp(t, measured.body_rate, starts),
                          rotor_speed=series[:, 0])
    return {engine: _stitch(simulate(params, engine=engine, initial=start,
                                     rotor_speed_series=series, duration=steps * period,
                                     control_period=period, batch=len(starts)), starts)
            for engine in engines}


def _stitch(batch: Trajectory, starts: np.ndarray) -> Trajectory:
    """One trajectory from a (B, n+1) batch of consecutive segments starting at ``starts``."""
    last = len(starts) - 1

    def join(values):
        if values is None:
            return None
        return np.concatenate([values[i, : None if i == last else -1] for i in range(last + 1)])

    t = np.concatenate([starts[i] + batch.t[: None if i == last else -1]
                        for i in range(last + 1)])
    return Trajectory(t, join(batch.position), join(batch.velocity), join(batch.quat),
                      join(batch.body_rate), join(batch.rotor_speed), join(batch.rotor_command),
                      batch.engine, dict(batch.meta))


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
                             "speeds in rad/s); without it a hover-and-step LQR flight is simulated")
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

    log, notes = check_log(load_log(path), params)
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
