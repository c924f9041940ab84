"""STEP parts (ISO 10303-21, ``.step``/``.stp``) as triangle meshes, through trimesh + cascadio.

SolidWorks and most CAD tools export STEP; ``cad/`` manifests may name a ``.step`` file
wherever they name an STL. The B-rep is tessellated by OpenCASCADE (``cascadio``, the
optional extra ``pip install -e '.[step]'``) via ``trimesh.load(..., file_type="step")``,
then checked exactly like an STL (:func:`quadsim.cad.assembly.load_mesh`: watertight, consistently
wound, outward normals, plausible size/density for the manifest's mass).

Units: a STEP file declares its own length unit (e.g. ``SI_UNIT(.MILLI.,.METRE.)``) and
OpenCASCADE converts to metres, so the manifest's ``mesh_unit`` applies to STL/OBJ only; a
STEP file whose declared unit is wrong is caught by the same size/density check as an STL.

Tessellation tolerance: ``STEP_TOLERANCE`` = 1e-6 *relative* chord deflection
(``tol_relative=True``: deflection / edge size), angular 0.5 rad. Relative, so that the
result does not depend on the part's size or unit. 1e-6: the volume error equals the
relative tolerance and the axial inertia error twice it, so both stay below any mass or
inertia the bench measures (``docs/cad.md``: a cylinder against the closed form). Flat faces
are exact at any tolerance.

A file must hold exactly one solid: several solids (or disconnected bodies) or an open shell
give a one-line :class:`~quadsim.core.errors.InputError`.

Example::

    >>> from quadsim.cad.step import read_step
    >>> vertices_m, faces = read_step("tests/data/box.step")
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import InputError

__all__ = ["STEP_ANGULAR_TOLERANCE", "STEP_SUFFIXES", "STEP_TOLERANCE", "is_step", "read_step"]

STEP_SUFFIXES = (".step", ".stp")
#: relative chord deflection of the tessellation (deflection / edge size)
STEP_TOLERANCE = 1e-6
#: angular deflection of the tessellation (rad)
STEP_ANGULAR_TOLERANCE = 0.5


def is_step(path: str | Path) -> bool:
    return Path(path).suffix.lower() in STEP_SUFFIXES


def read_step(path: str | Path, *, tolerance: float = STEP_TOLERANCE
              ) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) in metres and triangles (F, 3) of the one solid in a STEP file,
    identical vertices merged (so that shared edges are shared)."""
    import trimesh

    path = Path(path)
    try:
        import cascadio  # noqa: F401
    except ImportError:
        raise InputError(f"{path}: reading STEP needs cascadio: pip install -e '.[step]'") \
            from None
    try:
        scene = trimesh.load(path, file_type="step", tol_linear=tolerance, tol_relative=True,
                             tol_angular=STEP_ANGULAR_TOLERANCE)
    except Exception as exc:  # noqa: BLE001 - OpenCASCADE / glTF errors of any type
        raise InputError(f"{path}: cannot read STEP: {' '.join(str(exc).split())}") from None
    geometries = list(getattr(scene, "geometry", {}).values()) or [scene]
    if len(geometries) != 1:
        raise InputError(f"{path}: holds {len(geometries)} bodies; export one solid per file")
    soup = np.asarray(geometries[0].triangles, dtype=float).reshape(-1, 3)
    if len(soup) == 0:
        raise InputError(f"{path}: holds no solid")
    # bit-identical float32 points are one vertex (as for STL): faces then share edges
    points = np.ascontiguousarray(soup, dtype=np.float32) + np.float32(0.0)
    _, first, index = np.unique(points.view(np.dtype((np.void, 12))).ravel(),
                                return_index=True, return_inverse=True)
    vertices = points[first].astype(np.float64)
    faces = index.reshape(-1, 3)
    labels = trimesh.graph.connected_component_labels(
        trimesh.graph.face_adjacency(faces), node_count=len(faces))
    count = len(np.unique(labels))
    if count > 1:
        raise InputError(f"{path}: holds {count} separate solids; export one solid per file")
    return vertices, faces
