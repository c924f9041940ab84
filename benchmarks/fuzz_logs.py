"""Fuzz the log importers: deterministic corruptions of small PX4 ULog, ArduPilot DataFlash
and Crazyflie uSD logs (written by each format's writer, ``quadsim.logs.samples``) through
``quadsim.logs.flightlog.load_log``; prints the outcome table (``benchmarks.corrupt``:
refusal, plausible, garbage, uncaught, hang) per format, and the first examples of every
outcome other than refusal and plausible.

    python -m benchmarks.fuzz_logs --cases 3400 --workers 2       # 3 x 3400 = 10,200 cases
    python -m benchmarks.fuzz_logs --cases 50 --format ulog --show 5

Same arguments, same table (cases are seeded by their index). ``--start`` skips cases.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from benchmarks.corrupt import FORMATS, OUTCOMES, judge, make_case


def _run(job: tuple[str, int, int, float]) -> list[tuple[str, int, str, str, str]]:
    fmt, start, stop, time_s = job
    out = []
    with tempfile.TemporaryDirectory(prefix="quadsim-fuzz-") as folder:
        for index in range(start, stop):
            case = make_case(fmt, index)
            outcome, message = judge(case, Path(folder), time_s=time_s)
            out.append((fmt, index, case.kind, outcome,
                        f"{case.kind} ({case.detail}): {message}"))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=3400, help="cases per format")
    parser.add_argument("--start", type=int, default=0, help="first case index")
    parser.add_argument("--format", choices=FORMATS, action="append", default=None)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--time-budget", type=float, default=10.0,
                        help="parse time budget per case (s)")
    parser.add_argument("--show", type=int, default=3, help="examples per outcome shown")
    args = parser.parse_args(argv)
    formats = args.format or list(FORMATS)
    chunk = 50
    jobs = [(fmt, a, min(a + chunk, args.start + args.cases), args.time_budget)
            for fmt in formats for a in range(args.start, args.start + args.cases, chunk)]
    began = time.perf_counter()
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as pool:
            results = [r for batch in pool.map(_run, jobs) for r in batch]
    else:
        results = [r for job in jobs for r in _run(job)]
    wall = time.perf_counter() - began
    table = Counter((fmt, outcome) for fmt, _, _, outcome, _ in results)
    print(f"{len(results)} cases in {wall:.0f} s ({args.workers} worker(s))")
    print("| format | " + " | ".join(OUTCOMES) + " |")
    print("|---|" + "---|" * len(OUTCOMES))
    for fmt in formats:
        print(f"| {fmt} | " + " | ".join(str(table[(fmt, o)]) for o in OUTCOMES) + " |")
    kinds = Counter((kind, outcome) for _, _, kind, outcome, _ in results)
    print("\nper corruption kind: " + "; ".join(
        f"{k}: " + ", ".join(f"{o} {kinds[(k, o)]}" for o in OUTCOMES if kinds[(k, o)])
        for k in sorted({k for k, _ in kinds})))
    for outcome in OUTCOMES[2:]:
        shown = [r for r in results if r[3] == outcome][:args.show]
        for fmt, index, _, _, message in shown:
            print(f"{outcome}: {fmt} case {index}: {message}")
    bad = sum(table[(f, o)] for f in formats for o in OUTCOMES[2:])
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
