"""Cost before work: a long command estimates its time and memory from its arguments and
refuses, before it starts, a run past the caps unless told otherwise (``--allow-large``).

The estimates are linear models whose coefficients were measured on the 2-core x86_64
development machine (each command's module names its own and the command that measures
it); they are meant to catch a slip of orders of magnitude (``--samples 100000000``: weeks),
not to predict to the minute. Caps: ``MAX_SECONDS`` = 4 h and ``MAX_BYTES`` = 8 GiB.

Example::

    >>> from quadsim.core.cost import Estimate, check_cost
    >>> check_cost(Estimate(seconds=3e6, bytes=1e9, what="1e8 simulations"), "--samples",
    ...            allow=False)                    # InputError: ... 833 h ... --allow-large
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import InputError

__all__ = ["MAX_BYTES", "MAX_SECONDS", "Estimate", "check_cost", "describe"]

MAX_SECONDS = 4 * 3600.0
MAX_BYTES = 8 * 1024**3


@dataclass(frozen=True)
class Estimate:
    """Expected wall time ``seconds`` (s) and peak memory ``bytes`` of a run; ``what`` says
    what was counted (e.g. "64 simulations of 5 s")."""

    seconds: float
    bytes: float
    what: str


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 2 * 3600:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def describe(estimate: Estimate) -> str:
    """``about 12 min and 1.2 GiB for <what>``."""
    return (f"about {_duration(estimate.seconds)} and {estimate.bytes / 2**30:.2g} GiB for "
            f"{estimate.what}")


def check_cost(estimate: Estimate, flag: str, *, allow: bool,
               max_seconds: float = MAX_SECONDS, max_bytes: float = MAX_BYTES) -> None:
    """Refuse (one line naming ``flag``) an estimate past a cap unless ``allow``."""
    if allow:
        return
    if estimate.seconds > max_seconds or estimate.bytes > max_bytes:
        raise InputError(f"{flag}: {describe(estimate)}, past the cap of "
                         f"{_duration(max_seconds)} / {max_bytes / 2**30:g} GiB (2-core "
                         "machine); reduce it, or give --allow-large to run it anyway")
