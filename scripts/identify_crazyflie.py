"""Write models/crazyflie21.toml: the Crazyflie 2.1 Brushless parameter set.

The set is the skeleton ``docs/examples/crazyflie21_skeleton.toml`` (what the
crazyflie21_brushless data README and its thrust stand give: mass, rotor layout and spins,
radius, Izz, max_speed) plus what the project's own identification determines from the 20
*nominal* flights (never ``mixed/``): b, d (yaw balance, instrumental variables, given Izz),
Ixx and Iyy (4-16 Hz band) and the lagged, voltage-dependent motor map. This script only runs::

    python -m quadsim.identify \\
        --logs ../shared/data/crazyflie21_brushless/nominal/flight_*.csv.gz \\
        --vehicle docs/examples/crazyflie21_skeleton.toml -o models/crazyflie21.toml

Until 2026-11-28 it fitted b and a straight-line map itself and took d = 0.006 m x b from the
README (the brushed Crazyflie's firmware value); the flights' yaw balance reads 0.0015 m x b
(docs/gap.md, CHANGELOG.md).

Usage::

    python scripts/identify_crazyflie.py [--data ../shared/data/crazyflie21_brushless]
                                         [--out models/crazyflie21.toml]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from quadsim.core.errors import InputError, run_cli  # noqa: E402
from quadsim.identify.__main__ import main as identify_main  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SKELETON = ROOT / "docs" / "examples" / "crazyflie21_skeleton.toml"


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path,
                        default=ROOT.parent / "shared/data/crazyflie21_brushless",
                        help="folder holding nominal/flight_*.csv.gz")
    parser.add_argument("--out", type=Path, default=ROOT / "models/crazyflie21.toml")
    args = parser.parse_args(argv)
    nominal = sorted((args.data / "nominal").glob("flight_*.csv*"))
    if not nominal:
        raise InputError(f"{args.data / 'nominal'}: no flight_*.csv(.gz) files")
    return identify_main(["--logs", *map(str, nominal), "--vehicle", str(SKELETON),
                          "-o", str(args.out)])


if __name__ == "__main__":
    sys.exit(main())
