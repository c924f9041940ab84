"""The published nano-drone benchmark (Busetto et al. 2026) with quadsim's models.

Reads the benchmark's three melon test runs from ``DIR/test/``, builds the 0.5 s prediction
windows at every sample (:mod:`benchmarks.nanodrone`), predicts them with

* ``naive`` -- hold the state;
* ``physics`` -- the authors' physics baseline (reproduces their published row);
* ``quadsim_nominal`` -- quadsim's full rigid body (``models/nanodrone_cf21bl.toml``: b and d
  fitted on the training runs) driven by the measured rotor speeds;
* ``quadsim_diagnosed`` -- the same plus the effects the gap diagnosis named on the training
  runs (``models/effects/nanodrone_cf21bl_diagnosed.toml``, every number with unit and source),
  and ``quadsim_nominal+A+B..`` rows adding its effects one at a time in the file's order (how
  much each shrinks the error); ``quadsim_diagnosed_rate_held``: the diagnosed forces with
  the body rate held as in the authors' physics baseline; with ``--align-rotors`` also
  ``quadsim_diagnosed_aligned`` and ``quadsim_diagnosed_rate_held_aligned``: the same on
  windows whose rotor speeds are shifted per run by the rotor-speed delay behind the body
  rate estimated from that run's own rotor speeds and body rates
  (:func:`benchmarks.nanodrone.align_rotor_speeds`; JSON ``rotor_delays_ms``);

the quadsim rows batched over all windows on the analytic engine's equations
(:func:`benchmarks.rollout.rollout`, fixed-step RK4 at the 10 ms sample period), and scores
them with the published protocol (``published``: concatenated windows, the authors'
attitude angle) or per run (``per_run``: each run on its own, true geodesic). The published
rows are copied beside them as ``published_*``. Nothing is fitted here, and nothing ever on
the test runs.

Usage::

    python -m benchmarks.nanodrone_benchmark --data ../shared/data/nanodrone_cf21bl \\
        --json nano.json [--protocol published|per_run] [--plot docs/img/nanodrone.png] \\
        [--runs test|validation] [--diagnosed EFFECTS.toml] [--align-rotors]

JSON: ``{"protocol": P, "windows": B, "rows": {NAME: {"p": [h1, h10, h50, SimErr], "v": ...,
"R": ..., "w": ...}}, "rate_skill": {ROW: ...}, "by_run": {RUN: {ROW: {...}, "rate_skill":
{ROW: ...}}}}`` (m, m/s, rad, rad/s; ``rate_skill``: per body axis, how much of the body-rate
change the nominal and diagnosed rows get right, :func:`benchmarks.nanodrone.rate_skill`;
``by_run``: the :data:`BY_RUN` rows scored on each run's windows alone under the same
protocol, :func:`benchmarks.nanodrone.of_run`); same inputs give the same bytes. The wall and
CPU time of each model's predictions go to stdout.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks import nanodrone as bench
from benchmarks.rollout import rollout
from quadsim.core.args import check_output
from quadsim.core.errors import InputError, QuadsimWarning, run_cli
from quadsim.core.executor import limit_numeric_threads
from quadsim.core.files import atomic_write_bytes, atomic_write_text
from quadsim.effects.base import EffectSet
from quadsim.effects.effectfile import load_effect_file
from quadsim.logs.flightlog import load_log
from quadsim.vehicle.params import load_params

ROOT = Path(__file__).resolve().parent.parent
TEST_RUNS = ("melon_20251017_run1", "melon_20251017_run4", "melon_20251017_run5")
NOMINAL = ROOT / "models/nanodrone_cf21bl.toml"
DIAGNOSED = ROOT / "models/effects/nanodrone_cf21bl_diagnosed.toml"
#: the rows also scored run by run (``by_run``): the published physics baseline's
#: reproduction, the diagnosed model and its forces with the rate held
BY_RUN = ("physics", "quadsim_diagnosed", "quadsim_diagnosed_rate_held")


def run_logs(data: Path, runs: str) -> list:
    """The benchmark's test runs 1-3 in the published order, or its validation runs (run 4
    of each training trajectory)."""
    logs = []
    names = [f"test/{n}" for n in TEST_RUNS] if runs == "test" else \
        [f"train/{n}_20251017_run4" for n in ("square", "random", "chirp")]
    for name in names:
        path = data / f"{name}.csv.gz"
        if not path.exists():
            raise InputError(f"{path}: run missing (expected the benchmark's "
                             f"{name}.csv.gz under --data)")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            log = load_log(path)
        if log.rotor_speed is None or log.rotor_speed.shape[1] != 4 or log.velocity is None \
                or log.body_rate is None:
            raise InputError(f"{path}: rotor_1..4, vx..vz, wx..wz: needed by the benchmark")
        logs.append(log)
    return logs


def quadsim_prediction(windows: bench.Windows, params, effects=None, *,
                       hold_body_rate: bool = False) -> dict:
    """quadsim's rigid body (plus ``effects``) over every window, as the benchmark's dict."""
    out = rollout(params, initial=windows.initial(), rotor_speed_series=windows.rotor_speed,
                  control_period=bench.PERIOD, effects=effects, substeps=1,
                  hold_body_rate=hold_body_rate)
    return {"p": out["position"][:, 1:], "v": out["velocity"][:, 1:], "R": out["quat"][:, 1:],
            "w": out["body_rate"][:, 1:]}


def predictions(windows: bench.Windows, diagnosed: Path, aligned: bench.Windows | None = None):
    """(name, callable) per model row."""
    params = load_params(NOMINAL)
    model = load_effect_file(diagnosed)
    completed = load_params(model.params)
    ladder = []                  # the diagnosed effects added one at a time, in file order
    for k in range(1, len(model.effects.effects)):
        subset = EffectSet(model.effects.effects[:k])
        name = "quadsim_nominal+" + "+".join(e.name for e in subset.effects)
        ladder.append((name, lambda subset=subset: quadsim_prediction(windows, completed,
                                                                      subset)))
    return [("naive", lambda: bench.naive_prediction(windows)),
            ("physics", lambda: bench.physics_prediction(windows)),
            ("quadsim_nominal", lambda: quadsim_prediction(windows, params)), *ladder,
            ("quadsim_diagnosed", lambda: quadsim_prediction(windows, completed,
                                                             model.effects)),
            ("quadsim_diagnosed_rate_held", lambda: quadsim_prediction(
                windows, completed, model.effects, hold_body_rate=True)),
            *([] if aligned is None else [
                ("quadsim_diagnosed_aligned", lambda: quadsim_prediction(
                    aligned, completed, model.effects)),
                ("quadsim_diagnosed_rate_held_aligned", lambda: quadsim_prediction(
                    aligned, completed, model.effects, hold_body_rate=True))])]


def plot(path: Path, curves: dict, protocol: str, published: bool) -> None:
    """Per-horizon error of every computed row; the published rows at h = 1, 10, 50."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = {"p": "position (m)", "v": "velocity (m/s)", "R": "attitude (rad)",
              "w": "body rate (rad/s)"}
    fig, axes = plt.subplots(1, 4, figsize=(18, 3.8))
    horizon = np.arange(1, bench.HORIZON + 1)
    for ax, key in zip(axes, bench.QUANTITIES):
        for name, curve in curves.items():
            ax.plot(horizon, curve[key], label=name, lw=1.6)
        if published:
            for name, row in bench.PUBLISHED.items():
                if name in ("naive", "physics"):
                    continue
                ax.plot(bench.REPORTED, row[key][:3], "o--", ms=4, lw=0.8,
                        label=f"published {name}")
        ax.set_yscale("log")
        ax.set_title(labels[key])
        ax.set_xlabel("horizon h (10 ms steps)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(f"mean error ({protocol} scoring)")
    fig.tight_layout(rect=(0, 0, 0.8, 1))
    handles, names = axes[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="center right", fontsize=8)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110, metadata={"Software": None})
    plt.close(fig)
    atomic_write_bytes(path, buffer.getvalue())


@run_cli
@limit_numeric_threads
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True,
                        help="the benchmark folder (holding test/melon_20251017_run*.csv.gz)")
    parser.add_argument("--json", type=Path, required=True, metavar="OUT.json")
    parser.add_argument("--protocol", choices=("published", "per_run"), default="published")
    parser.add_argument("--plot", type=Path, metavar="PNG", help="per-horizon plot")
    parser.add_argument("--runs", choices=("test", "validation"), default="test",
                        help="score the melon test runs (default) or the validation runs "
                             "(run 4 of square/random/chirp: the held-out set while a model "
                             "is being diagnosed)")
    parser.add_argument("--align-rotors", action="store_true",
                        help="also score the diagnosed rows with each run's rotor speeds "
                             "shifted by their delay behind the body rate, estimated from "
                             "that run (benchmarks.nanodrone.align_rotor_speeds)")
    parser.add_argument("--diagnosed", type=Path, default=DIAGNOSED,
                        help="effect file of the diagnosed model (default %(default)s)")
    args = parser.parse_args(argv)
    check_output("--json", args.json)
    if args.plot:
        check_output("--plot", args.plot)
    logs = run_logs(args.data, args.runs)
    windows = bench.make_windows(logs)
    aligned, delays = None, {}
    if args.align_rotors:
        shifted = [bench.align_rotor_speeds(log) for log in logs]
        aligned = bench.make_windows([log for log, _ in shifted])
        delays = {Path(str(log.path)).name.split(".")[0]: round(1e3 * d, 1)
                  for log, (_, d) in zip(logs, shifted)}
        print("rotor-speed delays behind the body rate (ms): "
              + ", ".join(f"{k} {v:+.1f}" for k, v in delays.items()))
    rows, curves, skill, by_run = {}, {}, {}, {}
    for name, predict in predictions(windows, args.diagnosed, aligned):
        wall, cpu = time.perf_counter(), time.process_time()
        prediction = predict()
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        curves[name] = bench.curves(windows, prediction, args.protocol)
        if name in ("quadsim_nominal", "quadsim_diagnosed", "quadsim_diagnosed_aligned"):
            skill[name] = {k: [round(x, 4) for x in v] for k, v in bench.rate_skill(
                aligned if name.endswith("_aligned") else windows, prediction).items()}
            print(f"  {name} body rate per axis x/y/z: SimErr "
                  + "/".join(f"{x:.2f}" for x in skill[name]["simerr_model"])
                  + " (rate held " + "/".join(f"{x:.2f}" for x in skill[name]["simerr_hold"])
                  + "), corr of the predicted and true rate change at h = 50 "
                  + "/".join(f"{x:.2f}" for x in skill[name]["corr_h50"]))
        rows[name] = bench.summary(curves[name])
        if name in BY_RUN:
            for run, run_name in enumerate(windows.names):
                part, pred = bench.of_run(windows, prediction, run)
                if len(part) < bench.HORIZON:      # the published scoring needs H windows
                    continue
                entry = by_run.setdefault(Path(run_name).name.split(".")[0], {})
                entry[name] = bench.score(part, pred, args.protocol)
                entry.setdefault("rate_skill", {})[name] = [
                    round(x, 4) for x in bench.rate_skill(part, pred)["simerr_model"]]
        print(f"{name}: {len(windows)} windows x {bench.HORIZON} steps in {wall:.2f} s wall, "
              f"{cpu:.2f} s CPU; SimErr p {rows[name]['p'][3]:.4f} m, v {rows[name]['v'][3]:.4f}"
              f" m/s, R {rows[name]['R'][3]:.4f} rad, w {rows[name]['w'][3]:.4f} rad/s")
    for name, row in bench.PUBLISHED.items() if args.runs == "test" else ():
        rows[f"published_{name}"] = row
    result = {"protocol": args.protocol, "runs": args.runs, "windows": len(windows),
              **({"rotor_delays_ms": delays} if args.align_rotors else {}),
              "rate_skill": skill,
              "rows": {k: {q: [round(x, 6) for x in v[q]] for q in bench.QUANTITIES}
                       for k, v in rows.items()},
              "by_run": {run: {k: v if k == "rate_skill" else
                               {q: [round(x, 6) for x in v[q]] for q in bench.QUANTITIES}
                               for k, v in entry.items()} for run, entry in by_run.items()}}
    for run, entry in by_run.items():
        print(f"{run}: " + "; ".join(
            f"{k} SimErr p/v/R/w " + "/".join(f"{entry[k][q][3]:.4g}" for q in bench.QUANTITIES)
            + " body rate x/y/z " + "/".join(f"{x:.2f}" for x in entry["rate_skill"][k])
            for k in BY_RUN if k in entry))
    atomic_write_text(args.json, json.dumps(result, indent=1) + "\n")
    if args.plot:
        plot(args.plot, curves, args.protocol, args.runs == "test" and args.protocol == "published")
    return 0


if __name__ == "__main__":
    sys.exit(main())
