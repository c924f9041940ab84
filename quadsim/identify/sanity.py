"""What a user typed, checked before it becomes a confusing error elsewhere, and fit
qualities said in words (``identify --logs``).

* :func:`check_mass_scale`: a skeleton's mass against its rotor distances. A multirotor's
  mass per squared rotor distance lies within about 5-200 kg/m^2 (Crazyflie 0.027 kg at
  0.04 m: 17; a 1.5 kg quad at 0.25 m: 24; a 25 kg octocopter at 0.8 m: 39); above
  ``MAX_MASS_PER_R2`` the mass is almost surely in grams (27 for 27 g gives 16 875), and the
  loader would otherwise refuse the *written* set's inertia without naming the field typed.
* :func:`r2_text`: an R^2 with what a negative one means.
* :func:`check_swapped`: a flight log given as the skeleton, or a TOML file as a log.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import InputError, field_error

__all__ = ["MAX_MASS_PER_R2", "check_mass_scale", "check_swapped", "r2_text"]

#: kg/m^2: mass over the mean squared rotor distance above which the mass is in grams (5x
#: the heaviest multirotor class's ~40; grams give ~1000x the true value).
MAX_MASS_PER_R2 = 200.0


def check_mass_scale(skeleton) -> None:
    """Refuse a skeleton whose ``body.mass`` (kg) is implausible for its rotor distances
    (see the module), naming the field and the likely unit slip."""
    arms = np.asarray(skeleton.positions, float)[:, :2] - np.asarray(skeleton.com, float)[:2]
    r2 = float(np.mean(np.sum(arms * arms, axis=1)))
    if r2 <= 0:
        return
    ratio = skeleton.mass / r2
    if ratio > MAX_MASS_PER_R2:
        grams = skeleton.mass / 1000.0
        raise field_error(skeleton.path, "body.mass",
                          f"{skeleton.mass:g} kg on rotors {np.sqrt(r2):.3g} m from the centre "
                          f"({ratio:.4g} kg/m^2; multirotors lie within about 5-200): grams "
                          f"given as kg? ({grams:g} kg if so; the unit is kg)")


def r2_text(r2: float) -> str:
    """``R^2 x`` and, when x < 0, what it means (the fit predicts worse than the mean)."""
    if r2 >= 0:
        return f"R^2 {r2:.3f}"
    return (f"R^2 {r2:.3f} (below 0: the fit predicts these samples worse than their mean "
            "does; its form does not describe them: a thrust not quadratic in the logged "
            "speed, a log of another vehicle, or too little range flown)")


def check_swapped(logs, vehicle) -> None:
    """Refuse a flight log given as ``--vehicle`` or a TOML file given in ``--logs`` (the two
    arguments swapped), naming what the file is by its first bytes."""
    from ..logs import file_kind

    kind = file_kind(vehicle)
    if kind is not None and kind != "a TOML file":
        raise InputError(f"{vehicle}: --vehicle: {kind}, not a skeleton TOML: --logs and "
                         "--vehicle swapped?")
    for path in logs:
        if file_kind(path) == "a TOML file" and Path(path).suffix == ".toml":
            raise InputError(f"{path}: --logs: a TOML file, not a flight log: --logs and "
                             "--vehicle swapped?")
