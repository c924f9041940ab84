"""Inertia comparison: ``python -m quadsim.inertia_report [cad/] [--check]``.

Prints side by side, with relative differences to the report's SolidWorks model:

* **trimesh**: :func:`quadsim.cad.massprops.vehicle_mass_properties` of the CAD folder, for the
  whole vehicle (weighed mass) and for the mechanical parts of report Table 4.1 alone (the
  parts the SolidWorks model contained, report Fig. 4.1: "without the on-board system");
* **MuJoCo**: MuJoCo's own compiler on the same meshes with the same masses
  (``inertia="exact"`` mesh integration, an independent implementation);
* **SolidWorks**: report Fig. 4.3 / Appendix D: m 0.8098 kg, Ixx 0.00628, Iyy 0.00631,
  Izz 0.01206 kg m^2;
* **lumped**: report eq. 3.18/3.19 ``2 M R^2/5 + 2 (4) l^2 m`` with Table 4.4 means;
* **bifilar**: Table 4.14 periods through the report's formula (no T^2, units kg m^2/s) and
  through the corrected ``I = m g R^2 T^2 / (4 pi^2 L)`` (:mod:`quadsim.identify.bifilar`).

``--check`` (run by ``.ci/run``) exits non-zero when trimesh and MuJoCo differ by more than
1e-6 relative (mass, CoM, inertia) or when the mechanical subset's principal moments differ
from SolidWorks' by more than 10 %. ``docs/cad.md`` explains why the mechanical subset is the
like-for-like comparison and what remains different.
"""

from __future__ import annotations

import sys
from pathlib import Path

from .cad.assembly import load_assembly
from .core.args import ArgumentParser
from .core.errors import ModelError, run_cli
from .core.shipped import shipped_dir
from .identify.inertia_compare import (
    SOLIDWORKS,
    Row,
    agreement_lines,
    check_rows,
    mujoco_mass_properties,
    report_rows,
)

__all__ = ["SOLIDWORKS", "Row", "check_rows", "main", "mujoco_mass_properties", "report_rows"]

DEFAULT_CAD = shipped_dir("cad")
def format_rows(rows: list[Row]) -> str:
    """The human table: mass, CoM z, Ixx/Iyy/Izz and their difference to SolidWorks."""
    head = (f"{'source':<38} {'mass kg':>9} {'CoM z mm':>9} {'Ixx':>10} {'Iyy':>10} "
            f"{'Izz':>10}   {'vs SolidWorks (Ixx, Iyy, Izz)':<28} note")
    lines = [head, "-" * len(head)]
    for r in rows:
        rel = r.moments / SOLIDWORKS.moments - 1
        com = f"{1000 * r.com[2]:9.3f}" if r.com is not None else f"{'':>9}"
        lines.append(f"{r.label:<38} {r.mass:9.5f} {com} " + " ".join(
            f"{v:10.5g}" for v in r.moments) + "   " + " ".join(f"{100 * v:+8.1f}%" for v in rel)
            + f"  {r.note}")
    lines.append("(inertia in kg m^2 about the CoM, body axes; bifilar 'as published' has the "
                 "report's units kg m^2/s)")
    return "\n".join(lines)


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(
        prog="python -m quadsim.inertia_report",
        description="Compare the CAD mass properties (trimesh) with MuJoCo's compile of the "
                    "same meshes, the report's SolidWorks values, its lumped formula and its "
                    "bifilar test (published and corrected).")
    parser.add_argument("cad_dir", nargs="?", type=Path, default=DEFAULT_CAD,
                        help="CAD folder (default: the shipped testbed, the repository's cad/)")
    parser.add_argument("--check", action="store_true",
                        help="exit non-zero if trimesh and MuJoCo differ by more than 1e-6 "
                             "relative or the mechanical parts' principal moments differ "
                             "from SolidWorks by more than 10 %%")
    args = parser.parse_args(argv)
    rows = report_rows(load_assembly(args.cad_dir))
    print(format_rows(rows))
    for line in agreement_lines(rows):
        print(line)
    if args.check:
        failures = check_rows(rows)
        if failures:
            raise ModelError("inertia check failed: " + "; ".join(failures))
        print("check passed: trimesh = MuJoCo within 1e-6, mechanical parts within 10 % of "
              "SolidWorks")
    return 0


if __name__ == "__main__":
    sys.exit(main())
