"""The report's open-loop step experiment (section 4.4) as a computation: hover inputs plus a
step on one input channel at a time, simulated in both engines, with per-channel metrics.

The vehicle starts in the report's initial state (z = 1 m, roll = pitch = yaw = 0.261 rad,
Appendix D/F); each channel's step (collective thrust as a fraction of the weight, roll /
pitch / yaw torque in N m) is turned into rotor speeds by the geometry-derived mixer. A
channel's response is the difference between the stepped run and the same start with hover
inputs, so the step's own effect is isolated from the tumble the tilted start causes by itself.
:func:`response_metrics` gives python-control's ``step_info`` where a response settles, else
its growth exponent (log-log slope of |response| against time: 2 for a double integrator) and
the time to reach ``bound``. With ``controller="lqr"`` the step becomes a disturbance an LQR on
the hover linearisation must reject. Units: N, N m, s, rad, m.

Example::

    >>> from quadsim.sim.step_response import run_openloop
    >>> result = run_openloop(load_params("physical"), steps={"collective": 0.05, "roll": 0.01,
    ...                       "pitch": 0.01, "yaw": 0.01})
    >>> result.metrics()["analytic"]["roll"]["growth_exponent"]     # about 2

The command ``python -m quadsim.openloop`` prints :func:`format_report` and plots.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import control
import numpy as np

from ..core.errors import ModelError
from ..vehicle.params import VehicleParams
from ..vehicle.rotors import speeds_for
from .engines import initial_state, simulate
from .linear import LQRController, hover_point, linearize

__all__ = ["CHANNELS", "REPORT_EULER", "REPORT_HEIGHT", "OpenLoopResult", "format_report",
           "response_metrics", "run_openloop"]

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
