#!/usr/bin/env python3
"""Regenerate models/physical.toml and models/computational.toml from the identification.

The numbers in those files are never typed: this script runs quadsim.identify on the
packaged report tables (quadsim/identify/data/*.csv) and writes the parameter sets (atomically).
With --stand-data it first refits the 10-inch propeller's torque/thrust ratio d/b from a
thrust-stand sweep (torque, thrust, RPM) and rewrites quadsim/identify/data/torque_thrust_ratio.csv.
--check writes nothing and exits 1 if a committed file differs from a fresh rendering.

    python scripts/write_params.py                       # rewrite the two TOML files
    python scripts/write_params.py --check               # are they up to date?
    python scripts/write_params.py --stand-data ../shared/data/thrust_stand/kde2814_10inch_sweep.csv
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run from a checkout

from quadsim.core.errors import run_cli
from quadsim.core.files import atomic_write_text
from quadsim.identify import fit_thrust_stand, identify_testbed
from quadsim.identify.benchdata import DATA_DIR, load_thrust_stand
from quadsim.identify.paramsets import render_computational, render_physical, render_ratio_csv
from quadsim.vehicle.params import MODELS_DIR

STAND_SOURCE = ("KDE2814XF-775 motor + 10x3.3 carbon propeller on an RCbenchmark 1580 stand, "
                "up-and-down ESC sweep (Du et al., 'Computational Multicopter Design', 2016; "
                "github.com/mit-gfx/multicopter_design resources/measurement, "
                "kde2814_10inch_sweep.csv)")


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stand-data", type=Path, metavar="CSV",
                        help="thrust-stand sweep (esc_us, torque_Nm, thrust_N, speed_rpm) to "
                             "refit the torque/thrust ratio from")
    parser.add_argument("--stand-source", default=STAND_SOURCE,
                        help="source text stored with the ratio (default: the 10-inch sweep)")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if a file differs from a fresh rendering")
    args = parser.parse_args(argv)

    outputs = {}
    with tempfile.TemporaryDirectory() as scratch:
        ratio_path = None
        if args.stand_data:
            sweep = dataclasses.replace(load_thrust_stand(args.stand_data),
                                        source=args.stand_source)
            text = render_ratio_csv(fit_thrust_stand(sweep))
            outputs[DATA_DIR / "torque_thrust_ratio.csv"] = text
            ratio_path = Path(scratch) / "torque_thrust_ratio.csv"
            ratio_path.write_text(text, encoding="utf-8")
        ident = identify_testbed(ratio_path=ratio_path)
    outputs[MODELS_DIR / "physical.toml"] = render_physical(ident)
    outputs[MODELS_DIR / "computational.toml"] = render_computational(ident)

    if args.check:
        stale = [p for p, text in outputs.items()
                 if not p.is_file() or p.read_text(encoding="utf-8") != text]
        for path in stale:
            print(f"out of date: {path}", file=sys.stderr)
        return 1 if stale else 0
    for path, text in outputs.items():
        atomic_write_text(path, text)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
