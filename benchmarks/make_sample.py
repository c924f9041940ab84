"""Write the suite's small cached sample of an independent source, and its recorded verdicts.

The suite cannot install the foreign simulators (benchmarks/README.md), so a few flights of
one of them are committed: ``tests/data/independent_sample/`` holds quadcopter-sim flights
(:mod:`benchmarks.qcsim_cases`: its frozen references and cases, flown by
:func:`benchmarks.qcsim_source.qcsim_flights`, the same code as
``python -m benchmarks.gap_benchmark --independent --source quadcopter-sim``), each as
``NAME.csv.gz`` (flight-log schema) with its truth sidecar ``NAME.truth.json``, and
``verdicts.json``: each case's per-flight verdict against the references
(:func:`quadsim.gap.diagnose_per_flight`, read by :func:`benchmarks.score.read_verdict`) and
its score against the truth. ``tests/test_independent_sample.py`` judges the sample again and
asserts those verdicts.

Size: the logs are thinned to ``--rate`` Hz (every k-th sample of the source's 500 Hz log, no
filter: the sensor noise stays white at the lower rate) and written with ``--digits``
significant digits, so the whole sample stays a few hundred kB.

    python -m benchmarks.make_sample --out tests/data/independent_sample \\
        [--references 0 2 4 6] [--cases 0 6 20] [--rate 50] [--digits 6]

Needs quadcopter-sim (``pip install --no-deps quadcopter-sim==0.3.0 typing_extensions``).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from quadsim.core.errors import InputError, QuadsimWarning, run_cli
from quadsim.core.files import atomic_write_bytes, atomic_write_text
from quadsim.logs.flightlog import FlightLog, load_log, log_bytes

#: the sample's source rate (Hz): every simulator source logs at 500 Hz
SOURCE_RATE = 500.0


_FIELDS = ("position", "quat", "velocity", "body_rate", "accel", "rotor_speed",
           "rotor_command", "vbat")


def thinned(log: FlightLog, rate: float, digits: int) -> FlightLog:
    """Every k-th sample of ``log`` (k = SOURCE_RATE / rate, an integer), each value but the
    time rounded to ``digits`` significant digits; nothing else changed."""
    k = SOURCE_RATE / rate
    if k < 1 or abs(k - round(k)) > 1e-9:
        raise InputError(f"--rate: {rate:g} Hz does not divide {SOURCE_RATE:g} Hz")
    keep = slice(None, None, round(k))
    rounded = np.vectorize(lambda v: float(f"{v:.{digits}g}"), otypes=[float])
    fields = {name: (None if getattr(log, name) is None
                     else rounded(np.asarray(getattr(log, name), dtype=float)[keep]))
              for name in _FIELDS}
    return FlightLog(t=np.asarray(log.t)[keep], **fields)


def judge_sample(folder: Path) -> dict:
    """Per-flight verdicts of the sample's cases against its references: {case file name:
    {"truth", "kind", "verdict": read_verdict(...), "score": score_case(...)}}."""
    from benchmarks import qcsim_cases
    from benchmarks.score import read_verdict, score_case
    from quadsim.gap import diagnose_per_flight

    refs = [load_log(p, warn=False) for p in sorted(folder.glob("ref_*.csv.gz"))]
    names = sorted(p.name for p in folder.glob("case_*.csv.gz"))
    truths = [json.loads((folder / n.replace(".csv.gz", ".truth.json")).read_text())
              for n in names]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        result = diagnose_per_flight([load_log(folder / n, warn=False) for n in names], refs,
                                     qcsim_cases.vehicle_params())
    out = {}
    for name, truth, flight in zip(names, truths, result["flights"]):
        verdict = read_verdict(flight)
        out[name] = {"truth": truth["truth"], "kind": truth["kind"], "verdict": verdict,
                     "score": score_case(truth["truth"], truth["kind"], verdict)}
    return out


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, type=Path, help="sample folder (created)")
    parser.add_argument("--references", type=int, nargs="+", default=[0, 2, 4, 6],
                        help="indices into qcsim_cases.reference_specs()")
    parser.add_argument("--cases", type=int, nargs="+", default=[0, 6, 20],
                        help="indices into qcsim_cases.case_list()")
    parser.add_argument("--rate", type=float, default=50.0, help="sample rate written (Hz)")
    parser.add_argument("--digits", type=int, default=6, help="significant digits written")
    args = parser.parse_args(argv)
    from benchmarks import qcsim_cases
    from benchmarks.qcsim_source import qcsim_available
    from benchmarks.sim_cases import _name
    from benchmarks.simlog import truth_json

    if not qcsim_available():
        raise InputError("quadcopter-sim: not installed (pip install --no-deps "
                         "quadcopter-sim==0.3.0 typing_extensions)")
    refs, cases = qcsim_cases.reference_specs(), qcsim_cases.case_list()
    jobs = ([(_name("ref", k, ""), refs[k], None) for k in args.references]
            + [(_name("case", k, cases[k]["case"]), qcsim_cases.case_spec(cases[k]), cases[k])
               for k in args.cases])
    args.out.mkdir(parents=True, exist_ok=True)
    for (name, _, case), (log, truth) in zip(jobs, qcsim_cases.SOURCE.fly([j[1] for j in jobs])):
        if case is not None:
            truth = {**truth, "truth": case["truth"], "kind": case["kind"], "case": case["case"]}
        truth = {**truth, "sample": {"log_hz": args.rate, "digits": args.digits,
                                     "written_by": "benchmarks/make_sample.py"}}
        atomic_write_text(args.out / f"{name}.truth.json", truth_json(truth))
        atomic_write_bytes(args.out / f"{name}.csv.gz",
                           log_bytes(thinned(log, args.rate, args.digits), gzipped=True))
    verdicts = judge_sample(args.out)
    atomic_write_text(args.out / "verdicts.json", json.dumps(verdicts, indent=1, sort_keys=True)
                      + "\n")
    for name, row in verdicts.items():
        print(f"{name}: {row['verdict']['outcome']} {row['verdict']['lead']} "
              f"(truth {row['truth']}, {row['kind']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
