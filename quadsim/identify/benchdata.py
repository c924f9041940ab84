"""Bench data: the report's measured tables and real thrust-stand sweeps, read and checked.

Every table is a CSV file whose header names each column's unit, ``name[unit]`` (our own
files in ``quadsim/identify/data/``) or ``name_unit`` (the thrust-stand logs, e.g. ``speed_rpm``).
Lines starting with ``#`` are comments; our files carry a ``# source:`` line naming the
report table they transcribe. Units are converted to SI here, at the boundary (RPM -> rad/s,
grams -> kg, mm -> m, µs stays a command unit), and nothing else in the package sees RPM.

Checks (each failure is one :class:`~quadsim.core.errors.InputError` line naming file and column):
unknown or missing columns, a column without a unit, a unit that does not fit the column,
empty / non-numeric / NaN cells, implausible magnitudes (e.g. RPM numbers in a rad/s
column, grams in a kg column), and fewer rows than the fit needs.

Example::

    >>> from quadsim.identify.benchdata import load_force_lift
    >>> lift = load_force_lift()            # report Tables 4.5, 4.7, 4.9, 4.11
    >>> lift.thrust.shape, lift.speed.shape # (motor, trial, command) in N and rad/s
    ((4, 3, 11), (4, 3, 11))

Conventions: force from a scale reading is ``F = m g`` with the report's g = 9.81 m/s^2
(Table 4.15), so a transcription check reproduces the report's Force column.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import InputError, field_error

__all__ = [
    "DATA_DIR",
    "REPORT_GRAVITY",
    "BenchTable",
    "Column",
    "ForceLift",
    "SpeedSweep",
    "load_cfd_table",
    "load_force_lift",
    "load_physical_measurements",
    "load_testbed_constants",
    "load_thrust_stand",
    "load_torque_thrust_ratio",
    "read_table",
]

#: Folder of the transcribed report tables shipped with the package.
DATA_DIR = Path(__file__).resolve().parent / "data"
#: g used by the report to turn scale readings into force (Table 4.15), m/s^2.
REPORT_GRAVITY = 9.81

# unit as written -> (factor to SI, SI unit)
_UNITS = {
    "kg": (1.0, "kg"), "g": (1e-3, "kg"),
    "m": (1.0, "m"), "mm": (1e-3, "m"), "cm": (1e-2, "m"), "in": (0.0254, "m"),
    "kg/m^3": (1.0, "kg/m^3"),
    "s": (1.0, "s"), "ms": (1e-3, "s"),
    "N": (1.0, "N"), "N m": (1.0, "N m"), "Nm": (1.0, "N m"),
    "rad/s": (1.0, "rad/s"), "rpm": (2.0 * math.pi / 60.0, "rad/s"),
    "m/s^2": (1.0, "m/s^2"), "A": (1.0, "A"), "V": (1.0, "V"),
    "pwm": (1.0, "pwm"), "us": (1.0, "us"), "%": (1.0, "%"),
}
# suffix spellings of thrust-stand headers (``speed_rpm``)
_SUFFIX_UNITS = {"Nm": "N m", "N": "N", "rpm": "rpm", "A": "A", "us": "us", "kg": "kg",
                 "g": "g", "s": "s", "m": "m", "V": "V", "rad_s": "rad/s"}


@dataclass(frozen=True)
class Column:
    """What a column must hold: its SI unit and the plausible range of its SI values.

    ``si_unit`` None marks a text label column (no unit)."""

    si_unit: str | None
    low: float = -math.inf
    high: float = math.inf
    optional: bool = False


@dataclass(frozen=True)
class BenchTable:
    """A checked table: ``columns[name]`` in SI (labels as str arrays), ``units[name]``."""

    path: Path
    source: str
    columns: dict[str, np.ndarray]
    units: dict[str, str | None] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0


def _split_header(cell: str, path: Path, spec: dict[str, Column]) -> tuple[str, str | None]:
    cell = cell.strip()
    if cell.endswith("]") and "[" in cell:
        name, unit = cell[:-1].split("[", 1)
        return name.strip(), unit.strip()
    if cell in spec and spec[cell].si_unit is None:
        return cell, None
    for suffix, unit in sorted(_SUFFIX_UNITS.items(), key=lambda kv: -len(kv[0])):
        if cell.endswith("_" + suffix) and cell[: -len(suffix) - 1] in spec:
            return cell[: -len(suffix) - 1], unit
    raise field_error(path, cell, "no unit in the header (write it as name[unit], e.g. "
                      "speed[rad/s])")


def _read_rows(path: Path) -> tuple[list[str], list[list[str]], str]:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read: {exc}") from None
    source, lines = "", []
    for line in text.splitlines():
        if line.lstrip().startswith("#"):
            body = line.lstrip()[1:].strip()
            if body.lower().startswith("source:"):
                source = body.split(":", 1)[1].strip()
        elif line.strip():
            lines.append(line)
    rows = list(csv.reader(lines))
    if not rows:
        raise InputError(f"{path}: no header row")
    return rows[0], rows[1:], source


def _convert(path: Path, name: str, unit: str, column: Column, cells: list[str]) -> np.ndarray:
    if unit not in _UNITS or _UNITS[unit][1] != column.si_unit:
        valid = sorted(u for u, (_, si) in _UNITS.items() if si == column.si_unit)
        raise field_error(path, name, f"unit {unit!r} does not fit (valid: {', '.join(valid)})")
    try:
        values = np.array([float(c) if c.strip() else math.nan for c in cells])
    except ValueError:
        bad = next(c for c in cells if not _is_float(c))
        raise field_error(path, name, f"value {bad!r} is not a number") from None
    if not np.all(np.isfinite(values)):
        row = int(np.flatnonzero(~np.isfinite(values))[0]) + 1
        raise field_error(path, name, f"NaN, empty or infinite value in data row {row}")
    values = values * _UNITS[unit][0]
    if values.size and (values.min() < column.low or values.max() > column.high):
        worst = values.max() if values.max() > column.high else values.min()
        hint = " (RPM given as rad/s?)" if column.si_unit == "rad/s" else (
            " (grams given as kg?)" if column.si_unit == "kg" else "")
        raise field_error(path, name, f"value {worst / _UNITS[unit][0]:g} {unit} is implausible: "
                          f"expected {column.low:g}..{column.high:g} {column.si_unit}{hint}")
    return values


def _is_float(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def read_table(path: str | Path, spec: dict[str, Column], *, min_rows: int = 1) -> BenchTable:
    """Read a CSV table, check it against ``spec`` (name -> :class:`Column`), convert to SI."""
    path = Path(path)
    header, rows, source = _read_rows(path)
    names = [_split_header(cell, path, spec) for cell in header]
    unknown = [n for n, _ in names if n not in spec]
    if unknown:
        raise field_error(path, unknown[0], f"unknown column (valid: {', '.join(spec)})")
    present = {n for n, _ in names}
    missing = [n for n, c in spec.items() if not c.optional and n not in present]
    if missing:
        raise field_error(path, missing[0], "missing column")
    for i, row in enumerate(rows, start=1):
        if len(row) != len(names):
            raise field_error(path, f"row {i}", f"{len(row)} cells where the header has "
                              f"{len(names)}")
    if len(rows) < min_rows:
        raise field_error(path, names[0][0], f"{len(rows)} data rows, at least {min_rows} "
                          "needed")
    columns, units = {}, {}
    for j, (name, unit) in enumerate(names):
        cells = [row[j] for row in rows]
        if spec[name].si_unit is None:
            columns[name] = np.array([c.strip() for c in cells])
        else:
            if unit is None:
                raise field_error(path, name, "no unit in the header")
            columns[name] = _convert(path, name, unit, spec[name], cells)
        units[name] = spec[name].si_unit
    return BenchTable(path, source, columns, units)


# ----------------------------------------------------------------------------- report tables

_SPEED = Column("rad/s", 0.0, 4000.0)      # 4000 rad/s = 38 000 RPM: beyond any hobby prop
_COMMAND = Column("pwm", 0.0, 255.0)


@dataclass(frozen=True)
class ForceLift:
    """Force-lift test: per motor, per trial, per command step.

    ``command`` (K,) PWM value; ``thrust`` (M, T, K) N; ``speed`` (M, T, K) rad/s;
    ``published_force`` / ``published_speed`` (M, K): the report's own average columns."""

    command: np.ndarray
    thrust: np.ndarray
    speed: np.ndarray
    published_force: np.ndarray
    published_speed: np.ndarray
    sources: tuple[str, ...]
    paths: tuple[Path, ...]


FORCE_LIFT_FILES = (
    "table_4_5_force_lift_motor1.csv",
    "table_4_7_force_lift_motor2.csv",
    "table_4_9_force_lift_motor3.csv",
    "table_4_11_force_lift_motor4.csv",
)
_FORCE_LIFT_SPEC = {
    "pwm": _COMMAND,
    **{f"mass_{t}": Column("kg", 0.0, 5.0) for t in (1, 2, 3)},
    **{f"speed_{t}": _SPEED for t in (1, 2, 3)},
    "published_force": Column("N", 0.0, 50.0, optional=True),
    "published_speed": Column("rad/s", 0.0, 4000.0, optional=True),
}


def load_force_lift(paths: list[str | Path] | None = None) -> ForceLift:
    """Load the force-lift tables (default: report Tables 4.5, 4.7, 4.9, 4.11, motors 1-4)."""
    paths = [Path(p) for p in paths] if paths else [DATA_DIR / f for f in FORCE_LIFT_FILES]
    tables = [read_table(p, _FORCE_LIFT_SPEC, min_rows=2) for p in paths]
    command = tables[0]["pwm"]
    for table in tables[1:]:
        if table["pwm"].shape != command.shape or np.any(table["pwm"] != command):
            raise field_error(table.path, "pwm", f"command steps differ from {tables[0].path}")
    thrust = np.array([[t[f"mass_{i}"] for i in (1, 2, 3)] for t in tables]) * REPORT_GRAVITY
    speed = np.array([[t[f"speed_{i}"] for i in (1, 2, 3)] for t in tables])
    nan = np.full(command.shape, np.nan)
    return ForceLift(
        command=command, thrust=thrust, speed=speed,
        published_force=np.array([t.columns.get("published_force", nan) for t in tables]),
        published_speed=np.array([t.columns.get("published_speed", nan) for t in tables]),
        sources=tuple(t.source for t in tables), paths=tuple(paths),
    )


@dataclass(frozen=True)
class SpeedSweep:
    """Thrust (and torque where measured) against rotor speed, one row per point.

    ``speed`` rad/s, ``thrust`` N, ``torque`` N m (NaN-free; None when not measured),
    ``command`` in ``command_unit``."""

    speed: np.ndarray
    thrust: np.ndarray
    torque: np.ndarray | None
    command: np.ndarray
    command_unit: str
    source: str
    path: Path


def load_cfd_table(path: str | Path | None = None) -> SpeedSweep:
    """Report Table 4.2: SolidWorks Flow Simulation thrust against speed."""
    spec = {"pwm": _COMMAND, "speed": _SPEED, "thrust": Column("N", 0.0, 50.0),
            "published_speed": Column("rad/s", 0.0, 4000.0, optional=True)}
    table = read_table(path or DATA_DIR / "table_4_2_cfd.csv", spec, min_rows=2)
    return SpeedSweep(table["speed"], table["thrust"], None, table["pwm"], "pwm",
                      table.source, table.path)


def load_thrust_stand(path: str | Path) -> SpeedSweep:
    """A thrust-stand sweep with columns ``esc_us, torque_Nm, thrust_N, speed_rpm[, current_A]``
    (the RCbenchmark logs in ``../shared/data/thrust_stand``)."""
    spec = {"esc": Column("us", 500.0, 2500.0), "torque": Column("N m", -50.0, 50.0),
            "thrust": Column("N", -5.0, 500.0), "speed": _SPEED,
            "current": Column("A", -1.0, 500.0, optional=True)}
    table = read_table(path, spec, min_rows=3)
    return SpeedSweep(table["speed"], table["thrust"], table["torque"], table["esc"], "us",
                      table.source or f"thrust-stand sweep {Path(path).name}", table.path)


_PHYSICAL_SPEC = {
    "trial": Column(None),
    **{k: Column("kg", 0.0, 5.0) for k in ("total_mass", "mechanical_mass", "battery_mass",
                                           "motor_mass", "propeller_mass", "base_mass")},
    **{k: Column("m", 0.0, 2.0) for k in ("frame_length", "motor_to_centre", "motor_to_motor",
                                          "base_radius")},
}


def load_physical_measurements(path: str | Path | None = None) -> BenchTable:
    """Report Table 4.4: one row per trial; masses in kg, lengths in m."""
    return read_table(path or DATA_DIR / "table_4_4_physical.csv", _PHYSICAL_SPEC, min_rows=1)


def load_testbed_constants(path: str | Path | None = None) -> BenchTable:
    """Facts about the testbed that are not bench measurements: propeller radius (from the
    10-inch diameter) and the air density assumed for the figure of merit."""
    spec = {"propeller_diameter": Column("m", 0.01, 2.0), "air_density": Column("kg/m^3", 0.5, 1.5)}
    return read_table(path or DATA_DIR / "testbed_constants.csv", spec, min_rows=1)


def load_torque_thrust_ratio(path: str | Path | None = None) -> BenchTable:
    """The stored torque/thrust ratio d/b (m) of a 10-inch propeller, with its 95 % interval
    and its source (written by ``scripts/write_params.py --stand-data``)."""
    spec = {"ratio": Column("m", 1e-4, 0.1), "ci95_low": Column("m", 1e-4, 0.1),
            "ci95_high": Column("m", 1e-4, 0.1)}
    return read_table(path or DATA_DIR / "torque_thrust_ratio.csv", spec, min_rows=1)
