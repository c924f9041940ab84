"""No-effect check on real flights: nominal Crazyflie flights judged against other nominal flights.

The 20 nominal flights of the Crazyflie 2.1 Brushless data (``../shared/data``, README there;
IMRCLab/crazyflie-data-collection) are all the same vehicle, so each one judged per flight
(:func:`quadsim.gap.diagnose_per_flight`) against a reference set of *other* nominal flights
should get ``no_significant_gap``: anything else is a false alarm of the diagnosis on real
data. Two folds: odd-numbered flights against the even-numbered ones, then the reverse (every
flight judged once, never against itself). Nothing here reads ``mixed/``.

Usage::

    python scripts/nominal_crosscheck.py [--data ../shared/data] [--workers 2] [--json out.json]

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
from quadsim.core.executor import run_tasks  # noqa: E402
from quadsim.gap import diagnose_per_flight  # noqa: E402
from quadsim.gap.__main__ import collapse_warnings  # noqa: E402
from quadsim.logs.flightlog import load_log  # noqa: E402
from quadsim.vehicle.params import load_params  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def folds(files: list[Path]) -> list[tuple[list[Path], list[Path]]]:
    """(tested, reference) pairs: odd against even, then even against odd."""
    even, odd = files[0::2], files[1::2]
    return [(odd, even), (even, odd)]


def crosscheck(data: Path, workers: int) -> dict:
    nominal = sorted((data / "crazyflie21_brushless" / "nominal").glob("flight_*.csv.gz"))
    if len(nominal) < 4:
        raise InputError(f"{data}: crazyflie21_brushless/nominal/flight_*.csv.gz: "
                         f"found {len(nominal)} flights, need at least 4")
    params = load_params("crazyflie21")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", QuadsimWarning)
        logs = {p: load_log(p) for p in nominal}
    for line in collapse_warnings([str(w.message) for w in caught]):
        print(f"warning: {line}", file=sys.stderr)
    rows = []
    for tested, reference in folds(nominal):
        result = diagnose_per_flight(
            [logs[p] for p in tested], [logs[p] for p in reference], params,
            map_fn=lambda fn, items: run_tasks(fn, list(items), workers=workers))
        for path, flight in zip(tested, result["flights"]):
            rows.append({"file": path.name, "outcome": flight["outcome"],
                         "verdict": flight["verdict"], "answer": flight["answer"],
                         "tentative": bool(flight.get("tentative", False))})
    rows.sort(key=lambda r: r["file"])
    clean = sum(r["outcome"] == "no_significant_gap" for r in rows)
    return {"flights": rows, "no_significant_gap": clean, "judged": len(rows)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA,
                        help="the shared data folder (default: ../shared/data)")
    parser.add_argument("--workers", type=int, default=2, help="local processes")
    parser.add_argument("--json", type=Path, help="write the per-flight rows (JSON)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    out = crosscheck(args.data, args.workers)
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
