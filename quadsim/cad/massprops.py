"""Mass properties of a CAD assembly: the one place where mass, CoM and inertia are computed.

Each part's mesh gives its volume, centre of mass and inertia tensor (trimesh, exact for the
polyhedron, the part's mass spread uniformly over its volume). Each placement rotates and
shifts the part into the body frame; the parallel-axis theorem combines all instances into
the vehicle's total mass, centre of mass and full 3x3 inertia about that centre of mass.

Example::

    >>> from quadsim.cad.assembly import load_assembly
    >>> from quadsim.cad.massprops import vehicle_mass_properties
    >>> props = vehicle_mass_properties(load_assembly("cad"))
    >>> props.mass, props.com, props.principal_moments

Conventions: SI (kg, m, kg m^2); inertia tensors are the usual positive-definite matrix
``I = sum m (|r|^2 E - r r^T)`` (products of inertia enter with a minus sign, as in report
eq. 3.14), about the stated point, in body axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from ..core.errors import InputError, field_error
from .assembly import Assembly, Part

__all__ = [
    "MassProperties",
    "PartMassProperties",
    "combine_mass_properties",
    "mesh_mass_properties",
    "parallel_axis",
    "vehicle_mass_properties",
]


@dataclass(frozen=True)
class PartMassProperties:
    """One placed instance: ``mass`` (kg), ``volume`` (m^3), ``density`` (kg/m^3),
    ``com`` (3,) m and ``inertia`` (3, 3) kg m^2 about its own CoM, both in body axes."""

    part: str
    placement: str
    group: str
    mass: float
    volume: float
    density: float
    com: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class MassProperties:
    """Whole-vehicle mass (kg), CoM (3,) m (body frame), inertia (3, 3) kg m^2 about the CoM
    in body axes, and the per-instance table it was combined from."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    parts: tuple[PartMassProperties, ...]

    @property
    def principal_moments(self) -> np.ndarray:
        """Eigenvalues of the inertia tensor, ascending (kg m^2)."""
        return np.linalg.eigvalsh(self.inertia)


def mesh_mass_properties(mesh: trimesh.Trimesh | np.ndarray, mass: float | None = None,
                         density: float | None = None) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume (m^3), CoM (3,) and inertia about the CoM (3, 3) of a closed triangle mesh
    (a ``trimesh.Trimesh``, whose cached result is reused, or triangles (N, 3, 3)), its
    ``mass`` (kg) or ``density`` (kg/m^3) uniform over it."""
    if isinstance(mesh, trimesh.Trimesh) and mesh.density == 1.0:
        unit = mesh.mass_properties
    else:
        unit = trimesh.triangles.mass_properties(np.asarray(mesh, float).reshape(-1, 3, 3),
                                                 density=1.0)
    volume = float(unit.volume)
    scale = mass / volume if mass is not None else density
    return volume, np.asarray(unit.center_mass, float), np.asarray(unit.inertia, float) * scale


def parallel_axis(mass: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Inertia (..., 3, 3) of point masses ``mass`` (...) at ``offset`` (..., 3) about the
    origin: ``m (|r|^2 E - r r^T)``."""
    mass = np.asarray(mass, float)[..., None, None]
    r = np.asarray(offset, float)
    return mass * (np.einsum("...i,...i->...", r, r)[..., None, None] * np.eye(3)
                   - r[..., :, None] * r[..., None, :])


def combine_mass_properties(masses: np.ndarray, coms: np.ndarray, inertias: np.ndarray
                            ) -> tuple[float, np.ndarray, np.ndarray]:
    """Total mass, CoM and inertia about the CoM of bodies with masses (N,), CoMs (N, 3) and
    inertias about their own CoMs (N, 3, 3), all in one frame."""
    masses = np.asarray(masses, float)
    total = float(masses.sum())
    com = masses @ np.asarray(coms, float) / total
    inertia = np.sum(inertias, axis=0) + parallel_axis(masses, np.asarray(coms) - com).sum(0)
    return total, com, 0.5 * (inertia + inertia.T)


def _part_instances(part: Part) -> list[PartMassProperties]:
    volume, com, inertia = mesh_mass_properties(part.mesh, part.mass, part.density)
    mass = part.mass if part.mass is not None else part.density * volume
    return [PartMassProperties(part.name, p.name, part.group, mass, volume, mass / volume,
                               p.rotation @ com + p.position,
                               p.rotation @ inertia @ p.rotation.T)
            for p in part.placements]


def vehicle_mass_properties(assembly: Assembly, *, groups: tuple[str, ...] | None = None,
                            check_weighed: bool = True) -> MassProperties:
    """Mass properties of the assembly (or of the parts in ``groups`` only).

    With ``check_weighed`` (and all groups) the total is compared with the manifest's
    ``vehicle.weighed_mass``; a difference beyond ``mass_tolerance`` is an InputError."""
    instances = [inst for part in assembly.parts
                 if groups is None or part.group in groups for inst in _part_instances(part)]
    if not instances:
        raise InputError(f"{assembly.manifest}: no parts in groups {groups}")
    mass, com, inertia = combine_mass_properties(
        np.array([i.mass for i in instances]), np.array([i.com for i in instances]),
        np.array([i.inertia for i in instances]))
    weighed = assembly.weighed_mass
    if check_weighed and groups is None and weighed is not None \
            and abs(mass - weighed) > assembly.mass_tolerance * weighed:
        raise field_error(assembly.manifest, "vehicle.weighed_mass",
                          f"parts add up to {mass:.6g} kg but the vehicle weighs {weighed:.6g} "
                          f"kg ({100 * (mass / weighed - 1):+.2f} %, tolerance "
                          f"{100 * assembly.mass_tolerance:g} %): a part's mass is missing or "
                          "wrong")
    return MassProperties(mass, com, inertia, tuple(instances))
