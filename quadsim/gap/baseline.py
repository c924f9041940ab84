"""The nominal refit's candidate: the parameter set's thrust and drag factors b and d
re-identified (relative changes), the pseudo-effect :class:`NominalRefit` (declared with the
diagnosis' other effects in :mod:`quadsim.gap.fitmodels`). :data:`BASELINE` is its candidate
(used by :mod:`.calibrate` as a shared group and by the held-out mode as the reading "b and d
are off").
"""

from __future__ import annotations

from .fitmodels import NominalRefit
from .fitting import Candidate

__all__ = ["BASELINE", "NominalRefit"]

BASELINE = Candidate("nominal_refit", (("nominal_refit", {}, ("thrust", "drag")),))
