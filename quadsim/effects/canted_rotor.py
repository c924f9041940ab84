"""canted_rotor: one rotor's thrust axis tilted away from where the model has it.

Formula: rotor ``rotor`` (1-based, the parameter set's numbering) has its unit axis a
rotated by ``angle`` (rad) about the body-frame direction e = (cos azimuth, sin azimuth, 0)
(Rodrigues)::

    a' = a cos(angle) + (e x a) sin(angle) + e (e . a)(1 - cos(angle))

The rotor's thrust b Omega^2 and its drag (reaction) torque -s d Omega^2 both act along a'
(the motor, its shaft and the propeller disc tilt together); everything else about the
vehicle is unchanged. The effect changes the parameter set's rotor axis, so both engines,
the allocation (:mod:`quadsim.vehicle.rotors`) and every other effect (thrust scales, offsets,
gyroscopic torque) use the tilted axis.

A bent motor mount or a crash-bent arm tilts a rotor by a few degrees; some vehicles tilt
rotors on purpose (the rotor-axis geometry and its wrench are those of Rajappa, Ryll,
Bülthoff & Franchi, "Modeling, control and design optimization for a fully-actuated
hexarotor aerial vehicle with tilted propellers", ICRA 2015, eqs. 1-4). A tilt gives a
horizontal force b Omega^2 sin(angle) and a torque from the arm and from the tilted drag
torque, which a controller must trim out.

Parameters: ``rotor`` (index 1..8, must be a whole number within the vehicle's count),
``angle`` (rad; 0 = off), ``azimuth`` (rad, direction of the tilt axis in the body xy-plane
from body x). Example: ``canted_rotor:rotor=1,angle=0.05,azimuth=1.5708`` tilts the testbed's
front rotor by 2.9 deg about body y: at hover (2.06 N) the rotor pushes
2.06 sin(0.05) = 0.103 N forward (+x).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..core.errors import ModelError
from ..core.frames import cross
from .base import EffectBase, EffectParameter
from .facts import (
    ALL,
    EffectFacts,
    PlausibleRange,
    Reading,
    Scale,
    Spread,
    Together,
    Words,
    plus_minus,
)

__all__ = ["CantedRotor", "tilt_axis"]


def tilt_axis(axis: np.ndarray, angle: float, azimuth: float) -> np.ndarray:
    """``axis`` (3,) rotated by ``angle`` (rad) about (cos azimuth, sin azimuth, 0)."""
    axis = np.asarray(axis, dtype=float)
    e = np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
    out = axis * np.cos(angle) + cross(e, axis) * np.sin(angle) \
        + e * np.dot(e, axis) * (1.0 - np.cos(angle))
    return out / np.linalg.norm(out)


def _together(values: dict, ci: dict, params, fixed: dict) -> str:
    """A canted rotor in words: the lean (deg) and its direction, the sideways push at hover
    (``values``, ``ci``, ``fixed`` keyed by this effect's parameter names)."""
    tx, ty = values["tilt_x"], values["tilt_y"]
    cx, cy = ci.get("tilt_x"), ci.get("tilt_y")
    rotor = fixed.get("rotor")
    angle = float(np.hypot(tx, ty))
    c = None if cx is None or cy is None else float(np.hypot(cx, cy))
    push = params.weight / params.rotor_count * np.sin(angle)
    which = f"rotor {int(rotor)}" if rotor is not None else "a rotor"
    lean = plus_minus(np.degrees(angle), None if c is None else np.degrees(c), 1.0)
    return (f"{which}'s axis leans {lean}"
            f" deg (towards body x {np.degrees(tx):+.2g} deg and y {np.degrees(ty):+.2g} deg): "
            f"it pushes {1e3 * push:.3g} mN sideways at hover ({100 * push / params.weight:.2g} "
            "% of the weight)")


class CantedRotor(EffectBase):
    """One rotor axis tilted by an angle about a horizontal body direction."""

    name = "canted_rotor"
    parameters = (
        EffectParameter("rotor", "index", 1.0, 1.0, 8.0, "rotor number (1-based)"),
        EffectParameter("angle", "rad", 0.0, -0.5, 0.5, "tilt angle (0 = off)"),
        EffectParameter("azimuth", "rad", 0.0, -np.pi, np.pi,
                        "tilt axis direction in the body xy-plane, from body x"),
    )

    #: the diagnosis fits the tilted axis' horizontal components (its fit form,
    #: :class:`quadsim.gap.fitting.CantedRotorFit`): angle and azimuth are singular at 0
    facts = EffectFacts(
        fitted=("tilt_x", "tilt_y"),
        one_per_rotor="rotor",
        readings=(Reading(("tilt_x", "tilt_y"), "rotor {}", per_rotor=True),),
        fit_parameters=(
            EffectParameter("tilt_x", "rad", 0.0, -0.3, 0.3, "axis lean towards body +x"),
            EffectParameter("tilt_y", "rad", 0.0, -0.3, 0.3, "axis lean towards body +y"),
        ),
        scales={p: Scale(lambda params: 0.02, "a lean of about 1 deg")
                for p in ("tilt_x", "tilt_y")},
        ranges={ALL: PlausibleRange(
            -0.17, 0.17, "absolute",
            "a bent motor mount or arm leans a rotor a few deg; more than 10 deg (0.17 rad) is "
            "a visibly broken arm")},
        spreads={ALL: Spread()},
        separate_from={
            "wind": "fly the same path in both directions (wind is fixed in the world, a canted "
                    "rotor's push turns with the body); or look at the motor mounts",
            "com_offset": "hover with a payload on the CoM: a canted rotor's sideways push "
                          "grows with its thrust; or look at the motor mounts",
            "thrust_mismatch": "look at the motor mounts; a canted rotor also pushes sideways "
                               "(hover drifts)"},
        words={ALL: Words("rotor axis lean", "deg", 180.0 / np.pi),
               "rotor": Words("rotor", "index", 1.0)},
        together=Together(("tilt_x", "tilt_y"), _together),
    )

    def apply_to_params(self, params):
        if self.angle == 0.0:
            return params
        index = self.rotor
        if index != round(index) or not 1 <= index <= params.rotor_count:
            raise ModelError(f"canted_rotor: rotor = {index:g} is not a rotor of the vehicle "
                             f"(1..{params.rotor_count})")
        i = int(round(index)) - 1
        rotors = list(params.rotors)
        rotors[i] = dataclasses.replace(rotors[i],
                                        axis=tilt_axis(rotors[i].axis, self.angle, self.azimuth))
        return params.replace(rotors=tuple(rotors))
