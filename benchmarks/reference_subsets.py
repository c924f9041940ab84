"""How many references a user needs: the 26 labelled ``mixed/`` Crazyflie flights judged per
flight, as a user types it, against random subsets of the 20 nominal flights.

For each subset size k (``--sizes``) and draw d (``--draws``), the k nominal flights are drawn
without replacement by ``random.Random(100 d + k)`` (the same subsets every run), and

    python -m quadsim.gap --model crazyflie21 --per-flight mixed/*.csv.gz \\
        --reference <the k nominal flights> --workers 1 --json OUT

runs in a fresh process with a fresh references' cache (``QUADSIM_CACHE_DIR``). Each answer is
scored as :mod:`benchmarks.reliability` scores the labelled flights (right: a payload flight
named as a mass or cable payload adding up to within 2 g of +7.4 g, a plain flight
``no_significant_gap``), and counted apart where it is ``tentative`` (the tool saying it
cannot be sure: :func:`quadsim.gap.judge.unvouched`). One line per subset: payload right,
plain right, plain named *confidently* (a name not tentative: the false alarm the tool
vouches for), and the names given to plain flights.

``--logs`` cuts every log (judged and references alike, gzip copies in a temporary folder)
to what a user may have: ``commands`` drops the ``rotor_*`` columns (speeds come from the
parameter set's motor map, with its lag and battery-voltage law: no log has speeds, so no
command model is fitted), ``imu`` keeps only ``t``, the gyro, the accelerometer, the
commands and ``vbat`` (no pose, no speeds: the body-frame balance), ``attitude`` the same
with the attitude ``qw..qz`` (the on-board estimate's, without a position); ``as-logged``
(default) leaves them. A size of 20 or more is the whole set (one draw).

Usage (needs ``../shared/data``; one subset ~10-20 s CPU on the 2-core machine)::

    python -m benchmarks.reference_subsets                         # sizes 3 5 10, 4 draws each
    python -m benchmarks.reference_subsets --sizes 3 4 --draws 8 --out subsets.json
    python -m benchmarks.reference_subsets --logs commands --sizes 3 5 20 --draws 2
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import random
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

from benchmarks.reliability import mixed_answers

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "crazyflie21_brushless"


#: the columns each ``--logs`` choice keeps (None: every column)
KEPT = {"as-logged": None,
        "commands": lambda name: not name.startswith("rotor_"),
        "imu": lambda name: name in ("t", "wx", "wy", "wz", "ax", "ay", "az", "vbat")
        or name.startswith("cmd_"),
        "attitude": lambda name: name in ("t", "qw", "qx", "qy", "qz", "wx", "wy", "wz", "ax",
                                          "ay", "az", "vbat") or name.startswith("cmd_")}


def cut_log(path: Path, keep, out: Path) -> Path:
    """A gzip copy of the flight-log CSV ``path`` (gzip) with only the columns whose name
    (stripped) ``keep(name)`` is true for (``keep`` None: every column), written to ``out``
    (no file name or time stamp in the gzip header: the same bytes for the same input; the
    commands-only cut of ``scripts/write_crazyflie_reference.py`` is this one)."""
    with gzip.open(path, "rt", newline="") as handle:
        lines = handle.read().splitlines()
    names = lines[0].split(",")
    idx = [i for i, name in enumerate(names) if keep is None or keep(name.strip())]
    text = "\n".join(",".join(row[i] for i in idx)
                     for row in (line.split(",") for line in lines)) + "\n"
    with open(out, "wb") as raw, gzip.GzipFile(filename="", fileobj=raw, mode="wb",
                                               mtime=0) as handle:
        handle.write(text.encode())
    return out


def subset(size: int, draw: int, count: int = 20) -> list[int]:
    """The nominal flights' indices of draw ``draw`` of size ``size`` (sorted)."""
    return sorted(random.Random(100 * draw + size).sample(range(count), size))


def judge(references: list[Path], out: Path, data: Path = DATA) -> dict:
    """The per-flight JSON of the 26 mixed flights against ``references`` (a fresh process
    and references' cache, one numeric thread, as a user's run)."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
               QUADSIM_CACHE_DIR=tempfile.mkdtemp(prefix="qsub_"))
    cmd = [sys.executable, "-m", "quadsim.gap", "--model", "crazyflie21", "--per-flight",
           *map(str, sorted((data / "mixed").glob("flight_*.csv.gz"))),
           "--reference", *map(str, references), "--workers", "1", "--json", str(out)]
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return json.loads(out.read_text())


def score(result: dict, labels: dict) -> dict:
    """Payload and plain flights right, plain flights named confidently, and the plain
    flights' names (verdict, tentative) counted."""
    answers = mixed_answers(result, labels)
    flights = {Path(f["file"]).name: f for f in result["flights"]}
    payload = [a for a in answers if a.truth == "payload"]
    plain = [a for a in answers if a.truth != "payload"]
    named = [flights[a.flight] for a in plain if not a.right]
    return {"payload": [sum(a.right for a in payload), len(payload)],
            "plain": [sum(a.right for a in plain), len(plain)],
            "plain_confident": sum(1 for f in named if not f.get("tentative")
                                   and f["outcome"] == "effect"),
            "plain_names": dict(Counter(
                f"{f['verdict']}{' (tentative)' if f.get('tentative') else ''}"
                for f in named))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[3, 5, 10])
    ap.add_argument("--draws", type=int, default=4)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--logs", choices=tuple(KEPT), default="as-logged",
                    help="cut every log to what a user may have (module doc)")
    ap.add_argument("--out", type=Path, help="all subsets' scores as JSON")
    args = ap.parse_args(argv)
    if not (args.data / "mixed_labels.json").is_file():
        print(f"skipped: {args.data}/mixed_labels.json not found")
        return 0
    labels = json.loads((args.data / "mixed_labels.json").read_text())
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        data = args.data
        if KEPT[args.logs] is not None:         # the cut copies, judged and references alike
            data = Path(tmp) / "data"
            for group in ("mixed", "nominal"):
                (data / group).mkdir(parents=True)
                for path in sorted((args.data / group).glob("flight_*.csv.gz")):
                    cut_log(path, KEPT[args.logs], data / group / path.name)
        for size in args.sizes:
            for draw in range(1, (1 if size >= 20 else args.draws) + 1):
                picked = subset(min(size, 20), draw)
                refs = [data / "nominal" / f"flight_{i:02d}.csv.gz" for i in picked]
                row = {"size": size, "draw": draw, "logs": args.logs, "references": picked,
                       **score(judge(refs, Path(tmp) / "r.json", data), labels)}
                rows.append(row)
                print(f"k={size} draw {draw} {picked}: payload {row['payload'][0]}/"
                      f"{row['payload'][1]}, plain {row['plain'][0]}/{row['plain'][1]}, "
                      f"plain named confidently {row['plain_confident']}"
                      f"{'; ' + str(row['plain_names']) if row['plain_names'] else ''}",
                      flush=True)
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
