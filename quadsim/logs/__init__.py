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

Optional packages: ``pip install -e '.[logs]'`` (pyulog, pymavlink); the uSD reader needs
nothing.
"""

from __future__ import annotations

from pathlib import Path

from ..core.bounded import Budget, run_bounded
from ..core.errors import InputError, field_error
from .common import Columns, parse_rotor_map, resample

FORMATS = ("ulog", "usd", "dataflash")
#: every format a command reads a flight log from, for its --help.
READABLE = ("quadsim flight-log CSV, .csv.gz or Parquet; PX4 ULog (.ulg); Crazyflie uSD card "
            "log; ArduPilot DataFlash (.bin)")
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


#: Time budget of one import: PARSE_TIME_S plus PARSE_TIME_S_PER_MB per MB of file (the
#: real 1 MB DataFlash log parses in about 2 s on the 2-core development machine).
PARSE_TIME_S = 30.0
PARSE_TIME_S_PER_MB = 10.0
#: Memory budget of one import: PARSE_MEMORY_BYTES plus PARSE_MEMORY_PER_BYTE x file size.
PARSE_MEMORY_BYTES = 2 * 1024**3
PARSE_MEMORY_PER_BYTE = 100
_NAMES = {"ulog": "ULog (pyulog)", "usd": "uSD log", "dataflash": "DataFlash (pymavlink)"}


def parse_budget(path: str | Path) -> Budget:
    """The time and memory budget of importing ``path`` (see PARSE_TIME_S...)."""
    try:
        size = Path(path).stat().st_size
    except OSError:
        size = 0
    return Budget(time_s=PARSE_TIME_S + PARSE_TIME_S_PER_MB * size / 1e6,
                  memory_bytes=int(PARSE_MEMORY_BYTES + PARSE_MEMORY_PER_BYTE * size))


#: the first bytes of a stored reference (:mod:`quadsim.gap.reffile`, schema
#: ``quadsim.gap.reference/1``: its JSON header line); spelled here, as ``logs`` imports no
#: later stage
QREF_HEADER = b'{"schema": "quadsim.gap.reference/'


def file_kind(path: str | Path) -> str | None:
    """What a file is by its first bytes, for messages that catch a swapped argument: "a
    PX4 ULog flight log", "a Crazyflie uSD flight log", "an ArduPilot DataFlash flight log",
    "a gzip-compressed file (a .csv.gz flight log?)", "a Parquet file (a flight log?)", "a
    quadsim stored reference (.qref)" (``gap --write-reference``'s JSON header line), "a CSV
    flight log" (a header with ``t``), "a TOML file" (a ``schema =`` or ``[section]``
    line), or None (unreadable, none of these, or binary: a NUL byte, which no CSV or TOML
    holds, so random bytes that happen to hold a newline then ``[`` are no TOML file)."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(4096)
    except OSError:
        return None
    fmt = detect_format(path)
    if fmt is not None:
        return {"ulog": "a PX4 ULog flight log", "usd": "a Crazyflie uSD flight log",
                "dataflash": "an ArduPilot DataFlash flight log"}[fmt]
    if head.startswith(b"\x1f\x8b"):
        return "a gzip-compressed file (a .csv.gz flight log?)"
    if head.startswith(b"PAR1"):
        return "a Parquet file (a flight log?)"
    if head.startswith(QREF_HEADER):
        return "a quadsim stored reference (.qref)"
    if b"\0" in head:
        return None
    text = head.decode("utf-8", "replace")
    first = text.splitlines()[0] if text else ""
    if "," in first and "t" in [c.strip() for c in first.split(",")]:
        return "a CSV flight log"
    if any(line.strip().startswith(("schema =", "schema=", "[")) for line in text.splitlines()):
        return "a TOML file"
    return None


_MAGIC_BY_SUFFIX = {".ulg": ("ULog", "554c6f67011235"), ".bin": ("DataFlash", "a39580")}


def refuse_binary(path: Path) -> None:
    """A ``.ulg``/``.bin`` whose first bytes are not its format's magic, a stored reference
    (``.qref``, :data:`QREF_HEADER`), or a binary file that is no format at all, is refused
    here (not handed to the CSV reader)."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(4096)
    except OSError:
        return
    shown = head[:8].hex() or "none (empty file)"
    suffix = path.suffix.lower()
    if suffix in _MAGIC_BY_SUFFIX:
        name, magic = _MAGIC_BY_SUFFIX[suffix]
        raise field_error(path, "header", f"first bytes {shown}, not the {name} magic "
                          f"{magic}: a damaged or a different file")
    if head.startswith(QREF_HEADER):
        raise field_error(path, "header", "a quadsim stored reference (.qref), not a flight "
                          "log: give it to quadsim.gap as --reference")
    if b"\0" in head and not head.startswith((b"PAR1", b"\x1f\x8b")):
        raise field_error(path, "header", f"first bytes {shown} match no log format (PX4 "
                          "ULog, Crazyflie uSD, ArduPilot DataFlash, CSV, Parquet)")


def read_columns(path: str | Path, *, fmt: str | None = None,
                 rotor_map: tuple[int, ...] | None = None, topics: dict | None = None,
                 fields: dict | None = None,
                 pwm_range: tuple[float, float] | None = None,
                 rate_hz: float | None = None, budget: Budget | None = None,
                 euler: str | None = None) -> Columns:
    """Schema columns (SI, our frames) of a foreign log. ``topics``/``fields`` (ULog:
    signal -> topic / field prefix; signals as in ``ulog.TOPICS``), ``pwm_range`` (us),
    ``rate_hz`` (ULog only: uniform time base instead of the attitude instants), ``euler``
    (uSD: the convention of ``stateEstimate.roll/pitch/yaw``, :mod:`.attitude`).

    The parse runs in a worker process under ``budget`` (default :func:`parse_budget`;
    :mod:`quadsim.core.bounded`); what the parser printed becomes one note."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    fmt = fmt or detect_format(path)
    if fmt not in FORMATS:
        raise InputError(f"{path}: unknown log format (expected one of {', '.join(FORMATS)}, "
                         "or a CSV/Parquet flight log)")
    options = {"rotor_map": rotor_map, "topics": topics or {}, "fields": fields or {},
               "pwm_range": pwm_range, "rate_hz": rate_hz, "euler": euler}
    columns, chatter = run_bounded(_read_here, path, fmt, options, label=str(path),
                                   what=_NAMES[fmt], budget=budget or parse_budget(path))
    if chatter.total:
        columns.notes.append(f"{path}: {_NAMES[fmt]} printed {chatter.summary()}")
    return columns


def _read_here(path: Path, fmt: str, options: dict) -> Columns:
    """The import itself (in the worker process of :func:`read_columns`)."""
    columns = _parse(path, fmt, options)
    columns = columns if isinstance(columns, Columns) else Columns(columns)
    if fmt in ("ulog", "dataflash"):
        from .framing import framing_note
        note = framing_note(path, fmt, path.read_bytes())
        if note:
            columns.notes.append(note)
    return columns


def _parse(path: Path, fmt: str, options: dict) -> dict:
    rotor_map, topics = options["rotor_map"], options["topics"]
    if fmt == "ulog":
        from .ulog import ulog_columns
        return ulog_columns(path, rotor_map=rotor_map, topics=topics, fields=options["fields"],
                            pwm_range=options["pwm_range"] or (1000.0, 2000.0),
                            rate_hz=options["rate_hz"])
    if fmt == "usd":
        from .usd import usd_columns
        return usd_columns(path, rotor_map=rotor_map, event=topics.get("event"),
                           pose=topics.get("pose"), euler=options.get("euler"))
    from .dataflash import dataflash_columns
    return dataflash_columns(path, rotor_map=rotor_map, pwm_range=options["pwm_range"])


__all__ = ["FORMATS", "READABLE", "Columns", "detect_format", "file_kind", "parse_budget",
           "parse_rotor_map", "read_columns", "refuse_binary", "resample"]
