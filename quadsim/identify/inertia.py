"""Inertia of the testbed from the bifilar test (corrected) and from the lumped model.

Bifilar: :func:`quadsim.identify.bifilar.bifilar_inertia` per trial, mean and spread per axis, with
the report's unsquared formula alongside. Physical checks on the resulting diagonal tensor:
every moment positive; triangle inequality (Ixx + Iyy >= Izz and cyclic: no rigid body
breaks it); and each moment at most m r_max^2, r_max the farthest point of the vehicle from
the axis (motor arm + propeller radius), because no mass can sit farther out than that.

Lumped model (report eq. 3.18 / 3.19): a solid sphere of mass M, radius R at the centre and
four point masses m at distance l::

    Ixx = Iyy = 2 M R^2 / 5 + 2 l^2 m          Izz = 2 M R^2 / 5 + 4 l^2 m
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..vehicle.params import inertia_problems
from .bifilar import BifilarTable, bifilar_inertia, published_bifilar_inertia

__all__ = [
    "BifilarResult",
    "analyse_bifilar",
    "inertia_bound_problems",
    "lumped_inertia",
]

_AXES = ("roll", "pitch", "yaw")  # about body x, y, z


def lumped_inertia(*, sphere_mass: float, sphere_radius: float, arm_length: float,
                   point_mass: float) -> np.ndarray:
    """(3,) principal moments (kg m^2) of the eq. 3.18/3.19 lumped model."""
    sphere = 2.0 * sphere_mass * sphere_radius**2 / 5.0
    return np.array([sphere + 2.0 * arm_length**2 * point_mass,
                     sphere + 2.0 * arm_length**2 * point_mass,
                     sphere + 4.0 * arm_length**2 * point_mass])


def inertia_bound_problems(moments: np.ndarray, mass: float, max_radius: float) -> list[str]:
    """Why diagonal ``moments`` (3,) kg m^2 cannot belong to a body of ``mass`` (kg) whose
    every point lies within ``max_radius`` (m) of the axes (empty if they can)."""
    problems = inertia_problems(np.diag(moments))
    bound = mass * max_radius**2
    for axis, moment in zip("xyz", moments):
        if moment > bound:
            problems.append(f"I{axis}{axis} = {moment:.4g} kg m^2 exceeds m r_max^2 = "
                            f"{bound:.4g} kg m^2 (all {mass:g} kg at {max_radius:g} m)")
    return problems


@dataclass(frozen=True)
class BifilarResult:
    """Bifilar inertia per axis (roll/pitch/yaw = x/y/z), corrected and as published.

    ``periods`` axis -> (3,) measured periods (s); ``trials`` axis -> (3,) corrected kg m^2
    per trial; ``moments`` (3,) corrected means;
    ``published`` (3,) the report's formula (kg m^2/s) on the same mean periods;
    ``problems`` why the corrected tensor cannot be this vehicle's (empty if physical)."""

    periods: dict[str, np.ndarray]
    trials: dict[str, np.ndarray]
    moments: np.ndarray
    published: np.ndarray
    problems: list[str]
    max_radius: float

    @property
    def physical(self) -> bool:
        return not self.problems

    def to_json(self) -> dict:
        return {"periods_s": {a: t.tolist() for a, t in self.periods.items()},
                "corrected_kg_m2": dict(zip(_AXES, self.moments.tolist())),
                "corrected_trials_kg_m2": {a: t.tolist() for a, t in self.trials.items()},
                "published_formula_kg_m2_per_s": dict(zip(_AXES, self.published.tolist())),
                "physical": self.physical, "problems": self.problems,
                "max_radius_m": self.max_radius}


def analyse_bifilar(table: BifilarTable, *, vehicle_mass: float,
                    max_radius: float) -> BifilarResult:
    """Corrected inertia from every trial and from the mean period, the report's formula on
    the same mean periods, and the physical checks."""
    rig = table.rig
    args = (rig.mass, rig.gravity, rig.wire_half_spacing, rig.wire_length)
    trials = {axis: bifilar_inertia(*args, table.periods[axis]) for axis in _AXES}
    moments = np.array([bifilar_inertia(*args, table.mean_period[a]) for a in _AXES])
    published = np.array([published_bifilar_inertia(*args, table.mean_period[a]) for a in _AXES])
    problems = inertia_bound_problems(moments, vehicle_mass, max_radius)
    return BifilarResult(dict(table.periods), trials, moments, published, problems, max_radius)
