"""The nominal refit: the parameter set's thrust and drag factors b and d re-identified
(relative changes), as a pseudo-effect the fits and the evidence treat like a library effect.

Registered in :data:`quadsim.gap.fitting.LOCAL_EFFECTS` and :data:`quadsim.gap.fitting.FIT_SPEC`
on import; :data:`BASELINE` is its candidate (used by :mod:`.calibrate` as a shared group and
by the held-out mode as the reading "b and d are off").
"""

from __future__ import annotations

from ..effects.base import EffectBase, EffectParameter
from . import fitting
from .fitting import Candidate

__all__ = ["NominalRefit", "BASELINE"]


class NominalRefit(EffectBase):
    """Baseline: the nominal thrust and drag factors refitted (relative changes)."""

    name = "nominal_refit"
    parameters = (
        EffectParameter("thrust", "1", 0.0, -0.9, 3.0, "relative change of b"),
        EffectParameter("drag", "1", 0.0, -0.9, 3.0, "relative change of d"),
    )

    def apply_to_params(self, params):
        return params.replace(thrust_factor=params.thrust_factor * (1 + self.thrust),
                              drag_factor=params.drag_factor * (1 + self.drag))


fitting.LOCAL_EFFECTS["nominal_refit"] = NominalRefit
fitting.FIT_SPEC["nominal_refit"] = (("thrust", "drag"), {}, lambda p: [0.05, 0.2])
BASELINE = Candidate("nominal_refit", (("nominal_refit", {}, ("thrust", "drag")),))
