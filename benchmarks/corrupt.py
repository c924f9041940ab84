"""Deterministic corruptions of small foreign logs and the judge of what the loader made of
them: the engine of ``benchmarks/fuzz_logs.py`` and of the fuzz cases in the test suite.

A case is ``(format, index)``; its seed is ``SEED + index`` and it picks one corruption:

* bytes -- bit flips (1-8), a zeroed or a random run (1-64 bytes), truncation, a block
  (16-512 bytes) duplicated or removed, damage in the first 15 % (format and definition
  messages), damaged magic bytes, a wrong file with the right name (random bytes, text,
  another format);
* values, written by the format's own writer (:mod:`quadsim.logs.samples`) -- NaN, inf or a
  huge number in one sample of one signal, a quaternion scaled by 2 or zeroed, two
  timestamps swapped or made equal, a jump of the clock, a unit slip (position in mm, time
  in ms, gyro in deg/s, ...), a damaged parameter (``CA_ROTOR_COUNT``, ``MAV_TYPE``,
  ``FRAME_CLASS``, ``MOT_PWM_MIN`` NaN, inf, negative, huge).

:func:`judge` loads the file (``quadsim.logs.flightlog.load_log``, which parses foreign
formats in a worker process under a time budget) and classifies the outcome:

* ``refusal`` -- one ``InputError`` line that names the file;
* ``hang`` -- refused by the parser's time budget (the parser itself did not return);
* ``uncaught`` -- any other exception, or an error from quadsim's own code in the worker
  ("internal error"), or an error message that is not one printable line;
* ``garbage`` -- a log came back with values no multirotor has (checked here,
  independently of :mod:`quadsim.logs.plausible`: |position| > 1e4 m, |velocity| > 100
  m/s, |specific force| > 400 m/s^2, steps implying > 300 m/s or > 100 rad/s, battery
  outside 0-100 V, negative rotor speeds, quaternions off unit length by > 1e-3) or with
  fewer than 95 % of the flight's samples and no note saying so (except a file cut exactly
  at a message boundary: byte for byte a shorter valid log, counted plausible);
* ``plausible`` -- a log came back and passed all of that.
"""

from __future__ import annotations

import dataclasses
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadsim.core.bounded import Budget
from quadsim.core.errors import InputError, printable

__all__ = ["FORMATS", "OUTCOMES", "SEED", "Case", "hanging_ulog_bytes", "judge", "judge_batch",
           "judge_here", "make_case"]

SEED = 20261124
FORMATS = ("ulog", "dataflash", "usd")
OUTCOMES = ("refusal", "plausible", "garbage", "uncaught", "hang")
SUFFIX = {"ulog": ".ulg", "dataflash": ".bin", "usd": ""}
_BYTE_KINDS = ("bitflip", "zero_run", "random_run", "truncate", "duplicate_block",
               "remove_block", "damage_head", "damage_magic", "wrong_file")
_VALUE_KINDS = ("value", "quat_scale", "time_swap", "time_equal", "time_jump", "unit_slip",
                "parameter")
_SIGNALS = ("position", "velocity", "quat", "body_rate", "accel", "rotor_speed", "command",
            "vbat")
_BAD_VALUES = (np.nan, np.inf, -np.inf, 1e30, -1e30, 1e6, -5e3, 0.0)


@dataclass(frozen=True)
class Case:
    """One corrupted log: ``data`` to be written as ``name``; ``kind``/``detail`` say what
    was done; ``samples`` is the clean flight's sample count."""

    fmt: str
    index: int
    kind: str
    detail: str
    data: bytes
    samples: int

    @property
    def name(self) -> str:
        return f"case{self.index:06d}{SUFFIX[self.fmt]}"


def _flight():
    from quadsim.logs.samples import sample_flight

    return sample_flight(duration_s=1.0, rate_hz=100.0)


def _encode(fmt: str, flight, params: dict | None = None) -> bytes:
    from quadsim.logs.samples import dataflash_bytes, ulog_bytes, usd_bytes

    if fmt == "ulog":
        return ulog_bytes(flight, params=params)
    if fmt == "dataflash":
        return dataflash_bytes(flight, params=params)
    return usd_bytes(flight)


_CLEAN: dict[str, bytes] = {}


def clean_bytes(fmt: str) -> bytes:
    """The uncorrupted sample log of ``fmt`` (cached)."""
    if fmt not in _CLEAN:
        _CLEAN[fmt] = _encode(fmt, _flight())
    return _CLEAN[fmt]


def _bytes_case(fmt: str, kind: str, rng: np.random.Generator) -> tuple[str, bytes]:
    data = bytearray(clean_bytes(fmt))
    n = len(data)
    if kind == "bitflip":
        spots = rng.integers(0, n * 8, rng.integers(1, 9))
        for bit in spots:
            data[bit // 8] ^= 1 << (bit % 8)
        return f"{len(spots)} bit(s)", bytes(data)
    if kind in ("zero_run", "random_run"):
        size = int(rng.integers(1, 65))
        at = int(rng.integers(0, n - size))
        data[at:at + size] = bytes(size) if kind == "zero_run" else rng.bytes(size)
        return f"{size} bytes at {at}", bytes(data)
    if kind == "truncate":
        at = int(rng.integers(1, n))
        return f"at {at} of {n}", bytes(data[:at])
    if kind in ("duplicate_block", "remove_block"):
        size = int(rng.integers(16, 513))
        at = int(rng.integers(0, n - size))
        block = data[at:at + size]
        out = data[:at] + block + data[at:] if kind == "duplicate_block" else \
            data[:at] + data[at + size:]
        return f"{size} bytes at {at}", bytes(out)
    if kind == "damage_head":
        head = max(16, int(0.15 * n))
        for _ in range(int(rng.integers(1, 9))):
            data[int(rng.integers(0, head))] = int(rng.integers(0, 256))
        return f"first {head} bytes", bytes(data)
    if kind == "damage_magic":
        at = int(rng.integers(0, 3))
        data[at] ^= int(rng.integers(1, 256))
        return f"byte {at}", bytes(data)
    choice = int(rng.integers(0, 3))
    if choice == 0:
        return "random bytes", rng.bytes(int(rng.integers(0, 4096)))
    if choice == 1:
        return "text", b"not a log\n" * int(rng.integers(0, 100))
    other = [f for f in FORMATS if f != fmt][int(rng.integers(0, 2))]
    return f"a {other} log", clean_bytes(other)


def _value_case(fmt: str, kind: str, rng: np.random.Generator) -> tuple[str, bytes]:
    flight = _flight()
    n = len(flight.t)
    k = int(rng.integers(1, n - 1))
    if kind == "value":
        signal = _SIGNALS[int(rng.integers(0, len(_SIGNALS)))]
        value = _BAD_VALUES[int(rng.integers(0, len(_BAD_VALUES)))]
        array = np.array(getattr(flight, signal), dtype=float)
        if array.ndim == 1:
            array[k] = value
        else:
            array[k, int(rng.integers(0, array.shape[1]))] = value
        return f"{signal}[{k}] = {value:g}", _encode(fmt, dataclasses.replace(
            flight, **{signal: array}))
    if kind == "quat_scale":
        quat = flight.quat.copy()
        scale = (2.0, 0.0, 1e30, 0.5)[int(rng.integers(0, 4))]
        rows = slice(k, k + int(rng.integers(1, 20)))
        quat[rows] *= scale
        return f"quat x{scale:g} from {k}", _encode(fmt, dataclasses.replace(flight, quat=quat))
    if kind in ("time_swap", "time_equal", "time_jump"):
        t = flight.t.copy()
        if kind == "time_swap":
            t[k], t[k + 1] = t[k + 1], t[k]
        elif kind == "time_equal":
            t[k + 1] = t[k]
        else:
            t[k:] += (1e3, 1e6, -0.5)[int(rng.integers(0, 3))]
        return f"{kind} at {k}", _encode(fmt, dataclasses.replace(flight, t=t))
    if kind == "unit_slip":
        slips = {"position": 1000.0, "t": 1000.0, "body_rate": 180.0 / np.pi,
                 "accel": 1.0 / 9.81, "rotor_speed": 60.0 / (2 * np.pi), "vbat": 1000.0,
                 "velocity": 1000.0}
        name = list(slips)[int(rng.integers(0, len(slips)))]
        scaled = getattr(flight, name) * slips[name]
        return f"{name} x{slips[name]:.4g}", _encode(fmt, dataclasses.replace(
            flight, **{name: scaled}))
    names = {"ulog": ("CA_ROTOR_COUNT", "MAV_TYPE"),
             "dataflash": ("FRAME_CLASS", "MOT_PWM_MIN", "MOT_PWM_MAX"), "usd": ()}[fmt]
    if not names:
        return _bytes_case(fmt, "bitflip", rng)
    name = names[int(rng.integers(0, len(names)))]
    value = (np.nan, np.inf, -1.0, 1e9, 6.0, 22.0)[int(rng.integers(0, 6))]
    return f"{name} = {value:g}", _encode(fmt, flight, params={name: value})


def make_case(fmt: str, index: int) -> Case:
    """Case ``index`` of format ``fmt`` (deterministic: same index, same bytes)."""
    rng = np.random.default_rng([SEED, FORMATS.index(fmt), index])
    kinds = _BYTE_KINDS + _VALUE_KINDS
    kind = kinds[int(rng.integers(0, len(kinds)))]
    with np.errstate(all="ignore"):  # the writers convert corrupt values as they are
        if kind in _BYTE_KINDS:
            detail, data = _bytes_case(fmt, kind, rng)
        else:
            detail, data = _value_case(fmt, kind, rng)
    return Case(fmt, index, kind, detail, data, len(_flight().t))


# ----------------------------------------------------------------------------- judging


def _garbage(log, samples: int) -> str | None:
    """What is impossible about a log that loaded (independent checks), or None."""
    checks = [("position", 1e4), ("velocity", 100.0), ("accel", 400.0)]
    for name, limit in checks:
        value = getattr(log, name)
        if value is not None and np.nanmax(np.linalg.norm(value, axis=1), initial=0) > limit:
            return f"|{name}| above {limit:g}"
    dt = np.diff(log.t)
    if log.position is not None:  # an IMU-only log (no pose) is a log too (docs/flightlog.md)
        step = np.linalg.norm(np.diff(log.position, axis=0), axis=1)
        if np.nanmax(step / dt, initial=0) > 300.0:
            return "position step above 300 m/s"
    if log.quat is not None:
        norms = np.linalg.norm(log.quat, axis=1)
        if np.max(np.abs(norms - 1.0)) > 1e-3:
            return "quaternion not unit"
        dot = np.clip(np.abs(np.sum(log.quat[1:] * log.quat[:-1], axis=1)), 0, 1)
        if np.max(2 * np.arccos(dot) / dt, initial=0) > 100.0:
            return "attitude step above 100 rad/s"
    if log.vbat is not None and (np.nanmin(log.vbat) < 0 or np.nanmax(log.vbat) > 100):
        return "battery voltage outside 0-100 V"
    if log.rotor_speed is not None and np.nanmin(log.rotor_speed) < -1.0:
        return "negative rotor speed"
    if len(log) < 0.95 * samples and not any(
            word in note for note in log.notes for word in ("lost", "gap", "left out")):
        return f"{len(log)} of {samples} samples, no note"
    return None


def judge(case: Case, folder: Path, *, time_s: float = 10.0) -> tuple[str, str]:
    """(outcome, message) of loading ``case`` written into ``folder`` (see module)."""
    from quadsim.logs.flightlog import load_log

    path = Path(folder) / case.name
    path.write_bytes(case.data)
    try:
        log = load_log(path, warn=False, budget=Budget(time_s=time_s))
    except InputError as exc:
        text = str(exc)
        line = printable(text, limit=10_000)
        if "no result within" in text:
            return "hang", line
        if "internal error" in text or "\n" in text or not text.startswith(str(path)):
            return "uncaught", line
        return "refusal", line
    except Exception as exc:  # noqa: BLE001 (that is what the fuzzer counts)
        return "uncaught", f"{type(exc).__name__}: {printable(exc)}"
    finally:
        path.unlink(missing_ok=True)
    problem = _garbage(log, case.samples)
    if problem and problem.endswith("no note") and _whole(case):
        problem = None  # cut at a message boundary: byte for byte a shorter, valid log
    return ("garbage", problem) if problem else ("plausible", f"{len(log)} samples")


def _whole(case: Case) -> bool:
    """A truncated file that still consists of whole messages only."""
    from quadsim.logs.framing import dataflash_framing, ulog_framing

    if case.kind != "truncate" or case.fmt == "usd":
        return False
    if case.fmt == "ulog":
        return ulog_framing(case.data)[0] is None
    return dataflash_framing(case.data)[0] == 0


def judge_here(case: Case, folder: Path) -> tuple[str, str]:
    """:func:`judge` without the worker process: the importer runs in this process (for a
    batch of cases that the caller bounds as a whole, e.g. with
    :func:`quadsim.core.bounded.run_bounded`); a hang is the caller's time budget."""
    from quadsim.logs import _read_here, detect_format
    from quadsim.logs.flightlog import log_from_columns, read_log_columns

    path = Path(folder) / case.name
    path.write_bytes(case.data)
    options = {"rotor_map": None, "topics": {}, "fields": {}, "pwm_range": None,
               "rate_hz": None}
    try:
        fmt = detect_format(path)
        if fmt is None:
            columns = read_log_columns(path)
        else:
            columns = _read_here(path, fmt, options)
        log = log_from_columns(path, columns, warn=False)
    except InputError as exc:
        text = str(exc)
        if "\n" in text or not text.startswith(str(path)):
            return "uncaught", printable(text, limit=10_000)
        return "refusal", printable(text, limit=10_000)
    except Exception as exc:  # noqa: BLE001 (that is what is counted)
        return "uncaught", f"{type(exc).__name__}: {printable(exc)}"
    finally:
        path.unlink(missing_ok=True)
    problem = _garbage(log, case.samples)
    if problem and problem.endswith("no note") and _whole(case):
        problem = None
    return ("garbage", problem) if problem else ("plausible", f"{len(log)} samples")


def judge_batch(fmt: str, indices: list[int], folder: str) -> list[tuple[int, str, str]]:
    """``(index, outcome, message)`` of :func:`judge_here` for cases ``indices`` of ``fmt``."""
    import warnings

    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for index in indices:
            case = make_case(fmt, index)
            outcome, message = judge_here(case, Path(folder))
            out.append((index, outcome, f"{case.kind} ({case.detail}): {message}"))
    return out


def hanging_ulog_bytes() -> bytes:
    """A small ULog on which pyulog (1.3) never returns: the definitions section of the
    sample log, then a message header of type 0 whose size runs past the end of the file.
    pyulog reads the short rest, judges the header corrupt and seeks back ``2 + size``
    bytes, which lands exactly on the previous message; it re-reads that and the same
    header again, for ever."""
    data = clean_bytes("ulog")
    at, previous = 16, 16
    while True:
        size, kind = struct.unpack_from("<HB", data, at)
        if chr(kind) in "AL":  # first message of the data section
            break
        previous, at = at, at + 3 + size
    rest = 10
    return data[:at] + struct.pack("<HB", rest + 1 + (at - previous), 0) + bytes(rest)
