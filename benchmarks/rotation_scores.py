"""Score effect files on the nano-drone benchmark, pooled and per run, with the body rate per axis.

For each effect file (its ``params`` a shipped name or a path): the published scoring of all the
runs together (:mod:`benchmarks.nanodrone`, ``published``), and each run on its own windows
(``per_run`` scoring of that run alone: true geodesic); SimErr of position (m), velocity (m/s),
attitude (rad), body rate (rad/s), their h = 50 values, and the body-rate SimErr per axis
against holding the rate (:func:`benchmarks.nanodrone.rate_skill`). Nothing is fitted.

Usage::

    python -m benchmarks.rotation_scores --data ../shared/data/nanodrone_cf21bl \\
        [--runs test|validation] [--json OUT.json] [--params PARAMS.toml] \\
        [--drop EFFECT ...] [--flapping-axes SX SY] EFFECTS.toml [EFFECTS.toml ...]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks import nanodrone as bench  # noqa: E402
from benchmarks.nanodrone_benchmark import quadsim_prediction, run_logs  # noqa: E402
from quadsim.core.errors import run_cli  # noqa: E402
from quadsim.core.files import atomic_write_text  # noqa: E402
from quadsim.effects import make_effect  # noqa: E402
from quadsim.effects.base import EffectSet  # noqa: E402
from quadsim.effects.effectfile import load_effect_file  # noqa: E402
from quadsim.vehicle.params import load_params  # noqa: E402


def load_model(path: Path, params: Path | None = None, drop: tuple[str, ...] = (),
               flapping_axes: tuple[float, float] | None = None):
    """(parameter set, effects) of an effect file, its parameter set replaced by ``params``,
    the effects named in ``drop`` left out, and its flapping coefficients scaled per axis by
    ``flapping_axes`` (roll, pitch), when given (the library's per-axis ``blade_flapping``)."""
    model = load_effect_file(path)
    effects = []
    for effect in model.effects.effects:
        if effect.name in drop:
            continue
        if effect.name == "blade_flapping" and flapping_axes is not None:
            roll, pitch = effect.axes
            effect = make_effect("blade_flapping", roll=roll * flapping_axes[0],
                                 pitch=pitch * flapping_axes[1])
        effects.append(effect)
    return load_params(params if params is not None else model.params), EffectSet(tuple(effects))


def score_model(windows: bench.Windows, model, protocol: str) -> dict:
    """SimErr and h = 50 per quantity, and the per-axis body-rate SimErr (model, rate held);
    ``model`` = (parameter set, effects)."""
    prediction = quadsim_prediction(windows, model[0], model[1])
    row = bench.summary(bench.curves(windows, prediction, protocol))
    skill = bench.rate_skill(windows, prediction)
    return {"simerr": {q: round(row[q][3], 4) for q in bench.QUANTITIES},
            "h50": {q: round(row[q][2], 4) for q in bench.QUANTITIES},
            "rate_axes": [round(x, 3) for x in skill["simerr_model"]],
            "rate_axes_held": [round(x, 3) for x in skill["simerr_hold"]]}


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--runs", choices=("test", "validation"), default="test")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--params", type=Path, help="parameter set replacing the effect "
                        "files' own (e.g. the output of identify --logs)")
    parser.add_argument("--drop", nargs="*", default=[], metavar="EFFECT",
                        help="effects of the files to leave out")
    parser.add_argument("--flapping-axes", type=float, nargs=2, metavar=("SX", "SY"),
                        help="scale the files' flapping moment per axis (a probe)")
    parser.add_argument("effects", type=Path, nargs="+")
    args = parser.parse_args(argv)
    logs = run_logs(args.data, args.runs)
    names = [Path(str(log.path)).name.split(".")[0] for log in logs]
    pooled = bench.make_windows(logs)
    single = {n: bench.make_windows([log]) for n, log in zip(names, logs)}
    out = {}
    for path in args.effects:
        model = load_model(path, args.params, tuple(args.drop), args.flapping_axes)
        entry = {"pooled_published": score_model(pooled, model, "published")}
        for name, windows in single.items():
            entry[name] = score_model(windows, model, "per_run")
        out[str(path)] = entry
        for key, r in entry.items():
            print(f"{path.name} {key}: SimErr p/v/R/w "
                  + " / ".join(f"{r['simerr'][q]:.3f}" for q in bench.QUANTITIES)
                  + "; h50 " + " / ".join(f"{r['h50'][q]:.4f}" for q in bench.QUANTITIES)
                  + "; body rate x/y/z " + "/".join(f"{x:.2f}" for x in r["rate_axes"])
                  + " (held " + "/".join(f"{x:.2f}" for x in r["rate_axes_held"]) + ")")
    if args.json:
        atomic_write_text(args.json, json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
