"""wind: constant plus gusty air velocity (world frame), a seeded function of time.

Formula (per world axis k; the same at every position)::

    w_k(t) = mean_k + sum_{j=1..J} a cos(2 pi f_j t + phi_kj),   a = gust * sqrt(2 / J)

J = ``GUST_COMPONENTS`` sines with frequencies log-spaced between ``LOWEST_FREQUENCY`` and
``bandwidth`` (Hz) and phases phi drawn from ``numpy.random.default_rng(seed)``, so the gust
has RMS ``gust`` (m/s) per axis, is smooth (the integrators see no steps) and is the same for
the same seed. A sum of sinusoids is the usual deterministic stand-in for turbulence spectra
such as Dryden's (MIL-F-8785C; Beal, "Digital simulation of atmospheric turbulence for
Dryden and von Karman models", J. Guid. Control Dyn. 1993). The wind acts only through
the drag effects (``rotor_drag``, ``body_drag``): the engines subtract it from the vehicle
velocity to form the air velocity they read. Without a drag effect, wind has no force.

Example: ``wind:vx=2,gust=0.5,seed=3`` is a 2 m/s breeze along world x with 0.5 m/s gusts.
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectParameter
from .facts import ALL, Companion, EffectFacts, Scale, Spread, Words, plus_minus

__all__ = ["GUST_COMPONENTS", "LOWEST_FREQUENCY", "WIND_SD_MS", "Wind"]

GUST_COMPONENTS = 8
LOWEST_FREQUENCY = 0.05
#: prior spread of a steady wind, m/s (indoor drafts to Beaufort 3, 3.4-5.4 m/s): the spread
#: of a flight's wind reading and the prior of the reference calibration's shared wind
WIND_SD_MS = 5.0


def _phrase(parameter, value, ci, params) -> str:
    return f"mean wind {plus_minus(value, ci, 1.0)} m/s along world {parameter[-1]}"


class Wind(EffectBase):
    """Constant wind plus a seeded sum-of-sines gust."""

    name = "wind"
    parameters = (
        EffectParameter("vx", "m/s", 0.0, -30.0, 30.0, "mean wind, world x"),
        EffectParameter("vy", "m/s", 0.0, -30.0, 30.0, "mean wind, world y"),
        EffectParameter("vz", "m/s", 0.0, -10.0, 10.0, "mean wind, world z"),
        EffectParameter("gust", "m/s", 0.0, 0.0, 10.0, "RMS of the gust per axis"),
        EffectParameter("bandwidth", "Hz", 1.0, LOWEST_FREQUENCY, 20.0,
                        "highest gust frequency"),
        EffectParameter("seed", "1", 0.0, 0.0, 2.0**31, "seed of the gust phases"),
    )

    facts = EffectFacts(
        # the air velocity is the logged velocity less the wind
        needs_pose=("velocity", "attitude"),
        fitted=("vx", "vy"),
        # wind exerts no force of its own: it acts through drag
        companions=(Companion("rotor_drag", ("coefficient",)),),
        scales={ALL: Scale(lambda p: 1.0, "1 m/s: a draft")},
        spreads={ALL: Spread(lambda p: WIND_SD_MS,
                             "indoor drafts to a fresh breeze (Beaufort 3: 3.4-5.4 m/s)")},
        words={ALL: Words("wind", "m/s", 1.0),
               **{v: Words("mean wind", "m/s", 1.0, _phrase) for v in ("vx", "vy", "vz")}},
    )

    @property
    def _phases(self) -> np.ndarray:
        """Gust phases (3, components) from ``seed``, drawn on first use (a steady wind, the
        fits' case, never needs them)."""
        if "_gust_phases" not in self.__dict__:
            rng = np.random.default_rng(int(self.seed))
            self.__dict__["_gust_phases"] = rng.uniform(0.0, 2.0 * np.pi,
                                                        size=(3, GUST_COMPONENTS))
        return self.__dict__["_gust_phases"]

    @property
    def _frequencies(self) -> np.ndarray:
        return np.geomspace(LOWEST_FREQUENCY, self.bandwidth, GUST_COMPONENTS)

    def air_velocity(self, t, position):
        t = np.asarray(t, dtype=float)
        mean = np.array([self.vx, self.vy, self.vz])
        wind = np.broadcast_to(mean, t.shape + (3,)).copy()
        if self.gust > 0.0:
            amplitude = self.gust * np.sqrt(2.0 / GUST_COMPONENTS)
            angle = 2 * np.pi * self._frequencies * t[..., None, None] + self._phases
            wind += amplitude * np.cos(angle).sum(axis=-1)
        return wind
