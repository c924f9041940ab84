"""Collinear explanations in words, now in :mod:`quadsim.gap.priors` (what the effects'
facts imply: plausible magnitudes, and each reading in words).

Kept for :mod:`.judge` (changed on another branch) until it merges; then it imports these
from :mod:`.priors` and this module goes.
"""

from .priors import SEPARATE, describe, separation, torque_text, unit_of

__all__ = ["SEPARATE", "describe", "separation", "torque_text", "unit_of"]

_torque_text = torque_text  # alias for judge (being changed on another branch) until it merges
