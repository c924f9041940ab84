"""Write models/references/crazyflie21.qref and crazyflie21_commands.qref: the crazyflie21
set's shipped references.

The stored references (:mod:`quadsim.gap.reffile`) of the set's own 20 nominal flights
(``nominal/flight_00..19.csv.gz`` of the Crazyflie 2.1 Brushless data: IMRCLab/
crazyflie-data-collection, flights by its authors; the shared data README):

- ``crazyflie21.qref`` (logs with rotor speeds): their calibrated stage (the reference
  model, noise model, discrepancy term and self-check) as ``python -m quadsim.gap --model
  crazyflie21 --reference nominal/*.csv.gz`` computes it;
- ``crazyflie21_commands.qref`` (logs with the motor commands only, as most users log):
  the same flights with their rotor-speed columns cut (``cmd/flight_NN.csv.gz``: every
  ``rotor_*`` column dropped, the rest as logged) calibrated on speeds synthesised from the
  commands by the command -> speed model fitted on the originals, with that model: as
  ``--reference cmd/*.csv.gz --command-reference nominal/*.csv.gz`` computes it;

so that ``--model crazyflie21`` without ``--reference`` judges against the one that fits
the judged logs. Each file's header names the flights and their SHA-256 and this source.

Rerun it (the maintainer's step, module doc of quadsim.gap.reffile, "Staleness") whenever
the calibration's numbers change (tests/test_reference_file_data.py fails until then) or
quadsim.gap.reffile.FORMAT is bumped::

    python scripts/write_crazyflie_reference.py [--data ../shared/data/crazyflie21_brushless]
                                                [--out-dir models/references]
                                                [--only speeds|commands]

It runs in a temporary folder that links ``nominal/`` to the data's (and writes ``cmd/``
there, gzip without a time stamp: the same bytes each time), so the files record the
flights as ``nominal/flight_NN.csv.gz`` and ``cmd/flight_NN.csv.gz`` (no machine's folders)
and the commands as ones anyone with the data can run again there (``cmd/``: cut as above,
e.g. ``zcat nominal/flight_00.csv.gz | cut -d, -f1-17,22-26``). Single-threaded numerics
(as the tests run).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))      # benchmarks (the commands-only cut)
FLIGHTS = ("the set's own 20 nominal flights: Crazyflie 2.1 Brushless figure-8s at four "
           "speeds, nominal/flight_00..19.csv.gz of IMRCLab/crazyflie-data-collection (flights "
           "by its authors)")
SOURCE = f"{FLIGHTS}; written by scripts/write_crazyflie_reference.py"
COMMANDS_SOURCE = (f"{FLIGHTS}, their rotor-speed columns cut (cmd/), speeds synthesised by "
                   "the command model fitted on the originals (--command-reference nominal/); "
                   "written by scripts/write_crazyflie_reference.py")


def cut_speeds(src: Path, dst: Path) -> None:
    """``dst``: the CSV log ``src`` (gzip) without its ``rotor_*`` columns, gzip with no
    time stamp (the same bytes for the same input): :func:`benchmarks.reference_subsets.
    cut_log`'s ``commands`` cut."""
    from benchmarks.reference_subsets import KEPT, cut_log

    cut_log(src, KEPT["commands"], dst)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data" /
                                              "crazyflie21_brushless"))
    parser.add_argument("--out-dir", default=str(ROOT / "models" / "references"))
    parser.add_argument("--only", choices=("speeds", "commands"), default=None)
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

    out_dir = Path(args.out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    originals = [f"nominal/{f.name}" for f in flights]
    cut = [f"cmd/{f.name}" for f in flights]
    runs = {"speeds": ("crazyflie21.qref", originals, (), SOURCE),
            "commands": ("crazyflie21_commands.qref", cut,
                         ("--command-reference", *originals), COMMANDS_SOURCE)}
    here = Path.cwd()
    code = 0
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "nominal").symlink_to(nominal)
        (Path(tmp) / "cmd").mkdir()
        for f in flights:
            cut_speeds(f, Path(tmp) / "cmd" / f.name)
        os.chdir(tmp)
        try:
            for which, (name, refs, extra, source) in runs.items():
                if args.only not in (None, which):
                    continue
                code = gap_main(["--model", "crazyflie21", "--no-cache", "--quiet",
                                 "--reference", *refs, *extra, "--write-reference", name,
                                 "--reference-source", source])
                if code != 0:
                    return code
                shutil.move(str(Path(tmp) / name), str(out_dir / name))
                print(f"wrote {out_dir / name}")
        finally:
            os.chdir(here)
    return code


if __name__ == "__main__":
    sys.exit(main())
