"""Bifilar (two-wire) torsion pendulum: moment of inertia from the swing period.

A body of mass m hangs from two vertical wires of length L, each at distance R from the
vertical swing axis through the centre of mass. For small twists it oscillates with period T
and its moment of inertia about that axis is

    I = m g R^2 T^2 / (4 pi^2 L)                      (kg m^2)

The 2015 report (section 3.5.3 / 4.3.3) used ``I = [T / (2 pi)] m g R^2 / L``: the period is
not squared, so its numbers have units kg m^2 / s and are wrong by the factor
``T / (2 pi)``. :func:`published_bifilar_inertia` reproduces that formula for the audit only.

Example::

    >>> from quadsim.identify.bifilar import bifilar_inertia, load_bifilar_table
    >>> table = load_bifilar_table()
    >>> rig = table.rig
    >>> I = bifilar_inertia(rig.mass, rig.gravity, rig.wire_half_spacing, rig.wire_length,
    ...                     table.mean_period["yaw"])   # ~0.126 kg m^2

All functions broadcast over numpy arrays (e.g. one period per trial).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import field_error
from .benchdata import DATA_DIR, Column, read_table

__all__ = [
    "BifilarRig",
    "BifilarTable",
    "bifilar_inertia",
    "load_bifilar_table",
    "published_bifilar_inertia",
]


def bifilar_inertia(mass_kg, gravity, wire_half_spacing_m, wire_length_m, period_s):
    """Moment of inertia (kg m^2) about the swing axis: I = m g R^2 T^2 / (4 pi^2 L)."""
    return (np.asarray(mass_kg) * gravity * np.square(wire_half_spacing_m)
            * np.square(period_s) / (4.0 * math.pi**2 * np.asarray(wire_length_m)))


def published_bifilar_inertia(mass_kg, gravity, wire_half_spacing_m, wire_length_m, period_s):
    """The report's formula, I = [T / (2 pi)] m g R^2 / L (period not squared; kg m^2 / s).

    Kept only to reproduce and audit the published Table 4.15 values."""
    return (np.asarray(period_s) / (2.0 * math.pi) * np.asarray(mass_kg) * gravity
            * np.square(wire_half_spacing_m) / np.asarray(wire_length_m))


@dataclass(frozen=True)
class BifilarRig:
    """Rig constants of the report's bifilar test (section 4.3.3)."""

    mass: float               # kg, suspended mass
    gravity: float            # m/s^2
    wire_half_spacing: float  # m, R: swing axis to each wire
    wire_length: float        # m, L
    source: str


@dataclass(frozen=True)
class BifilarTable:
    """Table 4.14: ``periods[axis]`` (3,) s for every trial; ``rig`` the constants used."""

    periods: dict[str, np.ndarray]
    rig: BifilarRig
    source: str
    path: Path

    @property
    def mean_period(self) -> dict[str, float]:
        """Mean period per axis (s)."""
        return {axis: float(np.mean(t)) for axis, t in self.periods.items()}


_AXES = ("roll", "pitch", "yaw")


def load_bifilar_table(path: str | Path | None = None,
                       rig_path: str | Path | None = None) -> BifilarTable:
    """Load Table 4.14 (periods, all trials) and the section 4.3.3 rig constants."""
    spec = {"axis": Column(None), **{f"period_{t}": Column("s", 0.01, 60.0) for t in (1, 2, 3)}}
    table = read_table(path or DATA_DIR / "table_4_14_bifilar.csv", spec, min_rows=1)
    periods = {}
    for row, axis in enumerate(table["axis"]):
        if axis not in _AXES:
            raise field_error(table.path, "axis", f"row {row + 1}: {axis!r} is not one of "
                              f"{', '.join(_AXES)}")
        periods[str(axis)] = np.array([table[f"period_{t}"][row] for t in (1, 2, 3)])
    missing = [a for a in _AXES if a not in periods]
    if missing:
        raise field_error(table.path, "axis", f"no row for {', '.join(missing)}")
    rig_spec = {"mass": Column("kg", 0.0, 100.0), "gravity": Column("m/s^2", 9.0, 10.5),
                "wire_half_spacing": Column("m", 0.0, 5.0),
                "wire_length": Column("m", 0.0, 20.0)}
    rig_table = read_table(rig_path or DATA_DIR / "bifilar_rig_4_3_3.csv", rig_spec, min_rows=1)
    if len(rig_table) != 1:
        raise field_error(rig_table.path, "mass", "expected exactly one row of rig constants")
    rig = BifilarRig(*(float(rig_table[k][0]) for k in rig_spec), source=rig_table.source)
    return BifilarTable(periods, rig, table.source, table.path)
