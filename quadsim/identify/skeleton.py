"""The skeleton of a parameter set (what a user measures by hand) and the complete set
written from it.

A skeleton is a parameter set (:mod:`quadsim.vehicle.params`, same TOML, same units) in which
``[rotors] thrust_factor``, ``drag_factor``, ``max_speed`` and ``[motor_map]`` may be absent,
and ``[body] inertia`` and ``com`` too. It must give the mass (a scale) and the rotors'
positions and spins (a ruler; or ``from_cad`` for both). Example (a 45 g Crazyflie)::

    schema = "quadsim.vehicle.params/1"
    name = "my_cf"
    [body]
    mass = { value = 0.045, unit = "kg", source = "kitchen scale, with battery" }
    [rotors]
    radius = { value = 0.0275, unit = "m", source = "ruler: 55 mm propeller" }
    [[rotor]]
    name = "1"
    position = { value = [0.0353, -0.0353, 0.0], unit = "m", source = "ruler" }
    spin = "ccw"
    ...

:mod:`quadsim.identify.vehicle_set` writes the complete set (TOML by
:func:`quadsim.core.files.render_toml`; ``render_params`` here is the same function under its
earlier import path): the skeleton's own entries unchanged, the identified ones added with a
``source`` naming the fit, its logs and its quality, and the values the data could not
determine listed under ``warnings``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import InputError, field_error
from ..core.files import check_schema, read_toml
from ..core.files import render_toml as render_params  # the earlier import path
from ..vehicle.params import EARLIER_SCHEMAS, SCHEMA, cad_path, read_quantity, rotor_table
from .logseries import Skeleton

__all__ = ["load_skeleton", "quantity", "render_params"]


def load_skeleton(path: str | Path) -> tuple[Skeleton, dict]:
    """(Skeleton, the raw TOML data) of a skeleton file; one-line errors for what is missing."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: skeleton file not found")
    data = read_toml(path)
    data = check_schema(data, path, SCHEMA, EARLIER_SCHEMAS)
    body = data.get("body")
    if not isinstance(body, dict):
        raise field_error(path, "body", "missing section [body] (mass on a scale)")
    inertia = None
    com = np.zeros(3)
    if "from_cad" in body:
        from ..cad.assembly import load_assembly
        from ..cad.massprops import vehicle_mass_properties

        cad_dir, _ = cad_path(body["from_cad"], path, "body.from_cad")
        props = vehicle_mass_properties(load_assembly(cad_dir))
        mass, com, inertia = props.mass, props.com, np.diag(props.inertia).copy()
    else:
        if "mass" not in body:
            raise field_error(path, "body.mass", "missing: weigh the vehicle with its battery "
                              "(kg); nothing else fixes the force scale")
        mass, _ = read_quantity(body, "mass", "kg", path, "body")
        if "com" in body:
            com, _ = read_quantity(body, "com", "m", path, "body", shape=(3,))
        if "inertia" in body:
            full, _ = read_quantity(body, "inertia", "kg m^2", path, "body", shape=(3, 3))
            inertia = np.diag(full).copy()
    if not mass > 0:
        raise field_error(path, "body.mass", f"must be > 0, got {mass}")
    if "rotor_layout" in data:
        from ..cad.assembly import load_assembly

        layout, _ = cad_path(data["rotor_layout"].get("from_cad"), path, "rotor_layout.from_cad")
        rotors = load_assembly(layout).rotors
        positions = np.array([r.position for r in rotors], float)
        spins = np.array([r.spin for r in rotors], float)
        axes = np.array([r.axis for r in rotors], float)
    elif data.get("rotor"):
        rotors = rotor_table(data["rotor"], path)
        positions = np.array([r.position for r in rotors])
        spins = np.array([r.spin for r in rotors])
        axes = np.array([r.axis for r in rotors])
    else:
        raise field_error(path, "rotor", "missing: give one [[rotor]] per rotor with its "
                          "position (m, ruler) and spin ('ccw'/'cw' seen from above)")
    if np.any(np.abs(axes[:, 2]) < 0.99):
        raise field_error(path, "rotor.axis", "identify --logs handles upright rotors only")
    if np.allclose(positions[:, :2], positions[0, :2]):
        raise field_error(path, "rotor.position", "all rotors at one point: measure the "
                          "rotor positions (m, from the frame centre)")
    rotors_section = data.get("rotors", {})
    max_speed = None
    if "max_speed" in rotors_section:
        max_speed, _ = read_quantity(rotors_section, "max_speed", "rad/s", path, "rotors")
    return Skeleton(float(mass), np.asarray(com, float), inertia, positions, spins, max_speed,
                    str(path)), data


# ----------------------------------------------------------------------------- writing


def quantity(value, unit: str, source: str) -> dict:
    """An inline ``{ value, unit, source }`` entry."""
    return {"value": value, "unit": unit, "source": source}
