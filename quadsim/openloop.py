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
and models (the report's steady-state comparison, with real inputs). An open-loop quadrotor has twelve poles at the
origin: nothing settles. ``--controller lqr`` runs the closed-loop version (the step becomes a
disturbance the LQR must reject; responses then settle to a steady-state offset).

Examples::

    python -m quadsim.openloop --model physical
    python -m quadsim.openloop --model report            # MuJoCo refuses; analytic still runs
    python -m quadsim.openloop --model physical --compare computational --json
    python -m quadsim.openloop --model physical --controller lqr --rerun out/openloop.rrd

Units: step sizes in N (as a fraction of the weight for thrust) and N m; times in s; angles
in rad. Plots (PNG) go to ``--plots DIR`` (default ``out/openloop/``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import control
import numpy as np

from .core.args import ArgumentParser
from .core.errors import InputError, ModelError, run_cli
from .core.files import atomic_write_bytes
from .sim.engines import initial_state, simulate
from .sim.linear import LQRController, hover_point, linearize
from .vehicle.params import VehicleParams, load_params
from .vehicle.rotors import speeds_for

__all__ = ["CHANNELS", "OpenLoopResult", "run_openloop", "response_metrics", "main"]

#: channel -> (index into [T, Mx, My, Mz], output name, index into state12, output unit)
CHANNELS = {"collective": (0, "z", 2, "m"), "roll": (1, "roll", 6, "rad"),
            "pitch": (2, "pitch", 7, "rad"), "yaw": (3, "yaw", 8, "rad")}
REPORT_EULER = (0.261, 0.261, 0.261)
REPORT_HEIGHT = 1.0


def response_metrics(t: np.ndarray, response: np.ndarray, *, bound: float) -> dict:
    """Step information for one response (times from the step, response from 0).

    Settled (the last quarter stays within 2 % of the final value, below ``bound``):
    python-control ``step_info``; returned to zero (a rejected disturbance: final and last
    quarter within 2 % of the peak): settling time and peak. Otherwise: ``growth_exponent``
    (slope of log|y| against log t over the second half of the time before the bound is
    reached, or of the whole run) and ``time_to_bound`` (None if not reached)."""
    final = float(response[-1])
    peak = float(np.abs(response).max())
    tail = response[int(0.75 * len(response)):]
    out: dict = {"settles": False, "final": final}
    if peak < bound and abs(final) < 0.02 * peak and np.all(np.abs(tail) <= 0.02 * peak):
        # a disturbance rejected back to zero: step_info needs a non-zero final value
        outside = np.flatnonzero(np.abs(response) > 0.02 * peak)
        out.update(settles=True, SettlingTime=float(t[outside[-1]]) if outside.size else 0.0,
                   Peak=peak, PeakTime=float(t[np.argmax(np.abs(response))]))
        return out
    band = 0.02 * abs(final)
    if abs(final) < bound and abs(final) > 1e-12 and np.all(np.abs(tail - final) <= band):
        info = control.step_info(response, t, yfinal=final)
        out.update({k: float(v) for k, v in info.items()}, settles=True)
        return out
    beyond = np.flatnonzero(np.abs(response) >= bound)
    end = beyond[0] + 1 if beyond.size else len(t)      # fit the growth before the bound
    late = slice(end // 2, end)
    magnitude = np.abs(response[late])
    usable = (magnitude > 1e-12) & (t[late] > 0)
    exponent = None
    if usable.sum() > 2:
        exponent = float(np.polyfit(np.log(t[late][usable]), np.log(magnitude[usable]), 1)[0])
    out.update(growth_exponent=exponent,
               time_to_bound=float(t[beyond[0]]) if beyond.size else None)
    return out


@dataclass
class OpenLoopResult:
    """One model's experiment: trajectories per engine (batch: hover, then one per channel),
    per-channel metrics per engine, poles, and the engine that was refused (if any)."""

    params: VehicleParams
    controller: str
    steps: dict
    step_time: float
    bound: float
    trajectories: dict
    poles: np.ndarray
    refused: dict = field(default_factory=dict)

    def responses(self, engine: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """channel -> (time since the step, response) for ``engine``."""
        traj = self.trajectories[engine]
        states = traj.state12()
        states[..., 6:9] = np.unwrap(states[..., 6:9], axis=-2)
        after = traj.t >= self.step_time - 1e-12
        out = {}
        for k, (channel, (_, _, index, _)) in enumerate(CHANNELS.items()):
            delta = states[k + 1, :, index] - states[0, :, index]
            out[channel] = (traj.t[after] - self.step_time, delta[after])
        return out

    def metrics(self) -> dict:
        return {engine: {channel: response_metrics(t, y, bound=self.bound)
                         for channel, (t, y) in self.responses(engine).items()}
                for engine in self.trajectories}

    def engine_difference(self) -> dict[str, float] | None:
        """Largest |response difference| between the engines per channel (None if one ran)."""
        if len(self.trajectories) < 2:
            return None
        a, b = (self.responses(e) for e in ("mujoco", "analytic"))
        return {c: float(np.abs(a[c][1] - b[c][1]).max()) for c in CHANNELS}

    def to_json(self) -> dict:
        poles = [[float(p.real), float(p.imag)] for p in self.poles]
        return {"model": self.params.name, "controller": self.controller,
                "initial": {"z_m": REPORT_HEIGHT, "roll_pitch_yaw_rad": list(REPORT_EULER)},
                "steps": self.steps, "step_time_s": self.step_time, "bound": self.bound,
                "poles": poles, "engines": sorted(self.trajectories),
                "refused": self.refused, "metrics": self.metrics(),
                "engine_difference": self.engine_difference()}


def _step_inputs(params: VehicleParams, steps: dict) -> np.ndarray:
    """(5, R) rotor speeds: hover, then hover + each channel's step (rad/s)."""
    base = np.array([params.weight, 0.0, 0.0, 0.0])
    rows = [hover_point(params)[1]]
    for channel, (index, *_rest) in CHANNELS.items():
        wrench = base.copy()
        wrench[index] += steps[channel] * (params.weight if channel == "collective" else 1.0)
        rows.append(speeds_for(params, wrench, clip=False))
    return np.array(rows)


def _make_controller(params, inputs, step_time, use_lqr):
    hover = inputs[0]

    def controller(t, state):
        extra = np.where((t >= step_time - 1e-12)[:, None], inputs - hover, 0.0)
        base = lqr(t, state) if use_lqr else hover
        return base + extra

    lqr = LQRController(params, position=(0.0, 0.0, REPORT_HEIGHT)) if use_lqr else None
    return controller, lqr


def run_openloop(params: VehicleParams, *, steps: dict, step_time: float = 0.5,
                 duration: float = 5.0, control_period: float = 0.01, controller: str = "none",
                 bound: float = 1.0) -> OpenLoopResult:
    """Run the experiment for one model in both engines (MuJoCo skipped, with the reason in
    ``refused``, if it refuses the parameter set)."""
    inputs = _step_inputs(params, steps)
    command, lqr = _make_controller(params, inputs, step_time, controller == "lqr")
    start = initial_state(position=[(0.0, 0.0, REPORT_HEIGHT)] * len(inputs),
                          euler=[REPORT_EULER] * len(inputs))
    trajectories, refused = {}, {}
    for engine in ("mujoco", "analytic"):
        try:
            trajectories[engine] = simulate(params, engine=engine, initial=start,
                                            controller=command, duration=duration,
                                            control_period=control_period)
        except ModelError as exc:
            refused[engine] = " ".join(str(exc).split())
    sys_ = linearize(params)
    poles = lqr.closed_loop_poles if lqr is not None else np.linalg.eigvals(sys_.A)
    return OpenLoopResult(params, controller, dict(steps), step_time, bound, trajectories,
                          np.asarray(poles), refused)


# ----------------------------------------------------------------------------- output


def _fmt(value, unit="") -> str:
    if value is None:
        return "-"
    return f"{value:.4g}{unit}"


def format_report(results: list[OpenLoopResult]) -> str:
    """Human-readable tables: per model the poles and per-channel step information, then the
    comparison between engines and between models."""
    lines = []
    for res in results:
        mode = "LQR closed loop" if res.controller == "lqr" else "open loop"
        lines.append(f"model {res.params.name} ({mode}): start z = {REPORT_HEIGHT} m, "
                     f"roll = pitch = yaw = {REPORT_EULER[0]} rad; steps at {res.step_time} s")
        for engine in res.refused:
            lines.append(f"  {engine} refuses this set (reason on stderr); the analytic model "
                         "still runs")
        unstable = int(np.sum(res.poles.real >= -1e-9))
        which = "closed-loop poles (LQR on the hover linearisation)" if res.controller == "lqr" \
            else "poles of the hover linearisation"
        lines.append(f"  {which}: {_poles_text(res.poles)}"
                     f" ({unstable} not in the left half-plane)")
        lines.append(f"  {'channel':<11}{'output':<10}{'engine':<10}{'settles':<9}"
                     f"{'rise s':>9}{'settle s':>10}{'final':>11}{'growth':>8}{'t->bound':>10}")
        metrics = res.metrics()
        for channel, (_, output, _, unit) in CHANNELS.items():
            for engine, per_channel in metrics.items():
                m = per_channel[channel]
                lines.append(
                    f"  {channel:<11}{output + ' ' + unit:<10}{engine:<10}"
                    f"{'yes' if m['settles'] else 'no':<9}{_fmt(m.get('RiseTime')):>9}"
                    f"{_fmt(m.get('SettlingTime')):>10}{_fmt(m['final']):>11}"
                    f"{_fmt(m.get('growth_exponent')):>8}{_fmt(m.get('time_to_bound')):>10}")
        diff = res.engine_difference()
        if diff:
            lines.append("  MuJoCo vs analytic, max |response difference|: " + ", ".join(
                f"{c} {v:.2e} {CHANNELS[c][3]}" for c, v in diff.items()))
        lines.append("")
    if len(results) > 1:
        lines.append("final response per channel (model comparison, analytic engine):")
        lines.append(f"  {'model':<16}" + "".join(f"{c:>14}" for c in CHANNELS))
        for res in results:
            finals = res.metrics()["analytic"]
            lines.append(f"  {res.params.name:<16}"
                         + "".join(f"{finals[c]['final']:>14.5g}" for c in CHANNELS))
    return "\n".join(lines)


def _poles_text(poles: np.ndarray) -> str:
    if np.all(np.abs(poles) < 1e-9):
        return f"{len(poles)} at the origin"
    return ", ".join(f"{p.real:.3g}{p.imag:+.3g}j" if abs(p.imag) > 1e-9 else f"{p.real:.3g}"
                     for p in sorted(poles, key=lambda p: (p.real, p.imag)))


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
                    "the hover linearisation and the engine/model comparison; saves PNGs.",
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
    parser.add_argument("--plots", default="out/openloop", metavar="DIR",
                        help="folder for PNG plots (default out/openloop)")
    parser.add_argument("--no-plots", action="store_true", help="do not write PNGs")
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
    if not args.no_plots:
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
    if not args.no_plots:
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
