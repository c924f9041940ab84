"""The CAD assembly: a folder of meshes plus a TOML manifest, loaded into frozen objects.

A CAD folder (``cad/`` for the testbed) holds one mesh file per part (STL as exported from a
CAD tool, in the unit named by ``mesh_unit``, or STEP, which declares its own unit: see
:mod:`quadsim.cad.step`) and one manifest ``*.toml`` (schema
``quadsim.cad/1``, documented in ``docs/cad.md``) that says, for each part, its mesh, its
mass per instance (measured) or its density, and where each instance sits in the vehicle;
and which part placements are rotors, with their spin direction.

Example::

    >>> from quadsim.cad.assembly import load_assembly
    >>> assembly = load_assembly("cad")
    >>> [r.name for r in assembly.rotors], assembly.rotors[0].position
    (['1', '2', '3', '4'], array([0.197667, 0., 0.04135]))

Conventions: meshes are converted to metres at load (``mesh_unit``: mm, cm, m, in);
placements are ``position_m`` (m, body frame) and ``rpy_deg`` (roll, pitch, yaw in degrees,
Z-Y-X: ``R = Rz(yaw) Ry(pitch) Rx(roll)``, mesh frame to body frame). A rotor's hub is the
origin of its part placement, its thrust axis that placement's z axis (or ``axis``), and
``spin`` is ``ccw`` (+1) or ``cw`` (-1) about that axis.

Every manifest mistake raises :class:`quadsim.core.errors.InputError` naming the file and field.
A mesh must be a closed, consistently wound volume; ``hull=True`` replaces a bad mesh by its
convex hull and warns (:class:`quadsim.core.errors.QuadsimWarning`).
"""

from __future__ import annotations

import math
import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from ..core.errors import InputError, QuadsimWarning, field_error
from ..core.files import read_toml
from ..core.frames import euler_to_quat, quat_to_rotmat
from .step import is_step, read_step

__all__ = [
    "MESH_UNITS",
    "SCHEMA",
    "Assembly",
    "CadRotor",
    "Part",
    "Placement",
    "find_manifest",
    "load_assembly",
]

SCHEMA = "quadsim.cad/1"
#: Mesh unit name -> metres per unit.
MESH_UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "in": 0.0254}
#: Plausible average density of a vehicle part (kg/m^3): foam to tungsten. A mm/m slip moves
#: the implied density by 1e9 and lands far outside.
DENSITY_RANGE = (5.0, 25000.0)
#: Plausible largest extent of a part (m) when only its density is given.
EXTENT_RANGE = (1e-3, 10.0)
#: A part's largest extent is at most this many times the largest rotor hub distance.
MAX_PART_SPAN = 5.0
SPIN_SIGN = {"ccw": 1.0, "cw": -1.0}
COLLISION_SHAPES = ("box", "cylinder", "none")

_TOP_KEYS = {"schema", "name", "description", "mesh_unit", "vehicle", "part", "rotor", "notes"}
_VEHICLE_KEYS = {"weighed_mass", "mass_tolerance"}
_PART_KEYS = {"name", "mesh", "mass", "density", "group", "collision", "geometry", "placement"}
_PLACEMENT_KEYS = {"name", "position_m", "rpy_deg"}
_ROTOR_KEYS = {"name", "part", "placement", "spin", "axis"}


@dataclass(frozen=True)
class Placement:
    """One instance of a part: mesh frame -> body frame, ``x_body = rotation @ x + position``."""

    name: str
    position: np.ndarray  # (3,) m
    rotation: np.ndarray  # (3, 3)


@dataclass(frozen=True, eq=False)
class Part:
    """A mesh (in metres, mesh frame) with its mass per instance (kg) or density (kg/m^3)."""

    name: str
    mesh_path: Path
    mesh: trimesh.Trimesh
    mass: float | None
    density: float | None
    placements: tuple[Placement, ...]
    group: str = "part"
    collision: str = "box"
    source: str = ""
    geometry: str = ""

    @property
    def instance_mass(self) -> float:
        """Mass of one instance (kg), from ``mass`` or ``density * volume``."""
        return self.mass if self.mass is not None else self.density * self.mesh.volume


@dataclass(frozen=True)
class CadRotor:
    """A rotor: hub ``position`` (3,) m and unit thrust ``axis`` (3,) in the body frame,
    ``spin`` +1 ccw / -1 cw about the axis."""

    name: str
    position: np.ndarray
    axis: np.ndarray
    spin: float


@dataclass(frozen=True, eq=False)
class Assembly:
    """A loaded CAD folder: parts, rotors, and the optional weighed whole-vehicle mass."""

    name: str
    manifest: Path
    mesh_unit: str
    parts: tuple[Part, ...]
    rotors: tuple[CadRotor, ...]
    weighed_mass: float | None = None
    mass_tolerance: float = 0.02
    description: str = ""
    sources: dict[str, str] = field(default_factory=dict)

    @property
    def cad_dir(self) -> Path:
        return self.manifest.parent


def find_manifest(cad_dir: str | Path) -> Path:
    """The manifest of a CAD folder (its only ``*.toml``), or the file itself if given."""
    path = Path(cad_dir)
    if path.is_file():
        return path
    if not path.is_dir():
        raise InputError(f"{path}: CAD folder not found")
    manifests = sorted(path.glob("*.toml"))
    if len(manifests) != 1:
        found = ", ".join(m.name for m in manifests) or "none"
        raise InputError(f"{path}: expected exactly one manifest *.toml, found {found}")
    return manifests[0]


def _check_keys(table: object, valid: set[str], path: Path, where: str) -> dict:
    if not isinstance(table, dict):
        raise field_error(path, where, "expected a table")
    unknown = set(table) - valid
    if unknown:
        raise field_error(path, where, f"unknown key(s) {sorted(unknown)}; valid keys: "
                                       f"{', '.join(sorted(valid))}")
    return table


def _vector(value: object, path: Path, where: str, default=(0.0, 0.0, 0.0)) -> np.ndarray:
    if value is None:
        return np.array(default, dtype=float)
    try:
        vector = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise field_error(path, where, f"expected 3 numbers, got {value!r}") from None
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise field_error(path, where, f"expected 3 finite numbers, got {value!r}")
    return vector


def _positive_quantity(table: dict, key: str, unit: str, path: Path, where: str
                       ) -> tuple[float, str]:
    entry = table[key]
    if not isinstance(entry, dict) or not {"value", "unit", "source"} <= set(entry):
        raise field_error(path, f"{where}.{key}", "expected { value, unit, source }")
    _check_keys(entry, {"value", "unit", "source"}, path, f"{where}.{key}")
    if entry["unit"] != unit:
        raise field_error(path, f"{where}.{key}", f"unit {entry['unit']!r} where {unit!r} "
                                                  "is expected")
    value = entry["value"]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise field_error(path, f"{where}.{key}", f"value {value!r} is not a number")
    if not math.isfinite(value) or value <= 0:
        raise field_error(path, f"{where}.{key}", f"must be a finite number > 0, got {value}")
    return float(value), str(entry["source"])


def _mesh_file(cad_dir: Path, value: object, path: Path, where: str) -> Path:
    if not isinstance(value, str) or not value:
        raise field_error(path, where, "expected a mesh file name relative to the CAD folder")
    mesh_path = (cad_dir / value).resolve()
    if not mesh_path.is_relative_to(cad_dir.resolve()):
        raise field_error(path, where, f"mesh path {value!r} escapes the CAD folder {cad_dir}")
    if not mesh_path.is_file():
        raise field_error(path, where, f"mesh file {value!r} not found in {cad_dir}")
    return mesh_path


def _merge_vertices(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Identical float32 points (N, 3) -> unique vertices (V, 3) and the index of each point
    (N,). Exact bit comparison (after -0.0 -> 0.0), sorted with two 64-bit keys: ~6x faster
    than a structured np.unique on large meshes."""
    points = np.ascontiguousarray(points, dtype=np.float32) + np.float32(0.0)
    bits = points.view(np.uint32).astype(np.uint64)
    high = (bits[:, 0] << np.uint64(32)) | bits[:, 1]
    low = bits[:, 2]
    order = np.lexsort((low, high))
    high, low = high[order], low[order]
    first = np.empty(len(order), dtype=bool)
    first[0] = True
    first[1:] = (high[1:] != high[:-1]) | (low[1:] != low[:-1])
    index = np.empty(len(order), dtype=np.int64)
    index[order] = np.cumsum(first) - 1
    return points[order[first]].astype(np.float64), index


def read_mesh(mesh_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) in the file's units and triangles (F, 3) of a mesh file, identical
    vertices merged. Binary STL is read directly (fast); other formats through trimesh."""
    size = mesh_path.stat().st_size
    with open(mesh_path, "rb") as handle:
        head = handle.read(84)
        count = int.from_bytes(head[80:84], "little") if len(head) == 84 else -1
        if mesh_path.suffix.lower() == ".stl" and size == 84 + 50 * count and count > 0:
            record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)),
                               ("attribute", "<u2")])
            data = np.frombuffer(handle.read(), dtype=record, count=count)
            vertices, index = _merge_vertices(data["vertices"].reshape(-1, 3))
            return vertices, index.reshape(-1, 3)
    if is_step(mesh_path):                        # metres, whatever the file declares
        return read_step(mesh_path)
    mesh = trimesh.load_mesh(mesh_path, process=True)
    if not isinstance(mesh, trimesh.Trimesh):
        raise ValueError("not a single triangle mesh")
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


def topology_problem(faces: np.ndarray, vertex_count: int) -> str | None:
    """Why triangles (F, 3) do not bound a volume (None if they do): every edge must be
    shared by exactly two triangles (watertight) that run through it in opposite
    directions (consistent winding)."""
    faces = np.asarray(faces, dtype=np.int64)
    start, end = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    undirected = np.sort(np.minimum(start, end) * vertex_count + np.maximum(start, end))
    _, counts = np.unique(undirected, return_counts=True)
    if np.any(counts != 2):
        return (f"is not watertight ({int(np.sum(counts == 1))} open edges, "
                f"{int(np.sum(counts > 2))} edges shared by more than two triangles)")
    forward = np.sort(start * vertex_count + end)
    backward = np.sort(end * vertex_count + start)
    if np.any(forward[1:] == forward[:-1]) or not np.array_equal(forward, backward):
        return "is inconsistently wound (neighbouring triangles disagree on orientation)"
    return None


def load_mesh(mesh_path: Path, scale: float, *, where: str, hull: bool = False
              ) -> trimesh.Trimesh:
    """Read one mesh, convert it to metres, and check that it encloses a volume.

    A mesh with holes, inconsistent winding or inward normals is an error, unless ``hull``
    is set: then its convex hull replaces it and a :class:`QuadsimWarning` says so."""
    if is_step(mesh_path):
        scale = 1.0                               # STEP declares its unit: read in metres
    try:
        vertices, faces = read_mesh(mesh_path)
    except InputError:
        raise
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise InputError(f"{where}: cannot read mesh {mesh_path.name}: {exc}") from None
    if len(faces) == 0:
        raise InputError(f"{where}: mesh {mesh_path.name} holds no triangles")
    mesh = trimesh.Trimesh(vertices * scale, faces, process=False)
    problem = topology_problem(faces, len(vertices))
    if problem is None and mesh.volume <= 0:
        problem = "is inside out (normals point inward)"
    if problem is None:
        return mesh
    if not hull:
        raise InputError(f"{where}: mesh {mesh_path.name} {problem}; fix the export or pass "
                         "--hull to use its convex hull")
    warnings.warn(f"{where}: mesh {mesh_path.name} {problem}; using its convex hull instead "
                  "(mass properties are approximate)", QuadsimWarning, stacklevel=2)
    return mesh.convex_hull


def _placement(entry: object, path: Path, where: str, default_name: str) -> Placement:
    entry = _check_keys(entry, _PLACEMENT_KEYS, path, where)
    if "position_m" not in entry:
        raise field_error(path, f"{where}.position_m", "missing (m, body frame)")
    position = _vector(entry["position_m"], path, f"{where}.position_m")
    rpy = np.radians(_vector(entry.get("rpy_deg"), path, f"{where}.rpy_deg"))
    rotation = quat_to_rotmat(euler_to_quat(rpy))
    rotation[np.abs(rotation) < 1e-15] = 0.0  # exact zeros for right angles (clean tables)
    return Placement(str(entry.get("name", default_name)), position, rotation)


def _mass_or_density(entry: dict, path: Path, where: str) -> tuple[float | None, float | None,
                                                                   str]:
    has_mass, has_density = "mass" in entry, "density" in entry
    if has_mass == has_density:
        raise field_error(path, f"{where}.mass", "give exactly one of mass (kg, per instance) "
                                                 "or density (kg/m^3)")
    if has_mass:
        mass, source = _positive_quantity(entry, "mass", "kg", path, where)
        return mass, None, source
    density, source = _positive_quantity(entry, "density", "kg/m^3", path, where)
    return None, density, source


def _read_as(mesh_path: Path, unit: str) -> str:
    """How a mesh file's coordinates were read (for refusals): its name and unit."""
    if is_step(mesh_path):
        return f"{mesh_path.name} (read in the unit its STEP header declares)"
    return (f"{mesh_path.name} (read in mesh_unit = \"{unit}\", "
            f"scale {MESH_UNITS[unit]:g} m per unit)")


def _check_size(mesh: trimesh.Trimesh, mass: float | None, density: float | None,
                unit: str, path: Path, where: str, mesh_path: Path) -> None:
    """Catch a mesh drawn in other units than ``mesh_unit``: from the implied density when
    the mass is given (a mm/m slip moves it by 1e9), from the part's size otherwise. The
    refusal names the mesh field, the file and the unit it was read in."""
    low, high = DENSITY_RANGE
    extent = float(np.max(mesh.extents))
    field, read_as = f"{where}.mesh", _read_as(mesh_path, unit)
    small = f"mesh looks too small: drawn in m while mesh_unit says {unit}?"
    large = f"mesh looks too large: drawn in mm while mesh_unit says {unit}?"
    if is_step(mesh_path):
        small = large = "the STEP file declares the wrong length unit?"
    if mass is not None:
        implied = mass / mesh.volume
        if not low <= implied <= high:
            raise field_error(path, field, f"{read_as}: implied density {implied:.4g} kg/m^3 "
                                           f"(mass / volume) is outside the plausible "
                                           f"{low:g}..{high:g} (volume {mesh.volume:.4g} m^3, "
                                           f"largest extent {extent:.4g} m): "
                                           f"{small if implied > high else large}")
        return
    if not low <= density <= high:
        raise field_error(path, f"{where}.density", f"density {density:.4g} kg/m^3 is outside "
                                                    f"the plausible {low:g}..{high:g}")
    smallest, largest = EXTENT_RANGE
    if not smallest <= extent <= largest:
        raise field_error(path, field, f"{read_as}: largest extent {extent:.4g} m is outside "
                                       f"the plausible {smallest:g}..{largest:g} m for a "
                                       f"vehicle part: {small if extent < smallest else large}")


def _check_span(parts: list[Part], rotors: tuple, unit: str, path: Path) -> None:
    """A part larger than ``MAX_PART_SPAN`` x the largest distance between two rotor hubs
    (placements are in m whatever the meshes' unit): a mesh read in too small a unit that the
    per-part checks let through (a part given by density whose size is still plausible)."""
    hubs = np.array([r.position for r in rotors])
    if len(hubs) < 2:
        return
    span = float(np.max(np.linalg.norm(hubs[:, None] - hubs[None], axis=-1)))
    for index, part in enumerate(parts):
        extent = float(np.max(part.mesh.extents))
        if span > 0 and extent > MAX_PART_SPAN * span:
            raise field_error(path, f"part[{index}] ({part.name}).mesh",
                              f"{_read_as(part.mesh_path, unit)}: largest extent {extent:.4g} m "
                              f"is {extent / span:.3g} x the largest distance between two rotor "
                              f"hubs ({span:.4g} m, from position_m): mesh looks too large: "
                              f"drawn in mm while mesh_unit says {unit}?")


def _part(entry: object, index: int, cad_dir: Path, unit: str, path: Path, hull: bool) -> Part:
    where = f"part[{index}]"
    entry = _check_keys(entry, _PART_KEYS, path, where)
    name = entry.get("name")
    if not isinstance(name, str) or not name:
        raise field_error(path, f"{where}.name", "missing part name")
    where = f"part[{index}] ({name})"
    mesh_path = _mesh_file(cad_dir, entry.get("mesh"), path, f"{where}.mesh")
    mass, density, source = _mass_or_density(entry, path, where)
    mesh = load_mesh(mesh_path, MESH_UNITS[unit], where=f"{path}: {where}.mesh", hull=hull)
    _check_size(mesh, mass, density, unit, path, where, mesh_path)
    collision = entry.get("collision", "box")
    if collision not in COLLISION_SHAPES:
        raise field_error(path, f"{where}.collision", f"{collision!r}; valid: "
                                                      f"{', '.join(COLLISION_SHAPES)}")
    raw = entry.get("placement", [{"name": name, "position_m": [0.0, 0.0, 0.0]}])
    if not isinstance(raw, list) or not raw:
        raise field_error(path, f"{where}.placement", "expected at least one [[part.placement]]")
    placements = tuple(_placement(p, path, f"{where}.placement[{i}]", str(i + 1))
                       for i, p in enumerate(raw))
    names = [p.name for p in placements]
    if len(set(names)) != len(names):
        raise field_error(path, f"{where}.placement", f"placement names repeat: {names}")
    return Part(name, mesh_path, mesh, mass, density, placements, str(entry.get("group", "part")),
                collision, source, str(entry.get("geometry", "")))


def _rotor(entry: object, index: int, parts: dict[str, Part], path: Path) -> CadRotor:
    where = f"rotor[{index}]"
    entry = _check_keys(entry, _ROTOR_KEYS, path, where)
    part = parts.get(entry.get("part"))
    if part is None:
        raise field_error(path, f"{where}.part", f"{entry.get('part')!r} is not a part; valid: "
                                                 f"{', '.join(parts)}")
    placements = {p.name: p for p in part.placements}
    placement = placements.get(str(entry.get("placement")))
    if placement is None:
        raise field_error(path, f"{where}.placement", f"{entry.get('placement')!r} is not a "
                                                      f"placement of {part.name}; valid: "
                                                      f"{', '.join(placements)}")
    spin = entry.get("spin")
    if spin not in SPIN_SIGN:
        raise field_error(path, f"{where}.spin", f"must be 'ccw' or 'cw', got {spin!r}")
    axis = placement.rotation[:, 2] if "axis" not in entry else _vector(
        entry["axis"], path, f"{where}.axis")
    if np.linalg.norm(axis) < 1e-9:
        raise field_error(path, f"{where}.axis", "must be a non-zero vector")
    return CadRotor(str(entry.get("name", index + 1)), placement.position.copy(),
                    axis / np.linalg.norm(axis), SPIN_SIGN[spin])


def load_assembly(cad_dir: str | Path, *, hull: bool = False) -> Assembly:
    """Load and validate a CAD folder (or its manifest file); meshes in metres.

    Raises :class:`InputError` naming the file and field for any manifest or mesh problem."""
    path = find_manifest(cad_dir)
    data = read_toml(path)
    _check_keys(data, _TOP_KEYS, path, "top level")
    if data.get("schema") != SCHEMA:
        raise field_error(path, "schema", f"expected {SCHEMA!r}, got {data.get('schema')!r}")
    unit = data.get("mesh_unit")
    if unit not in MESH_UNITS:
        raise field_error(path, "mesh_unit", f"{unit!r}; valid: {', '.join(MESH_UNITS)}")
    raw_parts = data.get("part", [])
    if not isinstance(raw_parts, list):
        raise field_error(path, "part", "expected [[part]] entries (an array of tables)")
    if not raw_parts:
        raise field_error(path, "part", "empty assembly: no [[part]] entries")
    # Meshes load in threads (numpy sorts and sums release the GIL); results keep order.
    with ThreadPoolExecutor(max_workers=min(len(raw_parts), os.cpu_count() or 1)) as pool:
        futures = [pool.submit(_part, e, i, path.parent, unit, path, hull)
                   for i, e in enumerate(raw_parts)]
        parts = [f.result() for f in futures]
    by_name = {p.name: p for p in parts}
    if len(by_name) != len(parts):
        raise field_error(path, "part", f"part names repeat: {[p.name for p in parts]}")
    raw_rotors = data.get("rotor", [])
    if not isinstance(raw_rotors, list) or not raw_rotors:
        raise field_error(path, "rotor", "no rotors: add [[rotor]] entries naming a part "
                                         "placement and its spin")
    rotors = tuple(_rotor(e, i, by_name, path) for i, e in enumerate(raw_rotors))
    if len({r.name for r in rotors}) != len(rotors):
        raise field_error(path, "rotor", f"rotor names repeat: {[r.name for r in rotors]}")
    _check_span(parts, rotors, unit, path)
    vehicle = _check_keys(data.get("vehicle", {}), _VEHICLE_KEYS, path, "vehicle")
    weighed, sources = None, {}
    if "weighed_mass" in vehicle:
        weighed, sources["weighed_mass"] = _positive_quantity(vehicle, "weighed_mass", "kg",
                                                              path, "vehicle")
    tolerance = vehicle.get("mass_tolerance", 0.02)
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) \
            or not 0 < tolerance < 1:
        raise field_error(path, "vehicle.mass_tolerance", f"must be in (0, 1), got {tolerance!r}")
    return Assembly(str(data.get("name", path.stem)), path, unit, tuple(parts), rotors, weighed,
                    float(tolerance), str(data.get("description", "")), sources)
