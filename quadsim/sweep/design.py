"""Sweep dimensions from the command line, and the design matrix (one row per simulation).

Effect specs: ``NAME:param=LO..HI,param=VALUE`` (units of the effect's parameter, see
docs/effects.md); a range is swept, a single value is fixed. Initial-state specs:
``x=LO..HI,roll=LO..HI`` with keys x, y, z (m), vx, vy, vz (m/s) - offsets from the reference
path's start - and roll, pitch, yaw (rad), Z-Y-X offsets of the attitude.

Methods: ``mc`` draws ``samples`` rows uniformly in the box (``numpy.random.default_rng(seed)``,
all rows up front, so a row's inputs do not depend on chunking or executor); ``grid`` takes
``points`` evenly spaced values per swept dimension (endpoints included), all combinations,
first dimension slowest.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..core.errors import InputError
from ..effects import EFFECTS, make_effect

__all__ = [
    "INITIAL_KEYS",
    "Dimension",
    "design_matrix",
    "parse_effect_ranges",
    "parse_initial_ranges",
]

#: initial-state offset keys and their units
INITIAL_KEYS = {"x": "m", "y": "m", "z": "m", "vx": "m/s", "vy": "m/s", "vz": "m/s",
                "roll": "rad", "pitch": "rad", "yaw": "rad"}


@dataclass(frozen=True)
class Dimension:
    """One input column: ``effect.param`` or ``init.key``; ``low == high`` when fixed."""

    column: str
    low: float
    high: float

    @property
    def swept(self) -> bool:
        return self.high > self.low


def _number(text: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{where}: {text!r} is not a number") from None
    if not np.isfinite(value):
        raise InputError(f"{where}: {text!r} is not finite")
    return value


def _range(text: str, where: str) -> tuple[float, float]:
    low, dots, high = text.partition("..")
    lo = _number(low, where)
    hi = _number(high, where) if dots else lo
    if hi < lo:
        raise InputError(f"{where}: range {text!r} runs backwards (LO..HI with LO <= HI)")
    return lo, hi


def _items(spec: str, flag: str):
    for item in filter(None, (p.strip() for p in spec.split(","))):
        key, eq, text = item.partition("=")
        if not eq:
            raise InputError(f"{flag} {spec!r}: {item!r} is not key=LO..HI or key=VALUE")
        yield key.strip(), text.strip()


def parse_effect_ranges(specs: list[str]) -> list[Dimension]:
    """``["mass_offset:mass=0..0.2"]`` -> dimensions; both ends are checked by make_effect."""
    dims, seen = [], set()
    for spec in specs:
        name, _, rest = spec.strip().partition(":")
        if name not in EFFECTS:
            raise InputError(f"--effect {spec!r}: unknown effect {name!r}; valid: "
                             f"{', '.join(sorted(EFFECTS))}")
        if name in seen:
            raise InputError(f"--effect: effect {name!r} given more than once")
        seen.add(name)
        pairs = [(k, _range(v, f"--effect {spec}: {k}")) for k, v in _items(rest, "--effect")]
        for end in (0, 1):                      # validates names and plausible bounds
            make_effect(name, **{k: r[end] for k, r in pairs})
        dims += [Dimension(f"{name}.{k}", lo, hi) for k, (lo, hi) in pairs]
        if not pairs:
            dims.append(Dimension(name, 0.0, 0.0))     # effect on at its defaults
    return dims


def parse_initial_ranges(specs: list[str]) -> list[Dimension]:
    """``["x=-0.1..0.1,roll=-0.2..0.2"]`` -> ``init.*`` dimensions."""
    dims = {}
    for spec in specs:
        for key, text in _items(spec, "--initial"):
            if key not in INITIAL_KEYS:
                raise InputError(f"--initial: unknown key {key!r}; valid: "
                                 f"{', '.join(INITIAL_KEYS)}")
            dims[key] = Dimension(f"init.{key}", *_range(text, f"--initial {key}"))
    return list(dims.values())


def design_matrix(dims: list[Dimension], *, method: str, samples: int, points: int,
                  seed: int) -> np.ndarray:
    """(N, D) inputs, one row per simulation, columns in the order of ``dims``."""
    low = np.array([d.low for d in dims])
    high = np.array([d.high for d in dims])
    if method == "mc":
        if samples < 1:
            raise InputError(f"--samples: must be >= 1, got {samples}")
        rng = np.random.default_rng(seed)
        return low + (high - low) * rng.random((samples, len(dims)))
    if method == "grid":
        if points < 2:
            raise InputError(f"--points: must be >= 2, got {points}")
        axes = [np.linspace(d.low, d.high, points) if d.swept else np.array([d.low])
                for d in dims]
        return np.array(list(itertools.product(*axes)), dtype=float).reshape(-1, len(dims))
    raise InputError(f"--method: {method!r}; valid: mc, grid")
