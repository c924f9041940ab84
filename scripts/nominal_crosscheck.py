"""No-effect check on real flights: nominal Crazyflie flights judged against other nominal flights.

The 20 nominal flights of the Crazyflie 2.1 Brushless data (``../shared/data``, README there;
IMRCLab/crazyflie-data-collection) are all the same vehicle, so each one judged per flight
(:func:`quadsim.gap.diagnose_per_flight`) against a reference set of *other* nominal flights
should get ``no_significant_gap``: anything else is a false alarm of the diagnosis on real
data. Two folds: odd-numbered flights against the even-numbered ones, then the reverse (every
flight judged once, never against itself). Nothing here reads ``mixed/``.

Usage::

    python scripts/nominal_crosscheck.py [--data ../shared/data] [--workers 2] [--json out.json]
    python scripts/nominal_crosscheck.py --fastest      # one flight outside its references
    python scripts/nominal_crosscheck.py --effects-file models/effects/crazyflie21_nominal.toml

``--fastest``: the fastest nominal flight (RMS speed) judged against the 6 slowest, a flight
flown outside its references' envelope (``quadsim.gap.reference``). ``--effects-file``: an
effect file on ``crazyflie21`` (:mod:`quadsim.effects.effectfile`) in the references' model
and so every flight's (``python -m quadsim.gap --per-flight --effects-file``).

Prints, per flight, the verdict and answer, and the no_significant_gap rate. Runs in about
two minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run from a checkout

from quadsim.core.errors import InputError, QuadsimWarning, run_cli  # noqa: E402
from quadsim.core.executor import limit_numeric_threads, run_tasks  # noqa: E402
from quadsim.gap import diagnose_per_flight  # noqa: E402
from quadsim.gap.__main__ import collapse_warnings  # noqa: E402
from quadsim.logs.flightlog import load_log  # noqa: E402
from quadsim.vehicle.params import load_params  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def folds(files: list[Path]) -> list[tuple[list[Path], list[Path]]]:
    """(tested, reference) pairs: odd against even, then even against odd."""
    even, odd = files[0::2], files[1::2]
    return [(odd, even), (even, odd)]


def crosscheck(data: Path, workers: int, base_effects: tuple = ()) -> dict:
    nominal, logs = _nominal(data)
    params = load_params("crazyflie21")
    rows = []
    for tested, reference in folds(nominal):
        result = diagnose_per_flight(
            [logs[p] for p in tested], [logs[p] for p in reference], params,
            base_effects=base_effects,
            map_fn=lambda fn, items: run_tasks(fn, list(items), workers=workers))
        for path, flight in zip(tested, result["flights"]):
            rows.append({"file": path.name, "outcome": flight["outcome"],
                         "verdict": flight["verdict"], "answer": flight["answer"],
                         "tentative": bool(flight.get("tentative", False))})
    rows.sort(key=lambda r: r["file"])
    clean = sum(r["outcome"] == "no_significant_gap" for r in rows)
    return {"flights": rows, "no_significant_gap": clean, "judged": len(rows)}


def _nominal(data: Path) -> tuple[list[Path], dict]:
    nominal = sorted((data / "crazyflie21_brushless" / "nominal").glob("flight_*.csv.gz"))
    if len(nominal) < 4:
        raise InputError(f"{data}: crazyflie21_brushless/nominal/flight_*.csv.gz: "
                         f"found {len(nominal)} flights, need at least 4")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", QuadsimWarning)
        logs = {p: load_log(p) for p in nominal}
    for line in collapse_warnings([str(w.message) for w in caught]):
        print(f"warning: {line}", file=sys.stderr)
    return nominal, logs


#: references of ``--fastest``: the slowest flights
SLOWEST = 6


def fastest_against_slowest(data: Path, base_effects: tuple = ()) -> dict:
    """The fastest nominal flight (RMS speed, m/s) judged against the :data:`SLOWEST` slowest."""
    import numpy as np

    nominal, logs = _nominal(data)
    speed = {p: float(np.sqrt(np.mean(np.sum(logs[p].velocity ** 2, axis=1)))) for p in nominal}
    order = sorted(nominal, key=lambda p: (speed[p], p.name))
    refs, flight = order[:SLOWEST], order[-1]
    result = diagnose_per_flight([logs[flight]], [logs[p] for p in refs],
                                 load_params("crazyflie21"), base_effects=base_effects)
    entry = result["flights"][0]
    return {"references": {p.name: speed[p] for p in refs}, "file": flight.name,
            "rms_speed": speed[flight], "outcome": entry["outcome"],
            "verdict": entry["verdict"], "answer": entry["answer"],
            "reference_model": result["reference_model"]["params"]}


def _base_effects(path: Path | None) -> tuple:
    """The effects of the effect file ``path`` (none: ()); InputError unless it is on
    crazyflie21."""
    if path is None:
        return ()
    from quadsim.core.args import check_inputs
    from quadsim.effects.effectfile import load_effect_file

    check_inputs("--effects-file", [path])
    model = load_effect_file(path)
    if model.params != "crazyflie21":
        raise InputError(f"{path}: params: the effects complete {model.params!r}, this "
                         "check runs crazyflie21")
    return tuple(model.effects.effects)


@limit_numeric_threads
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA,
                        help="the shared data folder (default: ../shared/data)")
    parser.add_argument("--workers", type=int, default=2, help="local processes")
    parser.add_argument("--json", type=Path, help="write the per-flight rows (JSON)")
    parser.add_argument("--fastest", action="store_true",
                        help="judge the fastest nominal flight against the 6 slowest")
    parser.add_argument("--effects-file", type=Path, metavar="EFFECTS.toml",
                        help="an effect file on crazyflie21 in every model (default: none)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    base = _base_effects(args.effects_file)
    if args.effects_file is not None:
        names = ", ".join(e.name for e in base)
        print(f"model: crazyflie21 plus {args.effects_file.name} ({names})")
    if args.fastest:
        out = fastest_against_slowest(args.data, base)
        refs = ", ".join(f"{k} {v:.2f}" for k, v in out["references"].items())
        print(f"references (RMS speed, m/s): {refs}")
        print("reference model: " + ", ".join(f"{k} {v:.4g}"
                                              for k, v in out["reference_model"].items()))
        print(f"{out['file']} ({out['rms_speed']:.2f} m/s): {out['verdict']}: {out['answer']}")
        return 0
    out = crosscheck(args.data, args.workers, base)
    if args.effects_file is not None:
        out["effects_file"] = str(args.effects_file)
    for r in out["flights"]:
        mark = " (tentative)" if r["tentative"] else ""
        print(f"{r['file']}: {r['verdict']}{mark}: {r['answer']}")
    print(f"no_significant_gap on {out['no_significant_gap']}/{out['judged']} nominal flights "
          f"({time.perf_counter() - start:.0f} s)")
    if args.json:
        from quadsim.core.files import atomic_write_text

        atomic_write_text(args.json, json.dumps(out, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main)())
