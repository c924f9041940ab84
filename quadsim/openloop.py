"""The report's open-loop experiment (section 4.4), done so that it means something.

``python -m quadsim.openloop --model physical`` starts the vehicle in the report's initial
state (z = 1 m, roll = pitch = yaw = 0.261 rad, Appendix D/F), feeds hover thrust plus a step
on one input channel at a time (collective thrust, roll / pitch / yaw torque, turned into
rotor speeds by the geometry-derived mixer) and simulates every case in MuJoCo and in the
analytic Newton–Euler model. Each channel's response is the difference between the stepped
run and the same start with hover inputs (so the step's own effect is isolated from the
tumble that the tilted start causes by itself). Per channel it prints python-control's
``step_info`` where the response settles, else the growth (log-log slope of |response| against
time since the step before it reaches ``--bound``: 2 for a double integrator) and the time
to reach the bound; the poles of the hover linearisation; and the comparison between engines
and models (the report's steady-state comparison, with real inputs). An open-loop quadrotor has
twelve poles at the origin: nothing settles. ``--controller lqr`` runs the closed-loop version (the
step becomes a disturbance the LQR must reject; responses then settle to a steady-state offset).

Examples::

    python -m quadsim.openloop --model physical
    python -m quadsim.openloop --model report            # MuJoCo refuses; analytic still runs
    python -m quadsim.openloop --model physical --compare computational --json
    python -m quadsim.openloop --model physical --controller lqr --rerun out/openloop.rrd

Units: step sizes in N (as a fraction of the weight for thrust) and N m; times in s; angles
in rad. Plots (PNG) go to ``--plots DIR`` when asked (none by default: no command writes
where it was not asked; ``--no-plots`` is accepted and changes nothing).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from .core.args import ArgumentParser
from .core.errors import InputError, ModelError, run_cli
from .core.files import atomic_write_bytes
from .sim.step_response import (
    CHANNELS,
    OpenLoopResult,
    format_report,
    response_metrics,
    run_openloop,
)
from .vehicle.params import VehicleParams, load_params

__all__ = ["CHANNELS", "OpenLoopResult", "main", "response_metrics", "run_openloop",
           "save_compare_plot", "save_plot"]

def save_plot(result: OpenLoopResult, folder: Path) -> Path:
    """PNG of each channel's response in each engine; written atomically, deterministic."""
    styles = {"mujoco": dict(color="C0", lw=2.5, alpha=0.6), "analytic": dict(color="C3", ls="--")}
    curves = [(result, engine, styles[engine], engine) for engine in result.trajectories]
    mode = "LQR closed loop" if result.controller == "lqr" else "open loop"
    suffix = "lqr" if result.controller == "lqr" else "openloop"
    return _save_response_plot(
        curves, f"{result.params.name}: {mode} step responses from the report's initial state",
        folder / f"{result.params.name}_{suffix}.png")


def save_compare_plot(results: list[OpenLoopResult], folder: Path) -> Path:
    """One PNG overlaying every model's responses per channel (analytic engine, which runs
    every set; MuJoCo where the analytic one is absent); atomic, deterministic."""
    curves = []
    for k, result in enumerate(results):
        engine = "analytic" if "analytic" in result.trajectories else next(
            iter(result.trajectories), None)
        if engine is not None:
            curves.append((result, engine, dict(color=f"C{k}", ls=("-", "--", ":", "-.")[k % 4]),
                           f"{result.params.name} ({engine})"))
    mode = "LQR closed loop" if results[0].controller == "lqr" else "open loop"
    suffix = "lqr" if results[0].controller == "lqr" else "openloop"
    return _save_response_plot(
        curves, f"{mode} step responses: " + " vs ".join(r.params.name for r in results),
        folder / ("compare_" + "_".join(r.params.name for r in results) + f"_{suffix}.png"))


def _save_response_plot(curves, title: str, path: Path) -> Path:
    """The 2x2 step-response figure (one panel per channel, units on the axes) from
    ``(result, engine, line style, label)`` curves, written atomically as PNG."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(10, 7), sharex=True)
    for result, engine, style, label in curves:
        for ax, (channel, (t, y)) in zip(axes.flat, result.responses(engine).items()):
            ax.plot(t, y, label=label, **style)
            _, output, _, unit = CHANNELS[channel]
            ax.set_title(f"{channel} step -> {output}")
            ax.set_ylabel(f"{output} change ({unit})")
            ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("time since step (s)")
    axes.flat[0].legend()
    fig.suptitle(title)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100, metadata={"Software": None})
    plt.close(fig)
    atomic_write_bytes(path, buffer.getvalue(), make_parents=True)  # the --plots folder
    return path


# ----------------------------------------------------------------------------- CLI


def _parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="python -m quadsim.openloop",
        description="The report's open-loop experiment (section 4.4): start at z = 1 m, "
                    "roll = pitch = yaw = 0.261 rad, hover thrust plus a step on each input "
                    "channel, simulated in MuJoCo and in the analytic Newton-Euler model. "
                    "Prints step information (python-control step_info where a response "
                    "settles, growth and time to a bound where it diverges), the poles of "
                    "the hover linearisation and the engine/model comparison; PNGs with "
                    "--plots DIR.",
        epilog="Models: a built-in name (see models/) or a parameter TOML file. The report set "
               "has an inertia no rigid body has: MuJoCo refuses it and only the analytic "
               "model runs. Exit status 2 with a one-line error on bad input.")
    parser.add_argument("--model", default="physical",
                        help="parameter set: physical, computational, report, ... or FILE")
    parser.add_argument("--compare", nargs="+", default=[], metavar="MODEL",
                        help="further models to run side by side")
    parser.add_argument("--controller", choices=("none", "lqr"), default="none",
                        help="none: open loop (default); lqr: hover LQR closes the loop")
    parser.add_argument("--step-thrust", type=float, default=0.05, metavar="FRACTION",
                        help="collective thrust step as a fraction of the weight (default 0.05)")
    parser.add_argument("--step-roll", type=float, default=2e-3, metavar="NM",
                        help="roll torque step, N m (default 0.002)")
    parser.add_argument("--step-pitch", type=float, default=2e-3, metavar="NM",
                        help="pitch torque step, N m (default 0.002)")
    parser.add_argument("--step-yaw", type=float, default=5e-3, metavar="NM",
                        help="yaw torque step, N m (default 0.005)")
    parser.add_argument("--step-time", type=float, default=0.5, help="step instant, s")
    parser.add_argument("--duration", type=float, default=5.0, help="simulated time, s")
    parser.add_argument("--control-period", type=float, default=0.01,
                        help="zero-order-hold period of the inputs, s (default 0.01)")
    parser.add_argument("--bound", type=float, default=1.0,
                        help="divergence bound for the 'time to bound' (m or rad; default 1)")
    parser.add_argument("--plots", default=None, metavar="DIR",
                        help="write PNG plots into this folder (created; default: no plots)")
    parser.add_argument("--no-plots", action="store_true",
                        help="no PNGs (the default; kept for scripts that pass it)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")
    parser.add_argument("--rerun", metavar="RRD", help="save a rerun recording (first model)")
    parser.add_argument("--rerun-spawn", action="store_true", help="open a rerun viewer")
    return parser


def _check_args(args) -> dict:
    if not (args.duration > 0 and args.control_period > 0 and args.bound > 0):
        raise InputError("--duration, --control-period and --bound must be positive")
    if not 0 <= args.step_time < args.duration:
        raise InputError("--step-time must lie in [0, --duration)")
    steps = {"collective": args.step_thrust, "roll": args.step_roll, "pitch": args.step_pitch,
             "yaw": args.step_yaw}
    for name, value in steps.items():
        if not math.isfinite(value):
            raise InputError(f"--step-{name}: not a finite number")
    from .core.args import check_number, check_output

    for flag in ("duration", "control_period", "bound"):
        check_number("--" + flag.replace("_", "-"), getattr(args, flag), low=0.0)
    if args.control_period > args.duration:
        raise InputError(f"--control-period {args.control_period:g}: longer than --duration "
                         f"{args.duration:g}")
    names = [args.model, *args.compare]
    if len(set(names)) < len(names):
        raise InputError(f"--compare: model given twice ({', '.join(names)})")
    if args.plots is not None and not args.no_plots:
        plots = Path(args.plots)
        if plots.exists() and not plots.is_dir():
            raise InputError(f"{plots}: --plots: not a folder")
        folder = plots  # --plots names a folder to write into: it is created (asked for)
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        check_output("--plots", folder / "probe.png")
    if args.rerun:
        from .viewer import check_output_path

        check_output_path(args.rerun)
    return steps


def _load(name: str) -> VehicleParams:
    """Load a set; one MuJoCo refuses (non-physical inertia) is loaded unchecked so the
    analytic model can still run it (the refusal is reported by run_openloop)."""
    try:
        return load_params(name)
    except ModelError:
        return load_params(name, check=False)


@run_cli
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    steps = _check_args(args)
    models = [_load(name) for name in [args.model, *args.compare]]
    results = [run_openloop(p, steps=steps, step_time=args.step_time, duration=args.duration,
                            control_period=args.control_period, controller=args.controller,
                            bound=args.bound) for p in models]
    plots = []
    if args.plots is not None and not args.no_plots:
        plots = [str(save_plot(r, Path(args.plots))) for r in results]
        if len(results) > 1:
            plots.append(str(save_compare_plot(results, Path(args.plots))))
    if args.rerun or args.rerun_spawn:
        from .viewer import save_recording  # lazy: rerun only when asked for

        first = results[0]
        save_recording(args.rerun, params=first.params, trajectories=first.trajectories,
                       measured=None, spawn=args.rerun_spawn, batch_index="all",
                       title=f"openloop {first.params.name}")
        if args.rerun:
            print(f"wrote rerun recording {args.rerun}; view it with `rerun {args.rerun}`",
                  file=sys.stderr)
    if args.json:
        print(json.dumps({"results": [r.to_json() for r in results], "plots": plots},
                         indent=2, allow_nan=False))
    else:
        print(format_report(results))
        for path in plots:
            print(f"plot: {path}")
        for res in results:
            for engine, reason in res.refused.items():
                print(f"note: {engine} refused {res.params.name}: {reason}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
