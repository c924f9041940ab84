"""inertia_error: moments of inertia different from the model's.

Formula (relative errors e_x, e_y, e_z, fractions)::

    I' = S I S,   S = diag(sqrt(1 + e_x), sqrt(1 + e_y), sqrt(1 + e_z))

so each diagonal moment scales by (1 + e) exactly (I'_xx = (1 + e_x) I_xx) and the tensor
stays symmetric positive definite; a diagonal (principal-axis) tensor has its principal
moments scaled. Inertia is the least certain rigid-body parameter: bifilar/trifilar pendulum
measurements carry 5-10 % errors (e.g. Jardin & Mueller, "Optimized measurements of unmanned
air vehicle mass moment of inertia with a bifilar pendulum", J. Aircraft 2009), and CAD
models miss wiring and glue. The result must still obey the triangle inequality of
principal moments, else :class:`~quadsim.core.errors.ModelError`.

Example: ``inertia_error:xx=0.2`` makes roll 20 % more sluggish than the model believes.
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectParameter
from .facts import ALL, EffectFacts, PlausibleRange, Scale, Spread, Words, plus_minus

__all__ = ["InertiaError"]


def _phrase(parameter, value, ci, params) -> str:
    i = "xyz".index(parameter[0])
    base = params.inertia[i, i]
    return (f"I_{parameter} {plus_minus(value, ci, 100)} % ({base * (1 + value):.3g} kg m² "
            f"instead of the model's {base:.3g} kg m²)")


class InertiaError(EffectBase):
    """Relative errors of the diagonal moments of inertia."""

    name = "inertia_error"
    parameters = tuple(EffectParameter(axis, "1", 0.0, -0.9, 2.0,
                                       f"relative error of I_{axis} (fraction)")
                       for axis in ("xx", "yy", "zz"))

    facts = EffectFacts(
        fitted=("xx", "yy", "zz"),
        scales={ALL: Scale(lambda p: 0.1, "10 %: a CAD or lumped-mass inertia's error")},
        ranges={ALL: PlausibleRange(
            -0.5, 1.0, "relative",
            "CAD/lumped inertia within 10-20 % (CAD vs SolidWorks +9 %, Crazyflie literature "
            "+-20 %); a factor 2 is another vehicle")},
        spreads={ALL: Spread()},
        words={ALL: Words("inertia error", "%", 100.0, _phrase)},
    )

    def apply_to_params(self, params):
        if self.is_off():
            return params
        scale = np.diag(np.sqrt(1.0 + np.array([self.xx, self.yy, self.zz])))
        return params.replace(inertia=scale @ np.asarray(params.inertia, dtype=float) @ scale)
