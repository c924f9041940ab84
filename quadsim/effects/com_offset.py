"""com_offset: the centre of mass is not where the model puts it.

Formula: ``com' = com + (x, y, z)`` (m, body frame); the inertia about the (new) CoM is kept.
A shifted CoM moves every rotor's moment arm, ``tau = sum_i (r_i - com') x f_i``, so at hover
the vehicle needs a constant trim torque ``-(x, y) x m g``: with all rotors equal it tips
towards the offset (e.g. Bouabdallah & Siegwart 2007, "Full control of a quadrotor", IROS;
Mahony, Kumar & Corke, IEEE RAM 2012: the CoM is assumed at the rotor-plane centre). A
battery mounted 5 mm off centre on a 37 g Crazyflie is a typical size.

Static effect: engines build their model from ``apply_to_params``.
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectParameter
from .facts import (
    ALL,
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

__all__ = ["ComOffset"]


def _phrase(parameter, value, ci, params) -> str:
    return f"CoM {parameter[-1]} {plus_minus(value, ci, 1e3)} mm"


class ComOffset(EffectBase):
    """Shift of the centre of mass in body axes."""

    name = "com_offset"
    parameters = tuple(EffectParameter(axis, "m", 0.0, -0.1, 0.1,
                                       f"CoM shift along body {axis} (m)")
                       for axis in ("x", "y", "z"))

    #: z (the CoM below the rotor plane) acts only through forces in the rotor plane (drag)
    facts = EffectFacts(
        fitted=("x", "y", "z"),
        readings=(Reading(("x", "y")),),
        scales={ALL: Scale(lambda p: 0.02 * arm_length(p), "2 % of the arm: a battery a few mm "
                                                          "off the centre")},
        windows={ALL: Window(lambda p: -0.5 * arm_length(p), lambda p: 0.5 * arm_length(p),
                             "within half the arm: a CoM off by more is another vehicle")},
        ranges={axis: PlausibleRange(-0.15, 0.15, "arm", "battery/payload placement")
                for axis in ("x", "y")},
        spreads={axis: Spread() for axis in ("x", "y")},
        separate_from={
            "thrust_mismatch": "balance the vehicle on a knife edge along x and y (finds the "
                               "CoM), or each rotor on the thrust stand; in flight, fast yaw "
                               "turns: the accelerometer, c away from the CoM, reads w x (w x "
                               "c), a weak rotor adds nothing"},
        words={ALL: Words("CoM shift", "mm", 1e3, _phrase)},
    )

    def apply_to_params(self, params):
        if self.is_off():
            return params
        return params.replace(com=np.asarray(params.com, dtype=float) +
                              np.array([self.x, self.y, self.z]))
