"""Crazyflie uSD-card logs (the firmware's event-based binary format, versions 1 and 2).

Layout (little-endian; as written by the Crazyflie firmware's uSD deck driver and read by
its ``tools/usdlog/cfusdlog.py``), checked against the real files in
``crazyflie21_brushless/usd_raw/``::

    u8  0xBC                     magic
    u16 version                  1 or 2
    u16 number of event types
    per event type:
        u16 id                   (0xFFFF = the fixed-frequency logging event)
        char[] name, NUL         e.g. "fixedFrequency", "estPose"
        u16 number of variables
        per variable: char[] "group.name(t)", NUL   t = struct code: f, H, h, I, i, B, b, ...
    events until the last 4 bytes:
        u16 id, timestamp (v1: u32 ms; v2: u64 us), values packed as the definition says
    u32 CRC32 (zlib) of everything before it

Signals and units (converted here, at the boundary):

===========================  ==========  ====================  =============================
uSD variable                 unit        column                conversion
===========================  ==========  ====================  =============================
stateEstimate.x/y/z          m           x, y, z               --
stateEstimate.vx/vy/vz       m/s         vx, vy, vz            --
stateEstimate.qw/qx/qy/qz    --          qw, qx, qy, qz        --
gyro.x/y/z                   deg/s       wx, wy, wz            x pi/180
acc.x/y/z                    g           ax, ay, az            x 9.81 m/s^2 (the firmware's
                                                               GRAVITY_MAGNITUDE)
rpm.m1..m4                   RPM         rotor_1..4            x 2 pi/60
pwm.m1_pwm..m4_pwm           0-65535     cmd_1..4              / 65535
motor.m1..m4 (no pwm.*)      0-65535     cmd_1..4              / 65535
stateEstimate.roll/pitch/yaw deg         qw..qz (no quat)      Euler, ``euler`` convention
pm.vbatMV                    mV          vbat                  / 1000
===========================  ==========  ====================  =============================

The Crazyflie's world is z up and its body x forward, y left, z up: no frame change. The
flight-log rows are the fixed-frequency events (one row each, time from the first); a
motion-capture pose event (``estPose``, ``locSrv.*``, ~100 Hz) replaces the on-board state
estimate as position and attitude with ``pose="estPose"`` (``convert --topic pose=estPose``):
interpolated linearly onto the rows, NaN across its gaps (no hold), rows outside its span
dropped; by default the state estimate is used, as in the published CSVs. Measured: the three raw
logs reproduce ``nominal/flight_00..02.csv.gz`` row for row (docs/logs.md gives the differences).

No pose (no ``stateEstimate.x/y/z`` and attitude, no ``pose`` event): an IMU + motors log
(``acc``, ``gyro``, motor commands), as the system-identification logs of
``crazyflie21_imu_cmd/`` are; a partial attitude (roll and yaw only) is left out with a note.

Errors (one line, file and field): wrong magic byte, unknown version, bad CRC, a truncated
event or definition, an event id without a definition, an unknown type code.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from ..core.errors import field_error
from .common import (
    RPM_TO_RAD_S,
    Columns,
    check_unit_quat,
    map_rotors,
    median_rate,
    resample,
    resample_quat,
)

MAGIC = 0xBC
#: m/s^2 per g: the Crazyflie firmware's GRAVITY_MAGNITUDE (the nominal CSVs use it too).
CF_GRAVITY = 9.81
_TIMESTAMP = {1: (struct.Struct("<HI"), 1e-3), 2: (struct.Struct("<HQ"), 1e-6)}
_TYPES = set("bBhHiIqQfd")
#: |correlation| of the pitch angle's rate with the gyro's y rate that tells its sign (the
#: two measure the same turn: a right convention correlates near +1, the wrong sign near -1;
#: below this the flight pitches too little to tell, and the default is kept).
PITCH_SIGN_CORR = 0.5
#: a pitch reconstructed from the velocity (roll and yaw logged, no pitch) is used when the
#: roll the same construction implies matches the logged roll within this rms (deg): the
#: thrust-along-body-z premise holds on that axis.
RECONSTRUCT_ROLL_DEG = 5.0


def _definitions(path: Path, data: bytes) -> tuple[int, dict, int]:
    def need(idx: int, size: int, what: str) -> None:
        if idx + size > len(data) - 4:
            raise field_error(path, what, "truncated event definitions")

    need(0, 5, "header")
    version, count = struct.unpack_from("<HH", data, 1)
    if version not in _TIMESTAMP:
        raise field_error(path, "version", f"uSD log version {version}; only 1 and 2 are known")
    idx, defs = 5, {}
    for _ in range(count):
        need(idx, 2, "event definition")
        (event_id,) = struct.unpack_from("<H", data, idx)
        end = data.find(b"\0", idx + 2)
        if end < 0:
            raise field_error(path, "event definition", "truncated event name")
        name = data[idx + 2:end].decode("ascii", "replace")
        idx = end + 1
        need(idx, 2, name)
        (nvars,) = struct.unpack_from("<H", data, idx)
        idx += 2
        variables, codes = [], ""
        for _ in range(nvars):
            end = data.find(b"\0", idx)
            if end < 0:
                raise field_error(path, name, "truncated variable definition")
            text = data[idx:end].decode("ascii", "replace")
            idx = end + 1
            if not (text.endswith(")") and "(" in text) or text[-2] not in _TYPES:
                raise field_error(path, name, f"variable {text!r}: expected name(type) with a "
                                  f"type code in {''.join(sorted(_TYPES))}")
            variables.append(text[:text.rindex("(")])
            codes += text[-2]
        defs[event_id] = (name, variables, struct.Struct("<" + codes))
    return version, defs, idx


def read_usd(path: str | Path) -> tuple[dict[str, dict[str, np.ndarray]], int]:
    """Every event of a uSD log: ``{event name: {"t": s, variable: values}}`` in the units
    of the file (no conversion), and the format version. CRC checked."""
    path = Path(path)
    data = path.read_bytes()
    if len(data) < 9 or data[0] != MAGIC:
        raise field_error(path, "header", f"not a Crazyflie uSD log (first byte "
                          f"{data[:1].hex() or 'missing'}, expected bc)")
    (crc,) = struct.unpack_from("<I", data, len(data) - 4)
    if zlib.crc32(data[:-4]) != crc:
        raise field_error(path, "crc32", f"checksum {zlib.crc32(data[:-4]):08x} does not "
                          f"match the stored {crc:08x}: the file is corrupt or truncated")
    version, defs, idx = _definitions(path, data)
    head, tick = _TIMESTAMP[version]
    rows: dict[int, list] = {k: [] for k in defs}
    times: dict[int, list] = {k: [] for k in defs}
    end = len(data) - 4
    while idx < end:
        if idx + head.size > end:
            raise field_error(path, "event", f"truncated event header at byte {idx}")
        event_id, stamp = head.unpack_from(data, idx)
        idx += head.size
        if event_id not in defs:
            raise field_error(path, "event", f"id {event_id} at byte {idx - head.size} has no "
                              "definition")
        body = defs[event_id][2]
        if idx + body.size > end:
            raise field_error(path, defs[event_id][0], f"truncated event at byte "
                              f"{idx - head.size}")
        rows[event_id].append(body.unpack_from(data, idx))
        times[event_id].append(stamp)
        idx += body.size
    events = {}
    for event_id, (name, variables, _) in defs.items():
        values = np.array(rows[event_id], dtype=float).reshape(-1, len(variables))
        events[name] = {"t": np.array(times[event_id], dtype=float) * tick}
        events[name].update({v: values[:, i] for i, v in enumerate(variables)})
    return events, version


def _pose_from(path: Path, events: dict, pose: str, t: np.ndarray):
    """Position (N, 3) and quaternion (N, 4) of a motion-capture pose event (``locSrv.*``)
    interpolated onto ``t`` (NaN outside the pose event's span and across its gaps)."""
    if pose not in events:
        raise field_error(path, pose, f"pose event not in the log (events: {', '.join(events)})")
    ev = events[pose]
    names = [f"locSrv.{a}" for a in ("x", "y", "z", "qw", "qx", "qy", "qz")]
    missing = [n for n in names if n not in ev]
    if missing or len(ev["t"]) < 2:
        raise field_error(path, f"{pose}: {missing[0] if missing else 't'}",
                          "pose event needs locSrv.x/y/z/qw/qx/qy/qz and 2 or more samples")
    position = resample(ev["t"], np.stack([ev[n] for n in names[:3]], 1), t)
    check_unit_quat(path, f"{pose}: locSrv.qw..qz", ev["t"],
                    np.stack([ev[n] for n in names[3:]], 1))
    quat = resample_quat(ev["t"], np.stack([ev[n] for n in names[3:]], 1), t)
    return position, quat


def usd_columns(path: str | Path, *, rotor_map: tuple[int, ...] | None = None,
                event: str | None = None, pose: str | None = None,
                euler: str | None = None) -> Columns:
    """Flight-log columns (SI, schema names) from a uSD log: one row per fixed-frequency
    event (or per ``event`` when given), time from its first row. ``pose`` (e.g.
    ``"estPose"``): take position and attitude from that motion-capture event instead of
    ``stateEstimate`` (linearly interpolated onto the rows; rows outside its span dropped).
    Without quaternions, ``stateEstimate.roll/pitch/yaw`` (deg) are the attitude in the
    ``euler`` convention (:mod:`.attitude`, default ``crazyflie``). Without a pose the log is
    IMU + motors (``acc``, ``gyro``, ``motor.m*`` or ``pwm.m*_pwm``), with the attitude where
    ``stateEstimate`` logs one without ``x/y/z``; the notes say what was left out or kept and
    why."""
    path = Path(path)
    events, _ = read_usd(path)
    name = event or next((n for n in events if n == "fixedFrequency"), None)
    if name is None or name not in events:
        raise field_error(path, event or "fixedFrequency", "event not in the log (events: "
                          f"{', '.join(events)})")
    ev = events[name]
    if len(ev["t"]) == 0:
        raise field_error(path, name, "no events recorded")
    t = ev["t"]
    cols = {"t": t - t[0]}

    def take(names, scale=1.0):
        if all(n in ev for n in names):
            return np.stack([ev[n] for n in names], axis=1) * scale
        return None

    state = "stateEstimate."
    position = take([state + a for a in "xyz"])
    quat = take([state + a for a in ("qw", "qx", "qy", "qz")])
    notes: list[str] = []
    if quat is None:
        quat = _euler_attitude(path, ev, name, euler, notes)
    if pose is not None:
        position, quat = _pose_from(path, events, pose, t)
    if position is not None and quat is None:
        position = None
        notes.append(f"{path}: {name}: {state}x/y/z logged without a whole attitude: position "
                     "left out (without the tilt it cannot enter the body-frame balance)")
    if quat is not None and position is None:
        notes.append(f"{path}: {name}: attitude logged without {state}x/y/z: kept (IMU, "
                     "motors and attitude: the diagnosis weighs what reads only the attitude)")
    if position is None and not all(f"{g}.{a}" in ev for g in ("acc", "gyro") for a in "xyz"):
        raise field_error(path, f"{name}: {state}x/y/z", "not logged, and no acc.x/y/z and "
                          "gyro.x/y/z either: a log needs a pose or the IMU (with motor "
                          "commands or rotor speeds)")
    groups = {
        "x y z": position, "vx vy vz": take([state + a for a in ("vx", "vy", "vz")]),
        "qw qx qy qz": quat,
        "wx wy wz": take(["gyro.x", "gyro.y", "gyro.z"], np.pi / 180.0),
        "ax ay az": take(["acc.x", "acc.y", "acc.z"], CF_GRAVITY),
    }
    for names, value in groups.items():
        if value is not None:
            cols.update({n: value[:, i] for i, n in enumerate(names.split())})
    motors = sorted(int(k[5:]) for k in ev if k.startswith("rpm.m") and k[5:].isdigit())
    commands = _commands(ev)
    rotor = take([f"rpm.m{m}" for m in motors], RPM_TO_RAD_S) if motors else None
    cmd = take(commands[1], 1.0 / 65535.0) if commands else None
    for prefix, value in (("rotor", map_rotors(path, "rpm.m*", rotor, rotor_map)),
                          ("cmd", map_rotors(path, commands[0] if commands else "pwm.m*",
                                             cmd, rotor_map))):
        if value is not None:
            cols.update({f"{prefix}_{i + 1}": value[:, i] for i in range(value.shape[1])})
    if "pm.vbatMV" in ev:
        cols["vbat"] = ev["pm.vbatMV"] / 1000.0
    # every channel at its event's rate (the pose's: the motion-capture event's)
    rate = median_rate(t)
    rates = {k: rate for k in ("position", "velocity", "quat", "body_rate", "accel",
                               "rotor_speed", "rotor_command", "vbat") if rate is not None}
    if pose is not None and median_rate(events[pose]["t"]) is not None:
        rates.update(position=median_rate(events[pose]["t"]), quat=median_rate(events[pose]["t"]))
    if pose is not None:
        ok = np.isfinite(position).all(axis=1) & np.isfinite(quat).all(axis=1)
        if ok.sum() < 2:
            raise field_error(path, pose, "pose event and fixed-frequency rows never overlap")
        cols = {k: v[ok] for k, v in cols.items()}
        cols["t"] = cols["t"] - cols["t"][0]
    return Columns(cols, notes=tuple(notes), rates=rates)


def _commands(ev: dict) -> tuple[str, list[str]] | None:
    """(field pattern, variable names) of the motor commands (0-65535): ``pwm.m1_pwm..`` (the
    PWM sent), else ``motor.m1..`` (the power distribution's output, as logged by the
    system-identification logs); None when neither is logged."""
    pwm = sorted(int(k[5:-4]) for k in ev if k.startswith("pwm.m") and k.endswith("_pwm")
                 and k[5:-4].isdigit())
    if pwm:
        return "pwm.m*_pwm", [f"pwm.m{m}_pwm" for m in pwm]
    motor = sorted(int(k[7:]) for k in ev if k.startswith("motor.m") and k[7:].isdigit())
    if motor:
        return "motor.m*", [f"motor.m{m}" for m in motor]
    return None


def _euler_attitude(path: Path, ev: dict, name: str, convention: str | None,
                    notes: list[str]) -> np.ndarray | None:
    """The attitude (N, 4) from ``stateEstimate.roll/pitch/yaw`` (degrees) in ``convention``
    (:mod:`.attitude`). Without ``convention`` the pitch sign is taken from the gyro (the
    correlation of the pitch rate with ``gyro.y``, :data:`PITCH_SIGN_CORR`), else the default
    ``crazyflie`` (the firmware logs pitch nose-up positive); a given convention the gyro
    contradicts is refused. Roll and yaw without pitch, with ``stateEstimate.vx/vy/vz``: the
    pitch reconstructed from the velocity (:func:`.attitude.pitch_from_velocity`) when the
    roll it implies matches the logged roll within :data:`RECONSTRUCT_ROLL_DEG`. Otherwise
    only some of the three logged: None, with a note of what that costs."""
    from .attitude import pitch_from_velocity, pitch_sign_from_gyro, quat_from_euler

    state = "stateEstimate."
    logged = [a for a in ("roll", "pitch", "yaw") if state + a in ev]
    if not logged:
        return None
    velocity = [state + a for a in ("vx", "vy", "vz")]
    if logged == ["roll", "yaw"] and all(v in ev for v in velocity) and len(ev["t"]) > 20:
        roll, yaw = np.radians(ev[state + "roll"]), np.radians(ev[state + "yaw"])
        pitch, check = pitch_from_velocity(ev["t"], roll, yaw,
                                           np.stack([ev[v] for v in velocity], 1))
        if check <= np.radians(RECONSTRUCT_ROLL_DEG):
            notes.append(f"{path}: {name}: {state}pitch: not logged: reconstructed from the "
                         f"velocity's derivative, roll and yaw (thrust along body z; the roll "
                         f"it implies differs from the logged roll by {np.degrees(check):.2g} "
                         "deg rms). What it costs: the tilt is biased by drag / weight and lags "
                         "by the velocity estimate's smoothing; log stateEstimate.pitch or "
                         "qw..qz to avoid it")
            return quat_from_euler(roll, pitch, yaw, convention="flu")
        notes.append(f"{path}: {name}: {state}pitch: not reconstructed from the velocity: the "
                     f"roll it implies differs from the logged roll by {np.degrees(check):.2g} "
                     f"deg rms (over {RECONSTRUCT_ROLL_DEG:g} deg)")
    if len(logged) < 3:
        lacking = [a for a in ("roll", "pitch", "yaw") if a not in logged]
        notes.append(f"{path}: {name}: {state}{'/'.join(lacking)}: not logged ({', '.join(logged)} "
                     "only): no whole attitude, so the log is read as IMU and motors only where "
                     "it has them; a partial attitude cannot rotate the pose into the body frame "
                     f"(log {state}{'/'.join(lacking)} or {state}qw..qz to keep it)")
        return None
    angles = [np.radians(ev[state + a]) for a in ("roll", "pitch", "yaw")]
    told = "given"
    if "gyro.y" in ev:
        corr = pitch_sign_from_gyro(ev["t"], angles[0], angles[1], np.radians(ev["gyro.y"]))
        found = "flu" if corr > PITCH_SIGN_CORR else "crazyflie" if corr < -PITCH_SIGN_CORR \
            else None
        if convention is None:
            convention, told = found or "crazyflie", ("from the gyro" if found else
                                                      "the default: the flight barely pitches")
        elif found is not None and (convention == "crazyflie") != (found == "crazyflie"):
            raise field_error(path, f"{name}: {state}pitch", f"--euler {convention}: the "
                              f"pitch angle's rate correlates {corr:+.2f} with the gyro's y rate "
                              f"under that convention's sign: the log says --euler {found}")
    convention = convention or "crazyflie"
    notes.append(f"{path}: {name}: attitude from {state}roll/pitch/yaw (deg), Euler convention "
                 f"{convention!r} ({told}; z-y-x; convert --euler names it)")
    return quat_from_euler(*angles, convention=convention)


def encode_usd(events: dict[str, tuple[int, list[tuple[str, str]], list[tuple[int, tuple]]]],
               *, version: int = 2) -> bytes:
    """A uSD log from ``{name: (id, [(variable, type code)], [(timestamp ticks, values)])}``
    (ticks: ms for version 1, us for version 2); events written in timestamp order. The
    writer of the test fixtures; the inverse of :func:`read_usd`."""
    head, _ = _TIMESTAMP[version]
    out = bytearray(struct.pack("<BHH", MAGIC, version, len(events)))
    stream = []
    for name, (event_id, variables, samples) in events.items():
        out += struct.pack("<H", event_id) + name.encode() + b"\0"
        out += struct.pack("<H", len(variables))
        for var, code in variables:
            out += f"{var}({code})".encode() + b"\0"
        body = struct.Struct("<" + "".join(c for _, c in variables))
        stream += [(stamp, head.pack(event_id, stamp) + body.pack(*values))
                   for stamp, values in samples]
    for _, chunk in sorted(stream, key=lambda s: s[0]):
        out += chunk
    return bytes(out + struct.pack("<I", zlib.crc32(bytes(out))))


def is_usd(head: bytes) -> bool:
    return len(head) >= 5 and head[0] == MAGIC and head[1:3] in (b"\x01\x00", b"\x02\x00")


__all__ = ["CF_GRAVITY", "encode_usd", "is_usd", "read_usd", "usd_columns"]
