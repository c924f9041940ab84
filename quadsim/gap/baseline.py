"""The nominal refit's candidate, now :data:`quadsim.gap.fitting.BASELINE` (its effect
:class:`quadsim.gap.fitmodels.NominalRefit`).

Kept for :mod:`.calibrate` (changed on another branch) until it merges; then it imports
``BASELINE`` from :mod:`.fitting` and this module goes.
"""

from .fitmodels import NominalRefit
from .fitting import BASELINE

__all__ = ["BASELINE", "NominalRefit"]
