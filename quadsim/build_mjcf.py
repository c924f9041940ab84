"""Build the vehicle's MJCF from a CAD folder: ``python -m quadsim.build_mjcf cad/``.

The body's mass, centre of mass and full inertia come from the meshes
(:func:`quadsim.cad.massprops.vehicle_mass_properties`) and are written as an explicit
``<inertial fullinertia=...>`` so MuJoCo never recomputes them; the rotor sites and
actuators come from the manifest's rotors; b, d and the speed range come from a parameter
set (``--params``, default ``physical``). Meshes are visual geoms (class ``visual``, no mass)
referenced relative to the MJCF with the mesh unit's scale (``0.001`` for mm); parts marked
``collision = "box"|"cylinder"`` get a simple collision geom of their bounding shape.

The actuator control is the squared rotor speed Omega^2 in rad^2/s^2 (see
:mod:`quadsim.sim.mjcf`). Example::

    python -m quadsim.build_mjcf cad/                         # -> models/testbed.xml
    python -m quadsim.build_mjcf cad/ -o /tmp/x.xml --params computational
    python -m quadsim.build_mjcf cad/ --params physical --inertial params

The model is built by :mod:`quadsim.sim.model` (``build_model``, ``write_model``).
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from .cad.massprops import MassProperties
from .core.args import ArgumentParser
from .core.errors import InputError, QuadsimWarning, run_cli
from .core.shipped import shipped_dir
from .sim.model import BuiltModel, build_model, default_output, write_model

__all__ = ["BuiltModel", "build_model", "main", "parts_table", "write_model"]


def parts_table(props: MassProperties) -> str:
    """Human table: one row per placed part (mass g, CoM mm, inertia about its own CoM in
    body axes, kg m^2) and the vehicle total (inertia about the vehicle CoM)."""
    head = (f"{'part':<20} {'inst':<6} {'mass g':>8} {'CoM x,y,z mm':>26} "
            f"{'Ixx':>10} {'Iyy':>10} {'Izz':>10} {'Ixy':>10} {'Ixz':>10} {'Iyz':>10}")
    rows = [head, "-" * len(head)]

    def row(name, inst, mass, com, inertia):
        c = ",".join(f"{1000 * v:8.2f}" for v in com)
        i = inertia
        return (f"{name:<20} {inst:<6} {1000 * mass:8.3f} {c:>26} " + " ".join(
            f"{v:10.3e}" for v in (i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2])))

    for p in props.parts:
        rows.append(row(p.part, p.placement, p.mass, p.com, p.inertia))
    rows.append("-" * len(head))
    rows.append(row("TOTAL (about CoM)", "", props.mass, props.com, props.inertia))
    return "\n".join(rows)


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(
        prog="python -m quadsim.build_mjcf",
        description="Write a MuJoCo MJCF of the vehicle in a CAD folder: mass properties "
                    "from the meshes (explicit fullinertia at the CoM), mesh visual geoms, "
                    "simple collision geoms, one site and one actuator per rotor "
                    "(ctrl = Omega^2 in rad^2/s^2, gear from b and d). Prints the parts "
                    "table and the total.")
    parser.add_argument("cad_dir", type=Path, nargs="?", default=shipped_dir("cad"),
                        help="CAD folder with meshes and one manifest *.toml (default: the "
                             "shipped testbed, the repository's cad/)")
    parser.add_argument("-o", "--output", type=Path, default=None,
                        help="MJCF to write (default: models/<assembly name>.xml in a "
                             "repository checkout; ./<assembly name>.xml when installed)")
    parser.add_argument("--params", default="physical",
                        help="parameter set NAME in models/ or a TOML FILE giving b, d and the "
                             "speed range (default: physical)")
    parser.add_argument("--inertial", choices=("cad", "params"), default="cad",
                        help="which mass properties the <inertial> gets: the CAD meshes "
                             "(default) or the parameter set's own")
    parser.add_argument("--hull", action="store_true",
                        help="replace a non-watertight or badly wound mesh by its convex hull "
                             "(warns; mass properties become approximate)")
    args = parser.parse_args(argv)
    from .core.args import check_output  # before any work

    if not args.cad_dir.is_dir():
        raise InputError(f"{args.cad_dir}: CAD folder not found (give the folder holding the "
                         "meshes and the manifest)")
    if args.output is not None:  # its folder (models/ by default) is created on success
        folder = args.output.parent
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        check_output("--output", folder / args.output.name, (".xml",))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", QuadsimWarning)
        model = build_model(args.cad_dir, params=args.params, output=args.output,
                            inertial=args.inertial, hull=args.hull)
    for warning in caught:  # one line each, after the fact, instead of Python's two-line form
        print(f"warning: {warning.message}", file=sys.stderr)
    output = args.output or default_output(model.assembly.name)
    print(parts_table(model.mass_properties))
    print(f"note: {model.inertial_note}")
    written = write_model(model, output)
    p = model.params
    print(f"wrote {written} ({p.rotor_count} rotors, ctrl = Omega^2 in rad^2/s^2, "
          f"b = {p.thrust_factor:.6g} N s^2/rad^2, d = {p.drag_factor:.6g} N m s^2/rad^2 "
          f"from {p.name}: {p.sources.get('rotors.thrust_factor', 'no source')})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
