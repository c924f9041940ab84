"""Flight logs as users have them -> the quadsim flight-log schema (``quadsim.logs.flightlog``).

Formats (detected from the first bytes, else from the file name; ``fmt`` forces one):

==========  ===========================  =============================  ======================
format      file                         magic bytes                    module
==========  ===========================  =============================  ======================
``ulog``    PX4 ``.ulg``                 ``ULog\\x01\\x12\\x35``           :mod:`.ulog` (pyulog)
``usd``     Crazyflie uSD card (v1, v2)  ``0xBC`` + version 1 or 2      :mod:`.usd`
``dataflash`` ArduPilot ``.bin``         ``0xA3 0x95 0x80`` (FMT)       :mod:`.dataflash`
                                                                        (pymavlink)
==========  ===========================  =============================  ======================

Each importer returns the schema's columns in SI units and our frames (world z up, body x
forward, y left, z up; quaternions wxyz body to world); :func:`quadsim.logs.flightlog.load_log`
then validates them exactly like a CSV, so ``gap``, ``view`` and ``convert`` accept these
files directly. Resampling, frame rotations and rotor numbering: :mod:`.common`.

Example::

    >>> from quadsim.logs.flightlog import load_log
    >>> log = load_log("sample_px4_events.ulg")            # FlightLog, SI, our frames
    >>> from quadsim.logs import read_columns
    >>> cols = read_columns("eckart00", rotor_map=(1, 2, 3, 4))   # raw column dict

Optional packages: ``pip install 'quadsim[logs]'`` (pyulog, pymavlink); the uSD reader needs
nothing.
"""

from __future__ import annotations

from pathlib import Path

from ..core.errors import InputError
from .common import parse_rotor_map, resample

FORMATS = ("ulog", "usd", "dataflash")
_SUFFIX = {".ulg": "ulog", ".bin": "dataflash"}


def detect_format(path: str | Path) -> str | None:
    """``"ulog"``, ``"usd"``, ``"dataflash"`` or None (a CSV/Parquet log or unknown)."""
    from .dataflash import is_dataflash
    from .ulog import is_ulog
    from .usd import is_usd

    path = Path(path)
    try:
        with open(path, "rb") as handle:
            head = handle.read(16)
    except OSError:
        return _SUFFIX.get(path.suffix.lower())
    if is_ulog(head):
        return "ulog"
    if is_dataflash(head):
        return "dataflash"
    if is_usd(head):
        return "usd"
    return None


def read_columns(path: str | Path, *, fmt: str | None = None,
                 rotor_map: tuple[int, ...] | None = None, topics: dict | None = None,
                 fields: dict | None = None,
                 pwm_range: tuple[float, float] | None = None,
                 rate_hz: float | None = None) -> dict:
    """Schema columns (SI, our frames) of a foreign log. ``topics``/``fields`` (ULog:
    signal -> topic / field prefix; signals as in ``ulog.TOPICS``), ``pwm_range`` (us),
    ``rate_hz`` (ULog only: uniform time base instead of the attitude instants)."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    fmt = fmt or detect_format(path)
    if fmt == "ulog":
        from .ulog import ulog_columns
        return ulog_columns(path, rotor_map=rotor_map, topics=topics, fields=fields,
                            pwm_range=pwm_range or (1000.0, 2000.0), rate_hz=rate_hz)
    if fmt == "usd":
        from .usd import usd_columns
        topics = topics or {}
        return usd_columns(path, rotor_map=rotor_map, event=topics.get("event"),
                           pose=topics.get("pose"))
    if fmt == "dataflash":
        from .dataflash import dataflash_columns
        return dataflash_columns(path, rotor_map=rotor_map, pwm_range=pwm_range)
    raise InputError(f"{path}: unknown log format (expected one of {', '.join(FORMATS)}, "
                     "or a CSV/Parquet flight log)")


__all__ = ["FORMATS", "detect_format", "parse_rotor_map", "read_columns", "resample"]
