"""Parameter consistency, now in :mod:`quadsim.gap.where` (the held-out analysis of where
and when the gap lies).

Kept for :mod:`.judge` (changed on another branch) until it merges; then it imports these
from :mod:`.where` and this module goes.
"""

from .where import (
    MATERIAL,
    MIN_SAMPLES,
    SPLITS,
    check,
    inconsistent_note,
    partial_text,
    split_masks,
    standing,
    tentative_note,
    tentative_text,
)

__all__ = ["MATERIAL", "MIN_SAMPLES", "SPLITS", "check", "inconsistent_note", "partial_text",
           "split_masks", "standing", "tentative_note", "tentative_text"]
