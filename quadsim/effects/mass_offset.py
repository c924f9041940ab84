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
from .facts import (
    EffectFacts,
    PlausibleRange,
    Reading,
    Scale,
    Spread,
    Window,
    Words,
    arm_length,
    plus_minus,
)

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


def _phrase(parameter, value, ci, params) -> str:
    """A payload's reading in words: its mass against the model's, or where it sits."""
    if parameter == "mass":
        return (f"{plus_minus(value, ci, 1e3)} g heavier ({100 * value / params.mass:+.1f} % "
                f"of the model's {1e3 * params.mass:.4g} g)")
    return f"sitting at body {parameter[-1]} {plus_minus(value, ci, 1e3)} mm"


class MassOffset(EffectBase):
    """Point payload of unknown (to the model) mass and position."""

    name = "mass_offset"
    parameters = (
        EffectParameter("mass", "kg", 0.0, -1.0, 10.0, "extra mass (negative = lighter)"),
        EffectParameter("x", "m", 0.0, -1.0, 1.0, "payload position, body x"),
        EffectParameter("y", "m", 0.0, -1.0, 1.0, "payload position, body y"),
        EffectParameter("z", "m", 0.0, -1.0, 1.0, "payload position, body z"),
    )

    facts = EffectFacts(
        fitted=("mass",),
        weighed=("mass",),
        # a payload at the centre, or off it (its mass and where it sits: it also moves the
        # CoM; the position acts only through the mass, so the fit is coupled); the two
        # share the effect's prior
        readings=(Reading(("mass",), odds=2),
                  Reading(("mass", "x", "y"), "off the centre", odds=2, coupled=True,
                          kin=("mass_offset", "com_offset", "thrust_curve"),
                          through=(("x", "mass"), ("y", "mass")))),
        scales={"mass": Scale(lambda p: 0.05 * p.mass,
                              "5 % of the vehicle's mass: a small payload")},
        windows={
            "mass": Window(lambda p: -0.5 * p.mass, lambda p: 2.0 * p.mass,
                           "plausible payloads for this vehicle: half of it lighter to 2x"),
            **{axis: Window(lambda p: -arm_length(p), lambda p: arm_length(p),
                            "a payload within the rotors' span") for axis in ("x", "y", "z")}},
        ranges={"mass": PlausibleRange(
            -0.05, 0.6, "mass",
            "payloads up to ~60 % of the vehicle mass (Crazyflie 2.1: 15 g on 37 g, Bitcraze); "
            "lighter than modelled by > 5 % is unlikely")},
        spreads={"mass": Spread(reason="payload to 60 % of the vehicle's mass (the range)"),
                 **{axis: Spread(lambda p: 0.5 * arm_length(p),
                                 "a payload fixed anywhere within the rotors' span")
                    for axis in ("x", "y")}},
        separate_from={
            "thrust_factor": "weigh the vehicle (or measure thrust per Omega^2 on a thrust "
                             "stand); the yaw channel leans to thrust_factor if the drag torque "
                             "per Omega^2 changed too",
            "thrust_curve": "weigh the vehicle; fly over a wider range of rotor speeds (a "
                            "thrust-curve change depends on speed, a mass does not)",
            "thrust_mismatch": "weigh the vehicle; fly with one rotor swapped",
            "cable_payload": "look under the vehicle; or fly sharp stops and turns: a slung "
                             "payload lags and swings back at its own period 2 pi sqrt(L / g), a "
                             "rigid mass moves with the vehicle",
            "battery_sag": "log vbat over a long flight; weigh the vehicle"},
        words={"mass": Words("payload", "g", 1e3, _phrase),
               **{axis: Words(f"payload position, body {axis}", "mm", 1e3, _phrase)
                  for axis in ("x", "y", "z")}},
    )

    def apply_to_params(self, params):
        if self.mass == 0.0:
            return params
        mass, com, inertia = add_point_mass(params.mass, params.com, params.inertia, self.mass,
                                            [self.x, self.y, self.z])
        return params.replace(mass=mass, com=com, inertia=inertia)
