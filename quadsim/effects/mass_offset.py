"""mass_offset: an extra mass (payload) that the model does not know.

Formula: a point mass ``mass`` (kg) at body position p = (x, y, z) (m) added to the vehicle
(mass m, CoM c, inertia I about c)::

    m'  = m + mass
    c'  = (m c + mass p) / m'
    I'  = I + m (|c - c'|^2 E - (c - c')(c - c')^T) + mass (|p - c'|^2 E - (p - c')(p - c')^T)

(parallel-axis theorem, e.g. Goldstein, Poole & Safko, "Classical Mechanics", 3rd ed.,
2002, sec. 5.3). With p = 0 on a
symmetric vehicle only the mass changes: hover needs sqrt(m'/m) times the rotor speed.
Example: ``mass_offset:mass=0.005`` is a 5 g payload, 13.5 % of a 37 g Crazyflie.
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectParameter

__all__ = ["MassOffset", "add_point_mass"]


def _steiner(mass: float, offset: np.ndarray) -> np.ndarray:
    return mass * (np.dot(offset, offset) * np.eye(3) - np.outer(offset, offset))


def add_point_mass(mass: float, com: np.ndarray, inertia: np.ndarray, point_mass: float,
                   point: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, CoM, inertia about the new CoM) after adding ``point_mass`` at ``point``."""
    com = np.asarray(com, dtype=float)
    point = np.asarray(point, dtype=float)
    total = mass + point_mass
    new_com = (mass * com + point_mass * point) / total
    new_inertia = (np.asarray(inertia, dtype=float) + _steiner(mass, com - new_com)
                   + _steiner(point_mass, point - new_com))
    return total, new_com, new_inertia


class MassOffset(EffectBase):
    """Point payload of unknown (to the model) mass and position."""

    name = "mass_offset"
    parameters = (
        EffectParameter("mass", "kg", 0.0, -1.0, 10.0, "extra mass (negative = lighter)"),
        EffectParameter("x", "m", 0.0, -1.0, 1.0, "payload position, body x"),
        EffectParameter("y", "m", 0.0, -1.0, 1.0, "payload position, body y"),
        EffectParameter("z", "m", 0.0, -1.0, 1.0, "payload position, body z"),
    )

    def apply_to_params(self, params):
        if self.mass == 0.0:
            return params
        mass, com, inertia = add_point_mass(params.mass, params.com, params.inertia, self.mass,
                                            [self.x, self.y, self.z])
        return params.replace(mass=mass, com=com, inertia=inertia)
