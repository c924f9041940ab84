"""Vehicle meshes for the recording: the CAD assembly's parts, or stand-ins from the rotor
geometry (a centre plate, arms, rotor discs), in the body frame (m). Part of
:mod:`quadsim.viewer`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..vehicle.params import VehicleParams

__all__ = ["VehicleShape", "assembly_for", "vehicle_shapes"]


@dataclass(frozen=True)
class VehicleShape:
    """One triangle mesh of the vehicle: vertices (V, 3) in m, body frame; faces (F, 3)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    color: tuple[int, int, int]



def _box(size: Sequence[float], center: Sequence[float], direction: np.ndarray | None = None):
    import trimesh  # local: only needed when a recording is made

    mesh = trimesh.creation.box(extents=size)
    if direction is not None:
        mesh.apply_transform(trimesh.geometry.align_vectors([1.0, 0.0, 0.0], direction))
    mesh.apply_translation(center)
    return mesh


def _simple_shapes(params: VehicleParams) -> list[VehicleShape]:
    """Stand-in geometry from the rotor layout: a centre plate, an arm to every hub and a
    thin disc of the rotor radius at each hub, oriented along the rotor axis."""
    import trimesh

    positions = params.rotor_positions
    arm = float(np.max(np.linalg.norm(positions[:, :2], axis=1))) or 0.1
    radius = params.rotor_radius or 0.3 * arm
    shapes = [VehicleShape("plate", *_mesh_arrays(_box([0.5 * arm, 0.5 * arm, 0.04 * arm],
                                                       params.com)), (90, 90, 90))]
    for i, (position, axis, spin) in enumerate(zip(positions, params.rotor_axes,
                                                   params.rotor_spins)):
        length = float(np.linalg.norm(position)) or 1e-3
        arm_mesh = _box([length, 0.06 * arm, 0.04 * arm], 0.5 * position, position / length)
        shapes.append(VehicleShape(f"arm_{i + 1}", *_mesh_arrays(arm_mesh), (120, 120, 120)))
        disc = trimesh.creation.cylinder(radius=radius, height=0.01 * arm, sections=32)
        disc.apply_transform(trimesh.geometry.align_vectors([0.0, 0.0, 1.0], axis))
        disc.apply_translation(position + 0.03 * arm * axis)
        color = (60, 160, 230) if spin > 0 else (230, 120, 50)  # ccw blue, cw orange
        shapes.append(VehicleShape(f"rotor_{i + 1}", *_mesh_arrays(disc), color))
    return shapes


def _mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(mesh.vertices, dtype=np.float32), np.asarray(mesh.faces, dtype=np.uint32)


_GROUP_COLORS = {"mechanical": (150, 150, 160), "battery": (200, 170, 40),
                 "avionics": (40, 140, 80)}


def _assembly_shapes(assembly) -> list[VehicleShape]:
    """Every placed instance of every CAD part, in the body frame (m); propellers coloured by
    spin (ccw blue, cw orange) when they sit on a rotor hub."""
    spins = {tuple(np.round(r.position, 6)): r.spin for r in assembly.rotors}
    shapes = []
    for part in assembly.parts:
        vertices = np.asarray(part.mesh.vertices, dtype=float)
        faces = np.asarray(part.mesh.faces, dtype=np.uint32)
        for placement in part.placements:
            body = vertices @ np.asarray(placement.rotation).T + placement.position
            color = _GROUP_COLORS.get(part.group, (150, 150, 160))
            spin = spins.get(tuple(np.round(placement.position, 6)))
            if "prop" in part.name and spin is not None:
                color = (60, 160, 230) if spin > 0 else (230, 120, 50)
            shapes.append(VehicleShape(f"{part.name}/{placement.name}",
                                       body.astype(np.float32), faces, color))
    return shapes


def assembly_for(params: VehicleParams):
    """The CAD assembly the parameter set's mass properties or rotor layout come from
    (``from_cad``), or None when the set does not come from CAD."""
    if params.cad_dir is None:
        return None
    from ..cad.assembly import load_assembly  # local: trimesh and the mesh files

    return load_assembly(params.cad_dir)


def vehicle_shapes(params: VehicleParams, assembly=None) -> list[VehicleShape]:
    """Meshes to draw for the vehicle: the assembly's parts when given, else stand-ins."""
    if assembly is not None:
        return _assembly_shapes(assembly)
    return _simple_shapes(params)


# ----------------------------------------------------------------------------- logging

