"""Write models/references/crazyflie21.qref: the crazyflie21 set's shipped reference.

The stored reference (:mod:`quadsim.gap.reffile`) of the set's own 20 nominal flights
(``nominal/flight_00..19.csv.gz`` of the Crazyflie 2.1 Brushless data: IMRCLab/
crazyflie-data-collection, flights by its authors; the shared data README): their
calibrated stage (the reference model, noise model, discrepancy term and self-check) as
``python -m quadsim.gap --model crazyflie21 --reference nominal/*.csv.gz`` computes it, so
that ``--model crazyflie21`` without ``--reference`` judges against it. The file's header
names the flights and their SHA-256 and this source.

Rerun it (the maintainer's step, module doc of quadsim.gap.reffile, "Staleness") whenever
the calibration's numbers change (tests/test_reference_file_data.py fails until then) or
quadsim.gap.reffile.FORMAT is bumped::

    python scripts/write_crazyflie_reference.py [--data ../shared/data/crazyflie21_brushless]
                                                [--out models/references/crazyflie21.qref]

It runs in a temporary folder that links ``nominal/`` to the data's, so the file records
the flights as ``nominal/flight_NN.csv.gz`` (no machine's folders) and the command as one
anyone with the data can run again there. Single-threaded numerics (as the tests run).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ("the set's own 20 nominal flights: Crazyflie 2.1 Brushless figure-8s at four "
          "speeds, nominal/flight_00..19.csv.gz of IMRCLab/crazyflie-data-collection (flights "
          "by its authors); written by scripts/write_crazyflie_reference.py")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data" /
                                              "crazyflie21_brushless"))
    parser.add_argument("--out", default=str(ROOT / "models" / "references" /
                                             "crazyflie21.qref"))
    args = parser.parse_args(argv)
    nominal = Path(args.data).resolve() / "nominal"
    flights = sorted(nominal.glob("flight_*.csv.gz"))
    if len(flights) != 20:
        print(f"error: {nominal}: expected the 20 nominal flights, found {len(flights)}",
              file=sys.stderr)
        return 2
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    from quadsim.gap.__main__ import main as gap_main

    out = Path(args.out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    here = Path.cwd()
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "nominal").symlink_to(nominal)
        os.chdir(tmp)
        try:
            code = gap_main(["--model", "crazyflie21", "--no-cache", "--quiet",
                             "--reference", *[f"nominal/{f.name}" for f in flights],
                             "--write-reference", out.name, "--reference-source", SOURCE])
        finally:
            os.chdir(here)
        if code == 0:
            shutil.move(str(Path(tmp) / out.name), str(out))
            print(f"wrote {out}")
    return code


if __name__ == "__main__":
    sys.exit(main())
