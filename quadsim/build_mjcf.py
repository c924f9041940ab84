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

Library::

    >>> from quadsim.build_mjcf import build_model
    >>> model = build_model("cad")          # BuiltModel: xml text, params, mass properties
"""

from __future__ import annotations

import os
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .cad.assembly import MESH_UNITS, Assembly, load_assembly
from .cad.massprops import MassProperties, vehicle_mass_properties
from .cad.step import is_step
from .core.args import ArgumentParser
from .core.errors import InputError, ModelError, QuadsimWarning, run_cli
from .core.files import atomic_write_text
from .sim.mjcf import vehicle_xml
from .vehicle.params import MODELS_DIR, Rotor, VehicleParams, load_params

__all__ = [
    "BuiltModel",
    "build_model",
    "cad_params",
    "main",
    "mesh_geoms_xml",
    "parts_table",
    "write_model",
]


@dataclass(frozen=True, eq=False)
class BuiltModel:
    """The MJCF text, the parameter set it was built from, the CAD mass properties, and
    a note saying which inertial was written and why."""

    xml: str
    params: VehicleParams
    mass_properties: MassProperties
    assembly: Assembly
    inertial_note: str


GREY = "0.6 0.6 0.62 1"
#: Visual colour per manifest group (viewer only).
GROUP_RGBA = {"mechanical": "0.72 0.72 0.75 1", "battery": "0.2 0.3 0.75 1",
              "avionics": "0.1 0.45 0.2 1"}


def _vec(values) -> str:
    return " ".join(f"{float(v):.12g}" for v in np.ravel(values))


def _quat(rotation: np.ndarray) -> str:
    return _vec(Rotation.from_matrix(rotation).as_quat(scalar_first=True))


def cad_params(base: VehicleParams, assembly: Assembly, props: MassProperties, *,
               inertial: str = "cad") -> VehicleParams:
    """``base`` with the manifest's rotor layout and (``inertial="cad"``) the CAD mass
    properties; b, d, speed range, radius and environment stay those of ``base``."""
    rotors = tuple(Rotor(r.name, r.position.copy(), r.axis.copy(), r.spin)
                   for r in assembly.rotors)
    source = f"CAD meshes in {assembly.cad_dir.name}/ ({assembly.manifest.name}), trimesh"
    sources = dict(base.sources, rotor_layout=source)
    changes: dict = {"rotors": rotors, "sources": sources, "name": assembly.name}
    if inertial == "cad":
        changes.update(mass=props.mass, com=props.com, inertia=props.inertia)
        sources.update(mass=source, com=source, inertia=source)
    elif inertial != "params":
        raise InputError(f"--inertial: {inertial!r}; valid: cad, params")
    return base.replace(**changes)


def mesh_geoms_xml(assembly: Assembly, xml_dir: Path) -> tuple[str, str]:
    """``(assets, geoms)`` MJCF fragments: one mesh asset per part (file relative to
    ``xml_dir``, scaled to metres), one visual geom per placement, and a simple collision
    geom (box or cylinder around the part's mesh) where the part asks for one."""
    scale = _vec([MESH_UNITS[assembly.mesh_unit]] * 3)
    assets, geoms = [], []
    for part in assembly.parts:
        if is_step(part.mesh_path):               # MuJoCo reads no STEP: inline, metres
            vertex = " ".join(f"{v:.9g}" for v in np.asarray(part.mesh.vertices).ravel())
            face = " ".join(str(int(i)) for i in np.asarray(part.mesh.faces).ravel())
            assets.append(f'    <mesh name="{part.name}" vertex="{vertex}" face="{face}"/>')
        else:
            file = Path(os.path.relpath(part.mesh_path, xml_dir.resolve())).as_posix()
            assets.append(f'    <mesh name="{part.name}" file="{file}" scale="{scale}"/>')
        low, high = part.mesh.bounds
        centre, half = 0.5 * (low + high), 0.5 * (high - low)
        for p in part.placements:
            geoms.append(f'      <geom name="{part.name}:{p.name}" class="visual" type="mesh" '
                         f'mesh="{part.name}" pos="{_vec(p.position)}" '
                         f'quat="{_quat(p.rotation)}" rgba="{GROUP_RGBA.get(part.group, GREY)}"/>')
            pos = _vec(p.rotation @ centre + p.position)
            if part.collision == "box":
                size = _vec(half)
            elif part.collision == "cylinder":
                size = _vec([max(half[0], half[1]), half[2]])
            else:
                continue
            geoms.append(f'      <geom class="collision" type="{part.collision}" '
                         f'size="{size}" pos="{pos}" quat="{_quat(p.rotation)}"/>')
    return "\n".join(assets) + "\n", "\n".join(geoms)


#: MuJoCo's STL decoder refuses files with more triangles than this.
MUJOCO_STL_FACE_LIMIT = 200_000


def _check_mujoco_limits(assembly: Assembly) -> None:
    for i, part in enumerate(assembly.parts):
        faces = len(part.mesh.faces)
        if part.mesh_path.suffix.lower() == ".stl" and faces > MUJOCO_STL_FACE_LIMIT:
            raise InputError(f"{assembly.manifest}: part[{i}] ({part.name}).mesh: "
                             f"{part.mesh_path.name} has {faces} triangles; MuJoCo reads at most "
                             f"{MUJOCO_STL_FACE_LIMIT} per STL file: split the part or decimate "
                             "its mesh")


def build_model(cad_dir: str | Path, *, params: str | Path = "physical",
                output: str | Path | None = None, inertial: str = "cad",
                hull: bool = False) -> BuiltModel:
    """Load the CAD folder and the parameter set and produce the MJCF text (not written).

    ``output`` is where the MJCF will live (mesh paths are made relative to it); default
    ``models/<assembly name>.xml``."""
    assembly = load_assembly(cad_dir, hull=hull)
    props = vehicle_mass_properties(assembly)
    base = load_params(params, check=inertial != "cad")
    output = Path(output) if output else MODELS_DIR / f"{assembly.name}.xml"
    vehicle = cad_params(base, assembly, props, inertial=inertial)
    from .vehicle.guards import check_hover_control

    check_hover_control(  # CAD mass with the set's b and speed range: can it hover?
        vehicle, where=f"{assembly.manifest} + {base.path or base.name}",
        mass_field="mass (CAD parts)" if inertial == "cad" else "body.mass")
    if inertial == "cad":
        note = ("inertial from the CAD meshes (trimesh): mass/CoM/inertia of the parts in "
                f"{assembly.manifest.parent.name}/{assembly.manifest.name}")
        if "cad" not in base.sources.get("inertia", "").lower():
            note += (f"; parameter set {base.name!r} has its own mass {base.mass:.6g} kg and "
                     f"inertia ({base.sources.get('inertia', 'no source')}), not used here "
                     "(--inertial params writes those instead)")
    else:
        note = (f"inertial from parameter set {base.name!r} ({base.path}): "
                f"{base.sources.get('inertia', '')}; the CAD mass properties are NOT used "
                "(--inertial params)")
    _check_mujoco_limits(assembly)
    assets, geoms = mesh_geoms_xml(assembly, output.parent)
    comment = (f"generated by python -m quadsim.build_mjcf from {assembly.manifest.name}; "
               f"{note}; ctrl = Omega^2 (rad^2/s^2)").replace("--", "option ")  # XML comments
    xml = vehicle_xml(vehicle, visual_geoms=geoms, assets=assets, comment=comment)
    return BuiltModel(xml, vehicle, props, assembly, note)


def write_model(model: BuiltModel, output: str | Path) -> Path:
    """Check that MuJoCo compiles ``model`` at ``output``'s location, then write it
    atomically. Nothing is written when the check fails (ModelError)."""
    import mujoco

    output = Path(output)
    created = [p for p in (output.parent, *output.parent.parents) if not p.exists()]
    probe = output.parent / f".{output.stem}.check.xml"
    try:
        output.parent.mkdir(parents=True, exist_ok=True)
        probe.write_text(model.xml, encoding="utf-8")
        mujoco.MjModel.from_xml_path(str(probe))
    except (ValueError, OSError) as exc:
        probe.unlink(missing_ok=True)
        for folder in created:  # leave nothing behind, not even the folders we made
            if folder.exists():
                folder.rmdir()
        if isinstance(exc, OSError):
            raise InputError(f"{output}: cannot write: {exc.strerror or exc}") from None
        message = " ".join(str(exc).split())
        raise ModelError(f"{output}: MuJoCo refuses the generated model: {message}") from None
    probe.unlink(missing_ok=True)
    return atomic_write_text(output, model.xml)


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
    parser.add_argument("cad_dir", type=Path, help="CAD folder with meshes and one manifest "
                                                   "*.toml (e.g. cad/)")
    parser.add_argument("-o", "--output", type=Path, default=None,
                        help="MJCF to write (default: models/<assembly name>.xml)")
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
    output = args.output or MODELS_DIR / f"{model.assembly.name}.xml"
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
