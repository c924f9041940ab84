"""Issue 47's out-of-library cases (:mod:`.unmodelled`), judged once each.

Self-generated source (:func:`benchmarks.gap_benchmark.run_case`: three inverse-dynamics
flights, two train, one held out) and the sensor-pipeline source (:func:`.cases.run_case`,
held out, then :func:`.cases.run_per_flight`: each case's first flight against the source's 8
nominal flights of the vehicle; a gyro mounted askew, :mod:`.imu_error`, on this source only).
RotorPy has no such case (:data:`.cases.ROTORPY_UNMODELLED`
says why). Printed per case and mode: the verdict, its probability, whether a name is
tentative, the lead reading (the held-out best candidate; per flight the most probable
reading and its probability) and whether it is a confident wrong name
(:func:`.score.score_case`: any name not flagged tentative, the hidden effect being outside
the library).

Usage::

    python -m benchmarks.outside_run --cache /tmp/outside_cache --out outside.json \\
        [--references-from /tmp/rpcache] [--jobs 1] [--source self|pipeline] [--only NAME]

``--references-from DIR``: copy the pipeline source's reference flights from another cache
directory (same keys, :func:`.cases.reference_key`) instead of flying them again.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import warnings
from multiprocessing import Pool
from pathlib import Path

from quadsim.core.executor import limit_numeric_threads

__all__ = ["main", "row_line"]


def _self_case(case: dict) -> dict:
    from benchmarks.gap_benchmark import _self_score, run_case

    row = run_case(case)
    named = row["verdict"] not in ("no_significant_gap", "unexplained")
    return {"source": "self-generated", "mode": "held-out", "vehicle": case["vehicle"],
            "truth": case["truth"], "seed": case["seed"], "verdict": row["verdict"],
            "probability": row.get("probability"), "tentative": named and row["tentative"],
            "lead": row.get("best_candidate"), "lead_probability": None,
            "confident_wrong": _self_score(row)["confident_wrong"],
            "seconds": row["seconds"]}


def _pipeline_heldout(case: dict) -> dict:
    from benchmarks.cases import run_case

    return run_case(case)


def _verdict_name(v: dict) -> str:
    return "+".join(v["lead"]) if v["outcome"] == "named" else v["outcome"]


def _pipeline_rows(rows: list[dict], per_flight: dict) -> list[dict]:
    out = []
    for row in rows:
        h = row["heldout"]
        out.append({"source": "pipeline", "mode": "held-out", "vehicle": row["vehicle"],
                    "truth": row["truth"], "seed": row["seed"], "verdict": _verdict_name(h),
                    "probability": h["probability"],
                    "tentative": h["outcome"] == "named" and not h["confident"],
                    "lead": h.get("best_candidate"), "lead_probability": None,
                    "confident_wrong": h["score"]["confident_wrong"], "spec": row["spec"],
                    "seconds": row["seconds"]})
        p = per_flight[row["seed"]]
        out.append({"source": "pipeline", "mode": "per-flight", "vehicle": row["vehicle"],
                    "truth": row["truth"], "seed": row["seed"], "verdict": _verdict_name(p),
                    "probability": p["probability"],
                    "tentative": p["outcome"] == "named" and not p["confident"],
                    "lead": p.get("lead_reading"), "lead_probability": p.get("lead_probability"),
                    "confident_wrong": p["score"]["confident_wrong"], "spec": row["spec"],
                    "lack_of_fit": p.get("lack_of_fit"), "answer": p.get("answer")})
    return out


def _copy_references(source_dir: str, target_dir: str) -> int:
    """Copy the pipeline reference flights' cache entries (count copied)."""
    from benchmarks import cases

    copied = 0
    for vehicle in cases.VEHICLES:
        for k in range(cases.REFERENCES):
            key = cases.reference_key("pipeline", vehicle, k)
            os.environ[cases.CACHE_ENV] = source_dir
            src = cases._entry(key)
            os.environ[cases.CACHE_ENV] = target_dir
            dst = cases._entry(key)
            if src.exists() and not dst.exists():
                dst.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(src, dst)
                copied += 1
    return copied


def row_line(r: dict) -> str:
    """One Markdown table row of a judged case."""
    prob = "-" if r["probability"] is None else f"{r['probability']:.3f}"
    lead = r["lead"] or "-"
    if r.get("lead_probability") is not None:
        lead += f" ({r['lead_probability']:.2f})"
    return (f"| {r['source']} | {r['mode']} | {r['vehicle']} | {r['truth']} | {r['verdict']} "
            f"| {prob} | {'yes' if r['tentative'] else 'no'} | {lead} "
            f"| {'YES' if r['confident_wrong'] else 'no'} |")


@limit_numeric_threads
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cache", required=True, help="flight cache directory (created)")
    parser.add_argument("--out", required=True, help="JSON file of the judged rows")
    parser.add_argument("--references-from", help="cache directory to copy references from")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--source", choices=("all", "self", "pipeline"), default="all")
    parser.add_argument("--only", action="append", metavar="NAME",
                        help="judge only the cases of this hidden effect (repeatable)")
    args = parser.parse_args(argv)
    if args.references_from and not Path(args.references_from).is_dir():
        print(f"error: {args.references_from}: --references-from: not a directory",
              file=sys.stderr)
        return 2
    from benchmarks import cases
    from benchmarks.gap_benchmark import case_list as self_case_list
    from benchmarks.unmodelled import UNMODELLED
    from quadsim.core.errors import QuadsimWarning
    from quadsim.core.files import atomic_write_text

    warnings.simplefilter("ignore", QuadsimWarning)
    cache = str(Path(args.cache).resolve())
    Path(cache).mkdir(parents=True, exist_ok=True)
    if args.references_from:
        copied = _copy_references(str(Path(args.references_from).resolve()), cache)
        print(f"copied {copied} reference flight(s) from {args.references_from}", file=sys.stderr)
    os.environ[cases.CACHE_ENV] = cache
    rows = []
    with Pool(args.jobs) as pool:
        if args.source in ("all", "self"):
            todo = [c for c in self_case_list() if c["truth"] in UNMODELLED
                    and (not args.only or c["truth"] in args.only)]
            rows += pool.map(_self_case, todo)
        if args.source in ("all", "pipeline"):
            todo = [c for c in cases.unmodelled_cases() if not args.only
                    or c["truth"] in args.only]
            held = pool.map(_pipeline_heldout, todo)
            groups = [("pipeline", v, [r for r in held if r["vehicle"] == v])
                      for v in cases.VEHICLES if any(r["vehicle"] == v for r in held)]
            per_flight = {}
            for (_, _, group), verdicts in zip(groups, pool.map(cases.run_per_flight, groups)):
                per_flight.update({row["seed"]: v for row, v in zip(group, verdicts)})
            for row in held:
                row.pop("_log", None)
            rows += _pipeline_rows(held, per_flight)
    atomic_write_text(Path(args.out), json.dumps(rows, indent=1, default=str))
    print("| source | mode | vehicle | hidden | verdict | probability | tentative | lead reading "
          "| confident wrong |\n|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(row_line(r))
    wrong = sum(r["confident_wrong"] for r in rows)
    print(f"\nconfident wrong names: {wrong}/{len(rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
