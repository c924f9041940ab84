"""Flight logs: the CSV schema (gzip allowed), a validating loader and a deterministic writer.

One header row, one row per sample. Columns (SI). The minimum is **either the IMU** --
``t``, ``ax..az``, ``wx..wz`` and rotor speeds or motor commands, as most flight controllers
log it -- **or the pose** -- ``t``, ``x..z`` and an attitude (quaternion or Euler angles);
every other column may be absent:

=====================  ========  ====================================================
column                 unit      meaning
=====================  ========  ====================================================
``t``                  s         time since log start, strictly increasing
``x, y, z``            m         position, world frame, z up
``vx, vy, vz``         m/s       velocity, world frame
``qw, qx, qy, qz``     --        attitude quaternion, body to world, scalar first
``roll, pitch, yaw``   rad       attitude as Euler angles instead of the quaternion:
                                 z-y-x (yaw, then pitch, then roll, about the turned
                                 axes), body x forward, y left, z up in a z-up world;
                                 read as the quaternion (written back as ``qw..qz``)
``wx, wy, wz``         rad/s     body angular rate (gyro)
``ax, ay, az``         m/s^2     specific force, body frame (about +9.81 on z at rest)
``rotor_1..rotor_N``   rad/s     measured rotor speed
``cmd_1..cmd_N``       --        motor command, normalised 0-1
``vbat``               V         battery voltage
=====================  ========  ====================================================

Body frame: x forward, y left, z up. Position needs an attitude (the two together are the
pose); an IMU log without them (``FlightLog.position`` and ``quat`` None) is read, and each
stage says what it cannot do without a pose (:data:`WITHOUT_POSE`); so is one with its
attitude but no position (``position`` None: :data:`WITHOUT_POSITION`). Example::

    >>> from quadsim.logs.flightlog import load_log, write_log
    >>> log = load_log("flight_00.csv.gz")          # validates; raises InputError
    >>> log.t.shape, log.position.shape, log.rotor_speed.shape
    >>> write_log("copy.csv.gz", log)               # atomic, byte-deterministic
    >>> traj = log.to_trajectory()                  # quadsim.vehicle.state.Trajectory

Validation (:func:`load_log`): every problem is one line naming the file, the column and the
file line (the header is line 1). Errors (:class:`~quadsim.core.errors.InputError`): neither
the IMU minimum nor a pose (the message names what is missing for each), incomplete column
group (``vx`` without ``vy``), text that is not a number, non-finite values in
``t``/position/attitude, time not strictly increasing, quaternions that are not unit length,
and implausible units: rotor speeds that look like RPM (above ``MAX_ROTOR_SPEED`` rad/s),
body rates that look like deg/s (above ``MAX_BODY_RATE``),
accelerometer in g (median magnitude near 1 instead of 9.81), commands outside 0-1, battery
voltage in mV. Warnings (:class:`~quadsim.core.errors.QuadsimWarning`): NaN/Inf runs in optional
columns (kept as NaN), sample-rate jumps (a gap over ``GAP_FACTOR`` times the median step),
unknown columns (ignored).

Writer (:func:`write_log`): columns in schema order, floats as ``%.10g`` (time with full
precision, ``%.17g``, when ``%.10g`` would not keep its steps), ``\\n`` line ends;
``.gz`` output is gzip with mtime 0 and no stored file name, so equal logs give equal bytes.

Parquet (optional, ``pip install -e '.[parquet]'``): a ``.parquet`` file with the same
column names (float64) is read and validated the same way, and :func:`write_log` writes one
when the name ends in ``.parquet`` (zstd-compressed, deterministic). Problems in a Parquet
file are reported with the CSV-equivalent line number (row k is line k + 2). Reading a file
into columns is :mod:`quadsim.logs.csvfile`; :func:`read_log_columns` is re-exported here.
"""

from __future__ import annotations

import dataclasses
import gzip
import io
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import InputError, QuadsimWarning, field_error
from ..core.files import atomic_write_bytes
from ..core.frames import quat_conjugate, quat_multiply
from ..vehicle.state import Trajectory
from .csvfile import read_log_columns
from .plausible import check_plausible
from .rates import rates_of

__all__ = [
    "EULER",
    "FLOAT_FORMAT",
    "GAP_FACTOR",
    "LOG_SUFFIXES",
    "MAX_BODY_RATE",
    "MAX_ROTOR_SPEED",
    "WITHOUT_POSE",
    "WITHOUT_POSITION",
    "FlightLog",
    "body_rate_from_quat",
    "load_log",
    "log_bytes",
    "log_file_bytes",
    "log_from_columns",
    "parquet_bytes",
    "read_log_columns",
    "write_log",
]

#: rad/s; faster than any quadrotor propeller (~48 000 RPM), so larger values are RPM.
MAX_ROTOR_SPEED = 5000.0
#: rad/s; 3400 deg/s, beyond racing quadrotors' flips, so larger values are deg/s.
MAX_BODY_RATE = 60.0
#: a time step over GAP_FACTOR x the median step is reported as a sample-rate jump.
GAP_FACTOR = 5.0
#: s; the longest median sample step of a flight log (2 Hz: slower than a multirotor's
#: attitude dynamics, so no log worth reading has it; a 50 Hz log with ``t`` in
#: milliseconds reads as 20 s steps, in microseconds 20 000 s)
MAX_TIME_STEP = 0.5
#: fixed float format of the writer (10 significant digits).
FLOAT_FORMAT = "%.10g"

_GROUPS = {
    "position": ("x", "y", "z"),
    "velocity": ("vx", "vy", "vz"),
    "quat": ("qw", "qx", "qy", "qz"),
    "body_rate": ("wx", "wy", "wz"),
    "accel": ("ax", "ay", "az"),
}
_REQUIRED = ("t",)
#: the Euler-angle columns (rad, z-y-x), read as the quaternion.
EULER = ("roll", "pitch", "yaw")
#: how far (rad) a logged pitch may pass +-pi/2 before the log is refused (:func:`_minimum`):
#: an estimator's round-off at the gimbal point; a log in degrees passes it above 1.6 degrees
PITCH_SLACK = 0.01
#: one line a stage prints when a log has no pose (position and attitude).
WITHOUT_POSE = ("no position or attitude in the log (IMU and motors only): the body-frame "
                "force and torque balance is used; nothing that needs the world frame (speed, "
                "airspeed, drag, wind, ground effect, height) can be read; a pose (motion "
                "capture or the on-board estimate) would add it")
#: the same for a log with its attitude but no position (IMU, motors and attitude: the
#: on-board estimate's Euler angles or quaternion, as most flight controllers log them).
WITHOUT_POSITION = ("no position or velocity in the log (IMU, motors and attitude): the "
                    "body-frame force and torque balance is used, with the attitude for what "
                    "reads the world's directions (a payload swinging under gravity); nothing "
                    "that needs the speed or height (airspeed, drag, wind, ground effect) can "
                    "be read; a position or velocity (motion capture or the on-board estimate) "
                    "would add it")
#: the per-sample channels of a FlightLog (besides ``t``).
ARRAYS = ("position", "quat", "velocity", "body_rate", "accel", "rotor_speed",
          "rotor_command", "vbat")
_NUMBERED = re.compile(r"^(rotor|cmd)_(\d+)$")


@dataclass(frozen=True)
class FlightLog:
    """One flight, SI units (see the module docstring for the columns).

    t (N,) s; position (N, 3) m world or None; velocity (N, 3) m/s world or None; quat (N, 4)
    wxyz body-to-world or None (position None, quat given: IMU, motors and attitude; both
    None: an IMU-only log);
    body_rate (N, 3) rad/s body or None; accel (N, 3) specific force m/s^2 body or None;
    rotor_speed (N, R) rad/s or None; rotor_command (N, R) normalised 0-1 or None; vbat (N,)
    V or None; path: the file it came from (None if built in code); notes:
    the loader's remarks on suspicious but usable data (gaps, NaN runs, unknown columns);
    vehicle: what the log's own parameters say the vehicle is ("multirotor", "VTOL", ...;
    None when the log does not say, as in a CSV); segments: the sample indices where a new
    airborne stretch of the same flight starts (several take-offs, joined by
    :func:`quadsim.logs.spans.join_airborne`; empty for one stretch). The time axis jumps at
    each and the states with it: nothing may be interpolated, filtered or differentiated
    across one (:meth:`parts` gives the stretches); speeds_synthesised: True where
    rotor_speed was not logged but synthesised from rotor_command by a command -> speed
    model (:func:`quadsim.gap.logcheck.synthesise_speeds`): a timing read on it is the
    commands' timing through that model, not a logged signal's; corrections: what the
    checks changed in a channel, a short phrase each, no file name (a rotor speed read at a
    pulse-count factor, :func:`quadsim.logs.checks.check_rotor_speeds`): every answer on
    the log states them; rates_hz: each channel's native rate, ``((name, Hz), ...)`` with
    names of :data:`ARRAYS` (how often it was logged before the rows' resampling: the
    importer's, else read from the data by :func:`quadsim.logs.rates.native_rate`; a channel
    left out is unknown; :meth:`rate_hz`).
    """

    t: np.ndarray
    position: np.ndarray | None
    quat: np.ndarray | None
    velocity: np.ndarray | None = None
    body_rate: np.ndarray | None = None
    accel: np.ndarray | None = None
    rotor_speed: np.ndarray | None = None
    rotor_command: np.ndarray | None = None
    vbat: np.ndarray | None = None
    path: Path | None = None
    notes: tuple[str, ...] = ()
    vehicle: str | None = None
    segments: tuple[int, ...] = ()
    speeds_synthesised: bool = False
    corrections: tuple[str, ...] = ()
    rates_hz: tuple[tuple[str, float], ...] = ()

    def __post_init__(self):
        n = len(self.t)
        shapes = {"position": 3, "quat": 4, "velocity": 3, "body_rate": 3, "accel": 3}
        for name, width in shapes.items():
            value = getattr(self, name)
            if value is not None and np.shape(value) != (n, width):
                raise ValueError(f"FlightLog.{name}: shape {np.shape(value)}, "
                                 f"expected ({n}, {width})")
        for name in ("rotor_speed", "rotor_command"):
            value = getattr(self, name)
            if value is not None and (np.ndim(value) != 2 or len(value) != n):
                raise ValueError(f"FlightLog.{name}: shape {np.shape(value)}, expected ({n}, R)")
        if self.vbat is not None and np.shape(self.vbat) != (n,):
            raise ValueError(f"FlightLog.vbat: shape {np.shape(self.vbat)}, expected ({n},)")
        if list(self.segments) != sorted(set(self.segments)) or any(
                not 0 < k < n for k in self.segments):
            raise ValueError(f"FlightLog.segments: {self.segments}, expected increasing "
                             f"indices inside 1..{n - 1}")

    def __len__(self) -> int:
        return len(self.t)

    def rate_hz(self, channel: str) -> float | None:
        """The native rate (Hz) of ``channel`` (a name of :data:`ARRAYS`) as
        :attr:`rates_hz` states it, no faster than the rows' (1 / the median step: a channel
        resampled onto slower rows keeps only what they carry); None where unknown."""
        rate = dict(self.rates_hz).get(channel)
        if rate is None:
            return None
        steps = np.diff(self.t)
        rows = 1.0 / float(np.median(steps)) if len(steps) else np.inf
        return float(min(rate, rows))

    def parts(self) -> list[FlightLog]:
        """The airborne stretches of a joined log (:attr:`segments`), each a FlightLog with
        no segments; ``[self]`` when there is one."""
        if not self.segments:
            return [self]
        edges = (0, *self.segments, len(self.t))
        return [self.take(slice(a, b)) for a, b in zip(edges[:-1], edges[1:])]

    def take(self, index: slice) -> FlightLog:
        """The samples ``index`` (a slice) of every channel, without segments."""
        return dataclasses.replace(
            self, t=self.t[index], segments=(),
            **{name: (None if getattr(self, name) is None else getattr(self, name)[index])
               for name in ARRAYS})

    @property
    def has_pose(self) -> bool:
        """Whether the log has position and attitude (else it is IMU + motors only, with or
        without the attitude: :attr:`has_attitude`)."""
        return self.position is not None and self.quat is not None

    @property
    def has_attitude(self) -> bool:
        """Whether the log has its attitude (``qw..qz``, or ``roll, pitch, yaw``)."""
        return self.quat is not None

    @property
    def without_pose_words(self) -> str:
        """What a stage says of a log without a pose: :data:`WITHOUT_POSITION` where it has
        its attitude, else :data:`WITHOUT_POSE`; "" for a log with a pose."""
        if self.has_pose:
            return ""
        return WITHOUT_POSITION if self.has_attitude else WITHOUT_POSE

    @property
    def rotor_count(self) -> int:
        for value in (self.rotor_speed, self.rotor_command):
            if value is not None:
                return value.shape[1]
        return 0

    def to_trajectory(self) -> Trajectory:
        """The log as a :class:`~quadsim.vehicle.state.Trajectory`.

        Missing velocity is differentiated from position and missing body rate from the
        quaternions (central differences, ``numpy.gradient``); missing rotor speeds become
        an (N, 0) array. Commands (normalised) go to ``meta["command"]``, not to
        ``rotor_command`` (which is rad/s), together with ``vbat`` and ``accel``. An IMU-only
        log (no pose) has no trajectory: :class:`~quadsim.core.errors.InputError`."""
        if not self.has_pose:
            raise field_error(self.path or "log", "x..z, qw..qz", WITHOUT_POSE)
        if self.segments:                 # each stretch differentiated alone, then joined
            parts = [p.to_trajectory() for p in self.parts()]
            return Trajectory(self.t, self.position,
                              np.concatenate([p.velocity for p in parts]), self.quat,
                              np.concatenate([p.body_rate for p in parts]),
                              np.concatenate([p.rotor_speed for p in parts]), None,
                              engine="log", meta={**parts[0].meta, "command": self.rotor_command,
                                                  "vbat": self.vbat, "accel": self.accel,
                                                  "segments": self.segments})
        velocity = self.velocity
        if velocity is None:
            velocity = np.gradient(self.position, self.t, axis=0)
        body_rate = self.body_rate
        if body_rate is None:
            body_rate = body_rate_from_quat(self.t, self.quat)
        rotor_speed = self.rotor_speed
        if rotor_speed is None:
            rotor_speed = np.zeros((len(self.t), 0))
        meta = {"command": self.rotor_command, "vbat": self.vbat, "accel": self.accel,
                "path": self.path}
        return Trajectory(self.t, self.position, velocity, self.quat, body_rate, rotor_speed,
                          None, engine="log", meta=meta)


def body_rate_from_quat(t: np.ndarray, quat: np.ndarray) -> np.ndarray:
    """Body angular rate (N, 3) rad/s from quaternions (N, 4) by central differences:
    omega = 2 * vec(conj(q) * dq/dt)."""
    quat = np.asarray(quat, dtype=float).copy()
    # Remove sign flips (q and -q are the same attitude) before differentiating.
    flips = np.sign(np.sum(quat[1:] * quat[:-1], axis=-1))
    quat[1:] *= np.cumprod(np.where(flips == 0, 1.0, flips))[:, None]
    dq = np.gradient(quat, t, axis=0)
    return 2.0 * quat_multiply(quat_conjugate(quat), dq)[:, 1:]


# ----------------------------------------------------------------------------- reading


def _first_bad(mask: np.ndarray) -> tuple[int, int]:
    """(first index, length of the first run) of True values in a 1-D mask."""
    first = int(np.argmax(mask))
    rest = ~mask[first:]
    run = int(np.argmax(rest)) if rest.any() else len(rest)
    return first, run


def _numbered(path: Path, columns: dict, prefix: str) -> np.ndarray | None:
    numbers = sorted(int(m.group(2)) for c in columns if (m := _NUMBERED.match(c))
                     and m.group(1) == prefix)
    if not numbers:
        return None
    if numbers != list(range(1, len(numbers) + 1)):
        raise field_error(path, f"{prefix}_*", f"columns must be numbered 1..N without gaps, "
                          f"got {numbers}")
    return np.stack([columns[f"{prefix}_{i}"] for i in numbers], axis=1)


def _group(path: Path, columns: dict, names: tuple[str, ...]) -> np.ndarray | None:
    present = [n for n in names if n in columns]
    if not present:
        return None
    if len(present) != len(names):
        missing = [n for n in names if n not in columns]
        raise field_error(path, missing[0], f"missing while {', '.join(present)} present "
                          f"(the group {', '.join(names)} comes whole)")
    return np.stack([columns[n] for n in names], axis=1)


def _check_finite(path: Path, name: str, values: np.ndarray, *, required: bool,
                  notes: list[str]) -> None:
    """Non-finite values: an error in required columns, a warning (kept as NaN) otherwise."""
    bad = ~np.isfinite(values)
    if not bad.any():
        return
    first, run = _first_bad(bad)
    message = (f"line {first + 2}: non-finite value ({values[first]}), run of {run} sample(s); "
               f"{int(bad.sum())} in all")
    if required:
        raise field_error(path, name, message)
    values[bad] = np.nan
    notes.append(f"{path}: {name}: {message} (kept as NaN)")


def _check_time(path: Path, t: np.ndarray, notes: list[str]) -> None:
    steps = np.diff(t)
    if (steps <= 0).any():
        row = int(np.argmax(steps <= 0)) + 1
        raise field_error(path, "t", f"line {row + 2}: time {t[row]:g} s does not increase "
                          f"(previous {t[row - 1]:g} s); time must be strictly increasing")
    if len(steps) >= 2:
        typical = float(np.median(steps))
        if typical > MAX_TIME_STEP:
            unit = "milliseconds" if typical <= 1e3 * MAX_TIME_STEP else "microseconds"
            raise field_error(path, "t", f"median step {typical:.4g} s ({1 / typical:.2g} Hz), "
                              f"above {MAX_TIME_STEP:g} s: looks like {unit}; expected "
                              "seconds")
        jumps = np.flatnonzero(steps > GAP_FACTOR * typical)
        if len(jumps):
            row = int(jumps[0]) + 1
            notes.append(f"{path}: t: line {row + 2}: sample-rate jump, "
                         f"step {steps[row - 1]:.4g} s vs median {typical:.4g} s "
                         f"({len(jumps)} such gap(s))")


def _check_units(path: Path, log: dict) -> None:
    """Errors for values whose magnitude says the unit is wrong (RPM, deg/s, g, mV)."""
    norms = np.linalg.norm(log["quat"], axis=1) if log["quat"] is not None else np.ones(1)
    if (np.abs(norms - 1.0) > 0.01).any():
        row = int(np.argmax(np.abs(norms - 1.0) > 0.01))
        raise field_error(path, "qw..qz", f"line {row + 2}: quaternion norm {norms[row]:.4g}, "
                          "expected unit quaternions (scalar first)")
    limits = (("rotor_speed", "rotor_*", MAX_ROTOR_SPEED, "rad/s; looks like RPM"),
              ("body_rate", "wx..wz", MAX_BODY_RATE, "rad/s; looks like deg/s"))
    for key, column, limit, hint in limits:
        value = log.get(key)
        if value is not None and np.nanmax(np.abs(value), initial=0.0) > limit:  # NaN skipped
            row = int(np.nanargmax(np.nanmax(np.abs(value), axis=1)))
            raise field_error(path, column, f"line {row + 2}: {np.nanmax(np.abs(value[row])):.5g} "
                              f"exceeds {limit:g} {hint} (expected rad/s)")
    accel = log.get("accel")
    if accel is not None and np.isfinite(accel).any():
        typical = float(np.nanmedian(np.linalg.norm(accel, axis=1)))
        if 0.3 < typical < 3.0:
            raise field_error(path, "ax..az", f"median |specific force| {typical:.3g}: looks "
                              "like g; expected m/s^2 (about 9.81 at rest)")
    command = log.get("rotor_command")
    if command is not None and (np.nanmax(command, initial=0) > 1.05 or
                                np.nanmin(command, initial=0) < -0.05):
        row = int(np.nanargmax(np.nanmax(np.abs(command - 0.5), axis=1)))
        raise field_error(path, "cmd_*", f"line {row + 2}: command outside 0-1 "
                          f"({command[row].tolist()}); expected normalised commands")
    vbat = log.get("vbat")
    if vbat is not None and np.nanmax(vbat, initial=0) > 100.0:
        row = int(np.nanargmax(vbat))
        raise field_error(path, "vbat", f"line {row + 2}: {vbat[row]:g} V; looks like mV")


def load_log(path: str | Path, *, warn: bool = True, budget=None) -> FlightLog:
    """Read and validate a flight log (``.csv``, ``.csv.gz`` or ``.parquet``; also PX4 ULog,
    Crazyflie uSD and ArduPilot DataFlash files, converted by :mod:`quadsim.logs`); see the
    module docstring.

    Raises :class:`~quadsim.core.errors.InputError` (one line: file, column, line) for bad input.
    Suspicious but usable data (NaN runs in optional columns, sample-rate jumps, unknown
    columns) is described in ``FlightLog.notes`` and, with ``warn=True``, also warned as
    :class:`~quadsim.core.errors.QuadsimWarning` (the real Crazyflie logs have motion-capture
    dropouts, so callers that know this pass ``warn=False`` and read ``notes``). ``budget``:
    the time and memory budget of parsing a foreign format (default
    :func:`quadsim.logs.parse_budget`)."""
    path = Path(path)
    from . import detect_format, file_kind, read_columns  # PX4 ULog, Crazyflie uSD, DataFlash
    fmt = detect_format(path)
    if fmt is None and file_kind(path) == "a TOML file":
        raise field_error(path, "header", "a TOML file (a parameter set or skeleton?), not a "
                          "flight log: were the log and the vehicle arguments swapped?")
    columns = read_columns(path, fmt=fmt, budget=budget) if fmt else read_log_columns(path)
    return log_from_columns(path, columns, warn=warn)


def _minimum(path: Path, columns: dict) -> dict:
    """The columns with Euler angles read as the quaternion, after checking the schema's
    minimum: ``t`` and either a pose (``x..z`` with an attitude) or the IMU (``ax..az``,
    ``wx..wz`` and ``rotor_*`` or ``cmd_*``). Raises naming what each minimum lacks. An IMU
    log's velocity without a position is left out; its attitude is kept (IMU, motors and
    attitude). A ``pitch`` beyond +-(pi/2 + :data:`PITCH_SLACK`) rad is refused: a z-y-x
    pitch never lies there, and a log written in degrees does once it pitches by more than
    1.6 degrees."""
    if "t" not in columns:
        raise field_error(path, "t", "required column missing (time in s)")
    euler = [c for c in EULER if c in columns]
    if euler and not any(c in columns for c in _GROUPS["quat"]):
        if len(euler) != 3:
            missing = [c for c in EULER if c not in columns]
            raise field_error(path, missing[0], f"missing while {', '.join(euler)} present: an "
                              "attitude needs roll, pitch and yaw (rad, z-y-x) or qw..qz")
        from .attitude import quat_from_euler
        pitch = np.asarray(columns["pitch"], float)
        worst = float(np.nanmax(np.abs(pitch))) if np.any(np.isfinite(pitch)) else 0.0
        if worst > np.pi / 2 + PITCH_SLACK:
            raise field_error(path, "pitch", f"|pitch| up to {worst:.4g}, beyond pi/2 rad: the "
                              "z-y-x pitch lies within +-90 degrees; in degrees? roll, pitch "
                              "and yaw are rad")
        columns = dict(columns)
        quat = quat_from_euler(*(columns.pop(c) for c in EULER))
        columns.update({c: quat[:, i] for i, c in enumerate(_GROUPS["quat"])})
    has = {g: all(c in columns for c in _GROUPS[g]) for g in _GROUPS}
    motors = any(_NUMBERED.match(c) for c in columns)
    if has["position"] and has["quat"]:
        return columns
    if any(c in columns for c in _GROUPS["position"]) and not has["quat"]:
        name = next(c for c in _GROUPS["quat"] if c not in columns)
        raise field_error(path, name, "required with a position: an attitude (qw..qz, or roll, "
                          "pitch, yaw in rad); an IMU log may have neither")
    if has["accel"] and has["body_rate"] and motors:
        # IMU and motors, with the attitude where logged (FlightLog.has_attitude); a velocity
        # without a position is left out (the diagnosis' pose-free path reads none)
        if has["velocity"]:
            columns = {k: v for k, v in columns.items() if k not in _GROUPS["velocity"]}
        if not has["quat"]:
            columns = {k: v for k, v in columns.items() if k not in _GROUPS["quat"]}
        return columns
    lacking = [n for n, ok in (("ax..az", has["accel"]), ("wx..wz", has["body_rate"]),
                               ("rotor_* or cmd_*", motors)) if not ok]
    raise field_error(path, lacking[0], "required: a log needs either the IMU (t, ax..az, "
                      "wx..wz and rotor speeds or motor commands; missing "
                      f"{', '.join(lacking)}) or a pose (t, x..z and qw..qz or roll, pitch, "
                      "yaw)")


def log_from_columns(path: str | Path, columns: dict[str, np.ndarray], *,
                     warn: bool = True) -> FlightLog:
    """Validate schema columns (name -> float array) read from ``path`` into a FlightLog
    (the checks of :func:`load_log`; used by the importers in :mod:`quadsim.logs`)."""
    path = Path(path)
    notes: list[str] = []
    source, columns = columns, _minimum(path, columns)
    pose = tuple(c for g in ("position", "quat") for c in _GROUPS[g])
    known = set(_REQUIRED) | {c for g in _GROUPS.values() for c in g} | {"vbat"}
    unknown = sorted(c for c in columns if c not in known and not _NUMBERED.match(c))
    if unknown:
        notes.append(f"{path}: ignoring unknown column(s) {', '.join(unknown)}")
    for name, values in columns.items():
        if name in known or _NUMBERED.match(name):
            _check_finite(path, name, values, required=name in _REQUIRED + pose,
                          notes=notes)
    t = columns["t"]
    _check_time(path, t, notes)
    log = {key: _group(path, columns, names) for key, names in _GROUPS.items()}
    log["rotor_speed"] = _numbered(path, columns, "rotor")
    log["rotor_command"] = _numbered(path, columns, "cmd")
    if (log["rotor_speed"] is not None and log["rotor_command"] is not None
            and log["rotor_speed"].shape[1] != log["rotor_command"].shape[1]):
        raise field_error(path, "cmd_*", f"{log['rotor_command'].shape[1]} command columns but "
                          f"{log['rotor_speed'].shape[1]} rotor columns")
    log["vbat"] = columns.get("vbat")
    _check_units(path, log)
    check_plausible(path, t, log)
    notes = [*getattr(source, "notes", ()), *notes]
    if warn:
        for note in notes:
            warnings.warn(note, QuadsimWarning, stacklevel=2)
    vehicle = getattr(source, "vehicle", {}).get("kind")
    return FlightLog(t=t, path=path, notes=tuple(notes), vehicle=vehicle,
                     rates_hz=_rates(t, log, getattr(source, "rates", {})), **log)


def _rates(t: np.ndarray, log: dict, known: dict) -> tuple[tuple[str, float], ...]:
    """:attr:`FlightLog.rates_hz`: the importer's rate of each channel (``known``) where it
    gives one, else the one read from the data (:func:`quadsim.logs.rates.native_rate`)."""

    present = {k: log.get(k) for k in ARRAYS if log.get(k) is not None}
    read = dict(rates_of(t, {k: v for k, v in present.items() if known.get(k) is None}))
    return tuple((k, float(known[k]) if known.get(k) is not None else read[k])
                 for k in present if known.get(k) is not None or k in read)


# ----------------------------------------------------------------------------- writing


def _columns_of(log: FlightLog) -> tuple[list[str], list[np.ndarray]]:
    names, blocks = ["t"], [np.asarray(log.t, dtype=float)[:, None]]
    for key, group in _GROUPS.items():
        value = getattr(log, key)
        if value is not None:
            names += list(group)
            blocks.append(np.asarray(value, dtype=float))
    for key, prefix in (("rotor_speed", "rotor"), ("rotor_command", "cmd")):
        value = getattr(log, key)
        if value is not None:
            names += [f"{prefix}_{i + 1}" for i in range(value.shape[1])]
            blocks.append(np.asarray(value, dtype=float))
    if log.vbat is not None:
        names.append("vbat")
        blocks.append(np.asarray(log.vbat, dtype=float)[:, None])
    return names, blocks


def log_bytes(log: FlightLog, *, gzipped: bool) -> bytes:
    """The file contents :func:`write_log` writes (deterministic)."""
    names, blocks = _columns_of(log)
    buffer = io.StringIO()
    buffer.write(",".join(names) + "\n")
    formats = [time_format(log.t)] + [FLOAT_FORMAT] * (len(names) - 1)
    np.savetxt(buffer, np.hstack(blocks), fmt=formats, delimiter=",", newline="\n")
    data = buffer.getvalue().replace("nan", "").encode("ascii")
    if not gzipped:
        return data
    out = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", fileobj=out, mtime=0, compresslevel=6) as gz:
        gz.write(data)
    return out.getvalue()


def time_format(t: np.ndarray) -> str:
    """``FLOAT_FORMAT`` when it keeps every time step to 1e-6 of the smallest step, else
    ``%.17g`` (full double precision): absolute times such as 1.7e9 s are not rounded to
    whole seconds."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2:
        return FLOAT_FORMAT
    written = np.array([float(FLOAT_FORMAT % v) for v in t])
    tolerance = 1e-6 * float(np.min(np.abs(np.diff(t))))
    return FLOAT_FORMAT if np.all(np.abs(written - t) <= tolerance) else "%.17g"


def parquet_bytes(log: FlightLog) -> bytes:
    """The log as a Parquet file (float64 columns, schema order; needs pyarrow)."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise InputError("writing Parquet needs pyarrow (pip install -e '.[parquet]')"
                         ) from None
    names, blocks = _columns_of(log)
    data = np.hstack(blocks)
    table = pa.table({name: data[:, i] for i, name in enumerate(names)})
    out = io.BytesIO()
    pq.write_table(table, out, compression="zstd")
    return out.getvalue()


#: File names a log can be written to.
LOG_SUFFIXES = (".csv", ".csv.gz", ".parquet")


def log_file_bytes(path: str | Path, log: FlightLog) -> bytes:
    """The bytes :func:`write_log` writes to ``path``: CSV, gzipped CSV or Parquet by name."""
    path = Path(path)
    if not path.name.endswith(LOG_SUFFIXES):
        raise InputError(f"{path}: a flight log must end in {', '.join(LOG_SUFFIXES)}")
    if path.suffix == ".parquet":
        return parquet_bytes(log)
    return log_bytes(log, gzipped=path.suffix == ".gz")


def write_log(path: str | Path, log: FlightLog) -> Path:
    """Write ``log`` atomically as CSV (gzipped when the name ends in ``.gz``) or Parquet
    (``.parquet``). Columns in schema order; only the signals the log has. Same log -> same
    bytes."""
    return atomic_write_bytes(path, log_file_bytes(path, log))
