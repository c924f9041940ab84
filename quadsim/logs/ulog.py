"""PX4 ULog files through ``pyulog`` (optional: ``pip install -e '.[logs]'``).

Topics read (first instance, ``multi_id`` 0; ``--topic NAME=TOPIC`` overrides the topic of a
signal, ``--field NAME=FIELD`` the field prefix):

==============  ================================  ===================  =====================
signal          topic (fallback)                  fields               unit in the log
==============  ================================  ===================  =====================
position        vehicle_local_position            x y z                m, NED
velocity        vehicle_local_position            vx vy vz             m/s, NED
quat            vehicle_attitude                  q[0..3]              wxyz, FRD -> NED
body_rate       sensor_combined                   gyro_rad[0..2]       rad/s, FRD
                (vehicle_angular_velocity)        (xyz[0..2])
accel           sensor_combined                   accelerometer_m_s2   m/s^2, FRD
                (vehicle_acceleration)            (xyz[0..2])
rotor_speed     esc_status                        esc[i].esc_rpm       RPM
rotor_command   actuator_motors                   control[i]           0-1
                (actuator_outputs)                (output[i])          us, 1000-2000 (PWM)
vbat            battery_status                    voltage_v            V
==============  ================================  ===================  =====================

Frames: NED/FRD -> world (x north, y west, z up) and body FLU by the half turn about x
(``quadsim.logs.common``). Time: ``timestamp`` (us since boot) -> s from the first row.
Every topic is interpolated onto the attitude topic's instants (``common.resample``: linear,
NaN across gaps); the rows kept are those where position and attitude both exist, trimmed to
the span every topic covers (``common.common_span``; time restarts at 0 there). A log with
no position or attitude topic is read as IMU + motors on the gyro topic's instants (a note
says so), with the attitude interpolated onto them where it is logged without a position
(rows where it is not known are dropped).

The rotor count is the number of ``actuator_motors`` controls that are not NaN in the log
(PX4 sets unused ones to NaN), else ``CA_ROTOR_COUNT``, else 4; ESC rotor speeds are taken
for that many ESCs. ``actuator_outputs`` values (PWM us) are normalised with ``pwm_range``
(default 1000-2000 us, PX4's PWM_MAIN_MIN/MAX defaults; ``common.pwm_to_unit``: values
down to 10 % of the span below the minimum are disarmed outputs such as 900 us and become 0).
Commands outside -0.05..1.05 after that are an error ("commands in an unknown range").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import InputError, field_error
from .common import (
    LOSS_NOTE,
    RPM_TO_RAD_S,
    Columns,
    check_parameter,
    check_unit_quat,
    columns_from_signals,
    common_span,
    frd_to_body,
    increasing,
    map_rotors,
    median_rate,
    ned_to_world,
    pwm_to_unit,
    quat_ned_frd_to_world_body,
    resample,
    resample_quat,
)

MAGIC = b"ULog\x01\x12\x35"
#: most rows a uniform ``rate_hz`` time base may have (8 float columns x 1e7 rows ~ 2 GB).
MAX_ROWS = 10_000_000
#: signal -> candidate (topic, field prefix, count) in order of preference.
TOPICS = {
    "position": [("vehicle_local_position", "", ("x", "y", "z"))],
    "velocity": [("vehicle_local_position", "", ("vx", "vy", "vz"))],
    "quat": [("vehicle_attitude", "q", 4)],
    "body_rate": [("sensor_combined", "gyro_rad", 3), ("vehicle_angular_velocity", "xyz", 3)],
    "accel": [("sensor_combined", "accelerometer_m_s2", 3), ("vehicle_acceleration", "xyz", 3)],
    "rotor_speed": [("esc_status", "esc_rpm", None)],
    "rotor_command": [("actuator_motors", "control", None), ("actuator_outputs", "output", None)],
    "vbat": [("battery_status", "voltage_v", 0)],
}


def _open(path: Path):
    try:
        from pyulog import ULog
    except ImportError:
        raise InputError(f"{path}: reading ULog needs pyulog (pip install -e '.[logs]')"
                         ) from None
    try:
        return ULog(str(path))
    except Exception as exc:  # noqa: BLE001 (pyulog raises plain exceptions on corrupt files)
        raise InputError(f"{path}: not a readable ULog file: {' '.join(str(exc).split())}"
                         ) from None


def _fields(data: dict, prefix: str, spec) -> list[str] | None:
    if isinstance(spec, tuple):
        names = [f"{prefix}{n}" for n in spec]
    elif spec == 0:
        names = [prefix]
    elif isinstance(spec, int):
        names = [f"{prefix}[{i}]" for i in range(spec)]
    else:  # variable count: every prefix[i] (esc[i].esc_rpm for esc_status)
        names = [k for k in data if k.startswith(prefix + "[") and k.endswith("]")]
        names += [k for k in data if k.startswith("esc[") and k.endswith("." + prefix)]
    return names if names and all(n in data for n in names) else None


def _signal(ulog, key: str, topic_over: str | None, field_over: str | None):
    """(t s, values (N, k), topic name) of one signal, or None when absent."""
    candidates = TOPICS[key]
    if topic_over:
        candidates = [(topic_over, field_over if field_over is not None else c[1], c[2])
                      for c in candidates[:1]]
    elif field_over is not None:
        candidates = [(c[0], field_over, c[2]) for c in candidates]
    for topic, prefix, spec in candidates:
        sets = [d for d in ulog.data_list if d.name == topic]
        if not sets:
            continue
        data = min(sets, key=lambda d: d.multi_id).data
        names = _fields(data, prefix, spec)
        if names is None or "timestamp" not in data:
            continue
        values = np.stack([np.asarray(data[n], dtype=float) for n in names], axis=1)
        return np.asarray(data["timestamp"], dtype=float) * 1e-6, values, topic
    return None


#: PX4 MAV_TYPE values of multirotors -> rotor count (None: from the outputs).
_MULTIROTOR = {2: 4, 3: 2, 13: 6, 14: 8, 15: 3}
_VEHICLE = {1: "fixed wing", 4: "helicopter", 19: "VTOL", 20: "VTOL", 21: "VTOL",
            22: "VTOL", 23: "VTOL", 24: "VTOL", 25: "VTOL", 10: "ground rover", 12: "submarine"}


def _vehicle(path: Path, ulog) -> dict:
    """What the log's parameters say about the vehicle (MAV_TYPE, CA_ROTOR_COUNT)."""
    params = ulog.initial_parameters
    info: dict = {"source": "PX4 MAV_TYPE"}
    if "MAV_TYPE" in params:
        kind = int(check_parameter(path, "MAV_TYPE", params["MAV_TYPE"], low=0, high=255,
                                   integer=True))
        info["mav_type"] = kind
        info["kind"] = ("multirotor" if kind in _MULTIROTOR else
                        _VEHICLE.get(kind, f"MAV_TYPE {kind}"))
    if "CA_ROTOR_COUNT" in params:
        info["rotors"] = int(check_parameter(path, "CA_ROTOR_COUNT", params["CA_ROTOR_COUNT"],
                                             low=1, high=16, integer=True))
    return info


def ulog_columns(path: str | Path, *, rotor_map: tuple[int, ...] | None = None,
                 topics: dict[str, str] | None = None, fields: dict[str, str] | None = None,
                 pwm_range: tuple[float, float] = (1000.0, 2000.0),
                 rate_hz: float | None = None) -> dict[str, np.ndarray]:
    """Flight-log columns (SI, schema names, our frames) from a ULog file. ``rate_hz``: a
    uniform time base at that rate over the attitude topic's span instead of its instants
    (PX4 often logs vehicle_attitude at 20-50 Hz and sensor_combined at 250 Hz or more)."""
    path = Path(path)
    topics, fields = topics or {}, fields or {}
    ulog = _open(path)
    notes: list[str] = []
    if ulog.file_corruption:
        notes.append(f"{path}: pyulog found corrupt data and skipped it (file_corruption)")
    vehicle = _vehicle(path, ulog)
    sig = {k: _signal(ulog, k, topics.get(k), fields.get(k)) for k in TOPICS}
    pose = sig["position"] is not None and sig["quat"] is not None
    if not pose:
        lacking = [w for k, w in (("position", "vehicle_local_position x/y/z"),
                                  ("quat", "vehicle_attitude q[0..3]")) if sig[k] is None]
        if sig["body_rate"] is None or sig["accel"] is None:
            raise field_error(path, topics.get("position", lacking[0]), "not in the log, and "
                              "no gyro and accelerometer topics either: a log needs a pose or the "
                              "IMU (--topic overrides)")
        attitude = sig["quat"] is not None      # kept: IMU, motors and attitude
        notes.append(f"{path}: {', '.join(lacking)}: not in the log: read as IMU + motors"
                     f"{' with the attitude' if attitude else ''} on the "
                     f"{sig['body_rate'][2]} instants (no pose)")
        sig["position"] = sig["velocity"] = None
    base = sig["quat"] if pose else sig["body_rate"]
    t_base = base[0]
    valid = np.isfinite(base[1]).all(axis=1)
    if pose:
        check_unit_quat(path, f"{base[2]}.q", t_base, base[1])
    t_base = t_base[valid]
    t_base = t_base[increasing(path, f"{base[2]}.timestamp", t_base, [])]
    if len(t_base) < 2:
        raise field_error(path, f"{base[2]}", f"{len(t_base)} usable sample(s) of the time "
                          "base topic")
    if rate_hz:
        rows = (t_base[-1] - t_base[0]) * rate_hz
        if not 2 <= rows <= MAX_ROWS:
            raise field_error(path, "--rate", f"{rate_hz:g} Hz over the attitude span of "
                              f"{t_base[-1] - t_base[0]:.4g} s gives {rows:.4g} rows; "
                              f"2..{MAX_ROWS:.0e} allowed")
        t_base = t_base[0] + np.arange(int((t_base[-1] - t_base[0]) * rate_hz) + 1) / rate_hz
    out: dict[str, np.ndarray | None] = {}
    rates: dict[str, float | None] = {}
    for key, found in sig.items():
        if found is None:
            out[key] = None
            continue
        t_src, values, topic = found
        ok = np.isfinite(values).all(axis=1) if key not in ("rotor_command",) else \
            np.ones(len(t_src), bool)
        t_src, values = t_src[ok], values[ok]
        keep = increasing(path, f"{topic}.timestamp", t_src, notes,
                          required=key in ("position", "quat"))
        if keep is None:
            out[key] = None
            continue
        t_src, values = t_src[keep], values[keep]
        if len(t_src) < 2:
            if key in ("position", "quat"):
                raise field_error(path, topic, f"{len(t_src)} usable sample(s); 2 or more "
                                  "are needed")
            notes.append(f"{path}: {topic}: {len(t_src)} usable sample(s); {key} left out")
            out[key] = None
            continue
        rates[key] = median_rate(t_src)          # the topic's own rate, before resampling
        out[key] = (resample_quat(t_src, values, t_base) if key == "quat"
                    else resample(t_src, values, t_base))
        if key == "vbat":
            out[key] = out[key][:, 0]
    out["rotor_command"], out["rotor_speed"] = _rotors(path, ulog, sig, out, pwm_range)
    for key in ("position", "velocity"):
        if out[key] is not None:
            out[key] = ned_to_world(out[key])
    for key in ("body_rate", "accel"):
        if out[key] is not None:
            out[key] = frd_to_body(out[key])
    if out["quat"] is not None:
        out["quat"] = quat_ned_frd_to_world_body(out["quat"])
    out["rotor_speed"] = map_rotors(path, "esc_status", out["rotor_speed"], rotor_map)
    out["rotor_command"] = map_rotors(path, "actuator_motors", out["rotor_command"], rotor_map)
    keep = (np.isfinite(out["position"]).all(axis=1) & np.isfinite(out["quat"]).all(axis=1)
            if pose else np.isfinite(out["body_rate"]).all(axis=1) & (
                True if out["quat"] is None else np.isfinite(out["quat"]).all(axis=1)))
    if keep.sum() < 2:
        raise field_error(path, "vehicle_local_position", "position and attitude never "
                          "overlap in time")
    if keep.mean() < 1 - LOSS_NOTE:
        notes.append(f"{path}: vehicle_local_position: lost {int((~keep).sum())} of "
                     f"{len(keep)} attitude rows without position (kept "
                     f"{t_base[keep][0] - t_base[0]:.3f}-{t_base[keep][-1] - t_base[0]:.3f} s "
                     f"of 0-{t_base[-1] - t_base[0]:.3f} s)")
    if vehicle.get("kind", "multirotor") != "multirotor":
        notes.append(f"{path}: MAV_TYPE {vehicle['mav_type']}: a {vehicle['kind']}, not a "
                     "multirotor; rotor columns are its first motor outputs")
    if out["rotor_command"] is not None or out["rotor_speed"] is not None:
        vehicle["rotors"] = (out["rotor_command"] if out["rotor_command"] is not None
                             else out["rotor_speed"]).shape[1]
    columns = Columns(columns_from_signals(
        t_base[keep], {k: (v[keep] if v is not None else None) for k, v in out.items()}),
        notes=notes, vehicle=vehicle,
        rates={k: r for k, r in rates.items() if r is not None and out.get(k) is not None})
    return common_span(columns, path)


def _rotors(path, ulog, sig, out, pwm_range):
    """(commands (N, R) 0-1, rotor speeds (N, R) rad/s) with R from the commands."""
    cmd, speed = out["rotor_command"], out["rotor_speed"]
    count = None
    if cmd is not None:
        raw = sig["rotor_command"][1]
        used = np.isfinite(raw).any(axis=0)
        if sig["rotor_command"][2] == "actuator_outputs":
            count = int(check_parameter(path, "CA_ROTOR_COUNT", ulog.initial_parameters.get(
                "CA_ROTOR_COUNT", 4), low=1, high=16, integer=True))
            cmd = pwm_to_unit(cmd, pwm_range)
        else:
            count = int(np.flatnonzero(used)[-1]) + 1 if used.any() else 0
        cmd = cmd[:, :count]
        finite = cmd[np.isfinite(cmd)]
        if finite.size and (finite.max() > 1.05 or finite.min() < -0.05):
            raise field_error(path, f"{sig['rotor_command'][2]}", f"commands span "
                              f"{finite.min():.4g}..{finite.max():.4g}, not 0-1: unknown range "
                              "(set pwm_range / --pwm-range)")
    if speed is not None:
        if count is None:
            count = int(check_parameter(path, "CA_ROTOR_COUNT", ulog.initial_parameters.get(
                "CA_ROTOR_COUNT", speed.shape[1]), low=1, high=16, integer=True))
        if speed.shape[1] < count:
            raise field_error(path, "esc_status", f"{speed.shape[1]} ESCs for {count} motors")
        speed = np.abs(speed[:, :count]) * RPM_TO_RAD_S
    return cmd, speed


def is_ulog(head: bytes) -> bool:
    return head[:7] == MAGIC


__all__ = ["MAGIC", "TOPICS", "is_ulog", "ulog_columns"]
