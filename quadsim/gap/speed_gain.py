"""The motor map's gain, now declared in :mod:`quadsim.gap.fitmodels` (:class:`SpeedGain`).

Kept for :mod:`.calibrate` (changed on another branch) until it merges; then it imports
``SPEED_GAIN_PART`` from :mod:`.fitmodels` and this module goes.
"""

from .fitmodels import SPEED_GAIN_PART as PART
from .fitmodels import SpeedGain

__all__ = ["PART", "SpeedGain"]
