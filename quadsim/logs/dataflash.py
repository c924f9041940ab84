"""ArduPilot DataFlash binary logs (``.bin``) through ``pymavlink``'s DFReader (optional:
``pip install -e '.[logs]'``).

Messages read (first instance where a message has several: ``I``/``C``/``Instance`` = 0):

=============  ==========================  ==================================  ==============
signal         message (fallbacks)         fields                              unit in log
=============  ==========================  ==================================  ==============
quat           ATT                         Roll Pitch Yaw                      deg, Z-Y-X
                                                                               Euler, NED/FRD
position       XKF1 (EKF1, POS)            PN PE PD (POS: Lat Lng Alt)         m NED (deg, m)
velocity       XKF1 (EKF1)                 VN VE VD                            m/s NED
body_rate      IMU                         GyrX GyrY GyrZ                      rad/s FRD
accel          IMU                         AccX AccY AccZ                      m/s^2 FRD
rotor_command  RCOU                        C1..Cn (older: Ch1..Chn)            us PWM
rotor_speed    ESC (Instance, RPM)         RPM                                 RPM
vbat           BAT (CURR)                  Volt                                V (CURR with an
                                                                               int16 field: cV)
=============  ==========================  ==================================  ==============

Time: ``TimeUS`` (us) or, in older logs, ``TimeMS`` (ms) since boot -> s from the first attitude
row; every message is interpolated onto the ATT instants (``common.resample``: linear, NaN across
gaps), trimmed to the span every message covers (``common.common_span``). Frames as for PX4
(``quadsim.logs.common``). ``POS`` (geodetic) becomes local NED about its first fix by the
flat-earth approximation (R = 6378137 m).

Rotor count from ``FRAME_CLASS`` (1 quad 4, 2 hexa 6, 3 octa 8, 4 octa-quad 8, 5 Y6 6,
7 tri 3), else 4 (older logs: ``FRAME`` is only the X/+ layout). PWM range from
``MOT_PWM_MIN``/``MOT_PWM_MAX`` when set, else ``RC3_MIN``/``RC3_MAX`` (the throttle channel,
ArduCopter <= 3.x), else 1000-2000 us; ``pwm_range`` overrides. A voltage that is zero
throughout (no battery monitor, ``BATT_MONITOR`` = 0) is left out.

No position message (or no ATT): read as IMU + motors on the IMU instants, with a note; an
ATT without a position is kept, interpolated onto those instants (rows outside it dropped).
Errors: no pose and no IMU message; a message missing its fields ("unknown ArduPilot message
layout": the fields present are listed), a file pymavlink cannot parse, commands outside 0-1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import InputError, field_error
from ..core.frames import euler_to_quat
from .common import (
    LOSS_NOTE,
    RPM_TO_RAD_S,
    Columns,
    check_parameter,
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

MAGIC = b"\xa3\x95\x80"
_FRAME_ROTORS = {1: 4, 2: 6, 3: 8, 4: 8, 5: 6, 7: 3}
_WANTED = ("ATT", "XKF1", "EKF1", "POS", "IMU", "RCOU", "ESC", "BAT", "CURR", "PARM")
EARTH_RADIUS = 6378137.0  # m, WGS-84 equatorial
#: notes of the import in progress (one import per worker process at a time)
_NOTES: list[str] = []


def _read(path: Path) -> tuple[dict[str, list[dict]], dict[str, float], dict[str, str]]:
    try:
        from pymavlink import DFReader
    except ImportError:
        raise InputError(f"{path}: reading DataFlash needs pymavlink "
                         "(pip install -e '.[logs]')") from None
    try:
        reader = DFReader.DFReader_binary(str(path), zero_time_base=False)
    except Exception as exc:  # noqa: BLE001 (pymavlink raises assorted errors on bad files)
        raise InputError(f"{path}: not a readable DataFlash log: {' '.join(str(exc).split())}"
                         ) from None
    messages: dict[str, list[dict]] = {k: [] for k in _WANTED}
    params: dict[str, float] = {}
    while True:
        try:
            msg = reader.recv_match(type=list(_WANTED))
        except Exception as exc:  # noqa: BLE001 (pymavlink: any parse error)
            raise InputError(f"{path}: corrupt DataFlash data: {' '.join(str(exc).split())}"
                             ) from None
        if msg is None:
            break
        kind = msg.get_type()
        if kind == "PARM":
            name, value = getattr(msg, "Name", None), getattr(msg, "Value", None)
            if not isinstance(name, str) or value is None:
                raise field_error(path, "PARM", "parameter message without Name/Value "
                                  "(damaged format definition)")
            params[name] = value
        else:
            messages[kind].append(msg.to_dict())
    formats = {f.name: f.format for f in reader.formats.values()}
    reader.close()
    return messages, params, formats


def _time(path: Path, rows: list[dict], kind: str) -> np.ndarray:
    for name, scale in (("TimeUS", 1e-6), ("TimeMS", 1e-3)):
        if name in rows[0]:
            try:
                return np.array([r[name] for r in rows], dtype=float) * scale
            except (TypeError, ValueError, KeyError):
                raise field_error(path, f"{kind}.{name}", "not a number in every message "
                                  "(damaged format definition)") from None
    raise field_error(path, f"{kind}.TimeUS", "no TimeUS or TimeMS field: unknown ArduPilot "
                      f"message layout (fields present: {', '.join(_present(rows))})")


def _present(rows: list[dict]) -> list[str]:
    return [str(k) for k in rows[0] if k != "mavpackettype"]


def _first_instance(rows: list[dict]) -> list[dict]:
    for key in ("I", "C", "Instance", "Inst"):
        if rows and key in rows[0]:
            return [r for r in rows if r[key] == 0]
    return rows


def _table(path: Path, rows: list[dict], fields: list[str], kind: str, *,
           first_only: bool = True):
    rows = _first_instance(rows) if first_only else rows
    if not rows:
        return None
    missing = [f for f in fields if f not in rows[0]]
    if missing:
        raise field_error(path, f"{kind}.{missing[0]}", "unknown ArduPilot message layout "
                          f"(fields present: {', '.join(_present(rows))})")
    t = _time(path, rows, kind)
    try:
        values = np.array([[r.get(f) for f in fields] for r in rows], dtype=float)
    except (TypeError, ValueError):
        raise field_error(path, kind, f"fields {', '.join(fields)} are not numbers in every "
                          "message (damaged format definition)") from None
    ok = increasing(path, f"{kind}.TimeUS", t, _NOTES)
    if ok.sum() < 2:
        raise field_error(path, kind, f"{int(ok.sum())} usable message(s) with increasing "
                          "time; 2 or more are needed")
    return t[ok], values[ok]


def _position(path: Path, messages: dict):
    for kind in ("XKF1", "EKF1"):
        if messages[kind]:
            pos = _table(path, messages[kind], ["PN", "PE", "PD"], kind)
            vel = _table(path, messages[kind], ["VN", "VE", "VD"], kind)
            return pos, vel
    if messages["POS"]:
        t, geo = _table(path, messages["POS"], ["Lat", "Lng", "Alt"], "POS")
        lat0 = np.radians(geo[0, 0])
        north = np.radians(geo[:, 0] - geo[0, 0]) * EARTH_RADIUS
        east = np.radians(geo[:, 1] - geo[0, 1]) * EARTH_RADIUS * np.cos(lat0)
        return (t, np.stack([north, east, -(geo[:, 2] - geo[0, 2])], axis=1)), None
    return None, None


def _rotor_setup(path: Path, params: dict, pwm_range):
    count = 4
    if "FRAME_CLASS" in params:
        frame = int(check_parameter(path, "FRAME_CLASS", params["FRAME_CLASS"], low=0,
                                    high=255, integer=True))
        if frame not in _FRAME_ROTORS:
            raise field_error(path, "FRAME_CLASS", f"parameter {frame}: not a multirotor "
                              "frame class this importer knows (1 quad, 2 hexa, 3 octa, "
                              "4 octa-quad, 5 Y6, 7 tri)")
        count = _FRAME_ROTORS[frame]

    def pair(lo: str, hi: str):
        low = check_parameter(path, lo, params[lo], low=500, high=2500)
        high = check_parameter(path, hi, params[hi], low=500, high=2500)
        if not low < high:
            raise field_error(path, lo, f"parameter {low:g} not below {hi} {high:g}")
        return low, high

    if pwm_range is None:
        if "MOT_PWM_MIN" in params and "MOT_PWM_MAX" in params and not (
                params["MOT_PWM_MIN"] == 0 and params["MOT_PWM_MAX"] == 0):
            pwm_range = pair("MOT_PWM_MIN", "MOT_PWM_MAX")
        elif "RC3_MIN" in params and "RC3_MAX" in params:
            pwm_range = pair("RC3_MIN", "RC3_MAX")
        else:
            pwm_range = (1000.0, 2000.0)
    return count, pwm_range


def _commands(path, messages, count, pwm_range):
    rows = messages["RCOU"]
    if not rows:
        return None
    prefix = "C" if "C1" in rows[0] else "Ch"
    t, pwm = _table(path, rows, [f"{prefix}{i + 1}" for i in range(count)], "RCOU")
    cmd = pwm_to_unit(pwm, pwm_range)
    if not np.isfinite(cmd).all() or cmd.max() > 1.05 or cmd.min() < -0.05:
        raise field_error(path, "RCOU", f"motor outputs span {pwm.min():g}..{pwm.max():g} us, "
                          f"outside the PWM range {pwm_range[0]:g}-{pwm_range[1]:g} us: unknown "
                          "range (--pwm-range)")
    return t, cmd


def _speeds(path, messages, count):
    rows = messages["ESC"]
    if not rows or "RPM" not in rows[0] or "Instance" not in rows[0]:
        return None
    series = []
    for i in range(count):
        mine = [r for r in rows if r.get("Instance") == i]
        if len(mine) < 2:
            raise field_error(path, "ESC", f"no RPM for motor {i + 1} of {count}")
        t, rpm = _table(path, mine, ["RPM"], "ESC", first_only=False)
        series.append((t, np.abs(rpm[:, 0])))
    return series


def _voltage(path, messages, formats):
    for kind in ("BAT", "CURR"):
        if len(messages[kind]) >= 2 and "Volt" in messages[kind][0]:
            t, volt = _table(path, messages[kind], ["Volt"], kind)
            fmt_cols = formats.get(kind, "")
            if kind == "CURR" and "h" in fmt_cols and volt.max() > 100:
                volt = volt / 100.0  # ArduCopter <= 3.2 logged centivolts as int16
            if np.all(volt == 0):
                return None
            return t, volt[:, 0]
    return None


def _rates(**series) -> dict[str, float]:
    """Each message's native rate (Hz, :func:`quadsim.logs.common.median_rate`): signal ->
    (t, ...) or a list of them (one per ESC instance: the slowest), None left out."""
    out = {}
    for key, found in series.items():
        if not found:
            continue
        times = [f[0] for f in found] if isinstance(found, list) else [found[0]]
        rates = [r for r in (median_rate(t) for t in times) if r is not None]
        if rates:
            out[key] = min(rates)
    return out


def dataflash_columns(path: str | Path, *, rotor_map: tuple[int, ...] | None = None,
                      pwm_range: tuple[float, float] | None = None) -> dict[str, np.ndarray]:
    """Flight-log columns (SI, schema names, our frames) from an ArduPilot DataFlash log."""
    path = Path(path)
    _NOTES.clear()
    messages, params, formats = _read(path)
    pos, vel = _position(path, messages)
    imu = _table(path, messages["IMU"], ["GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"],
                 "IMU") if messages["IMU"] else None
    if pos is None or not messages["ATT"]:
        return _imu_columns(path, messages, params, formats, imu, rotor_map=rotor_map,
                            pwm_range=pwm_range)
    t_base, euler = _table(path, messages["ATT"], ["Roll", "Pitch", "Yaw"], "ATT")
    _check_euler(path, t_base, euler)
    quat_ned = euler_to_quat(np.radians(euler))
    count, pwm_range = _rotor_setup(path, params, pwm_range)
    cmd = _commands(path, messages, count, pwm_range)
    speeds = _speeds(path, messages, count)
    volt = _voltage(path, messages, formats)
    sig = {"quat": quat_ned_frd_to_world_body(resample_quat(t_base, quat_ned, t_base)),
           "position": ned_to_world(resample(*pos, t_base)),
           "velocity": ned_to_world(resample(*vel, t_base)) if vel else None}
    if imu is not None:
        both = resample(*imu, t_base)
        sig["body_rate"], sig["accel"] = frd_to_body(both[:, :3]), frd_to_body(both[:, 3:])
    sig["rotor_command"] = map_rotors(path, "RCOU", resample(*cmd, t_base) if cmd else None,
                                      rotor_map)
    if speeds:
        speed = np.stack([resample(t, v, t_base) for t, v in speeds], axis=1) * RPM_TO_RAD_S
        sig["rotor_speed"] = map_rotors(path, "ESC", speed, rotor_map)
    sig["vbat"] = resample(*volt, t_base) if volt else None
    keep = np.isfinite(sig["position"]).all(axis=1) & np.isfinite(sig["quat"]).all(axis=1)
    if keep.sum() < 2:
        raise field_error(path, "XKF1/EKF1", "position and attitude never overlap in time")
    notes = list(_NOTES)
    if keep.mean() < 1 - LOSS_NOTE:
        notes.append(f"{path}: XKF1/EKF1/POS: lost {int((~keep).sum())} of {len(keep)} ATT "
                     f"rows without position (kept {t_base[keep][0] - t_base[0]:.3f}-"
                     f"{t_base[keep][-1] - t_base[0]:.3f} s of 0-{t_base[-1] - t_base[0]:.3f} s)")
    columns = Columns(columns_from_signals(
        t_base[keep], {k: (v[keep] if v is not None else None) for k, v in sig.items()}),
        notes=notes, vehicle={"rotors": count, "kind": "multirotor",
                              "source": "ArduPilot FRAME_CLASS"},
        rates=_rates(quat=(t_base,), position=pos, velocity=vel, body_rate=imu, accel=imu,
                     rotor_command=cmd, rotor_speed=speeds, vbat=volt))
    return common_span(columns, path)


def _imu_columns(path: Path, messages: dict, params: dict, formats: dict, imu, *,
                 rotor_map, pwm_range) -> Columns:
    """A log without position (no XKF1, EKF1 or POS) or attitude (ATT): IMU + motors on the
    IMU message's instants (body rates, specific force, RCOU commands, ESC speeds, battery),
    with a note; refused when it has no IMU message either."""
    if imu is None:
        raise field_error(path, "XKF1/EKF1/POS", "no position message and no IMU message: "
                          "a log needs a pose (XKF1, EKF1 or POS with ATT) or the IMU")
    t_base, both = imu
    count, pwm_range = _rotor_setup(path, params, pwm_range)
    cmd = _commands(path, messages, count, pwm_range)
    speeds = _speeds(path, messages, count)
    volt = _voltage(path, messages, formats)
    sig = {"body_rate": frd_to_body(both[:, :3]), "accel": frd_to_body(both[:, 3:]),
           "rotor_command": map_rotors(path, "RCOU", resample(*cmd, t_base) if cmd else None,
                                       rotor_map),
           "vbat": resample(*volt, t_base) if volt else None}
    if speeds:
        speed = np.stack([resample(t, v, t_base) for t, v in speeds], axis=1) * RPM_TO_RAD_S
        sig["rotor_speed"] = map_rotors(path, "ESC", speed, rotor_map)
    lacking = "ATT" if not messages["ATT"] else "XKF1/EKF1/POS"
    keep = np.ones(len(t_base), bool)
    if messages["ATT"]:         # the attitude without a position: kept on the IMU instants
        t_att, euler = _table(path, messages["ATT"], ["Roll", "Pitch", "Yaw"], "ATT")
        _check_euler(path, t_att, euler)
        sig["quat"] = quat_ned_frd_to_world_body(
            resample_quat(t_att, euler_to_quat(np.radians(euler)), t_base))
        keep = np.isfinite(sig["quat"]).all(axis=1)
        if keep.sum() < 2:
            raise field_error(path, "ATT", "the attitude and the IMU never overlap in time")
    with_attitude = " with the attitude" if messages["ATT"] else ""
    notes = [*_NOTES, f"{path}: {lacking}: not logged: read as IMU + motors{with_attitude} "
             "(no pose)"]
    columns = Columns(columns_from_signals(
        t_base[keep], {k: (v[keep] if v is not None else None) for k, v in sig.items()}),
        notes=notes, vehicle={"rotors": count, "kind": "multirotor",
                              "source": "ArduPilot FRAME_CLASS"},
        rates=_rates(body_rate=imu, accel=imu, rotor_command=cmd, rotor_speed=speeds,
                     vbat=volt))
    return common_span(columns, path)


def _check_euler(path: Path, t: np.ndarray, euler: np.ndarray) -> None:
    """Roll and yaw within +-360 deg, pitch within +-90 deg (ATT, degrees)."""
    for i, (name, limit) in enumerate((("Roll", 360.0), ("Pitch", 90.5), ("Yaw", 360.0))):
        bad = ~np.isfinite(euler[:, i]) | (np.abs(euler[:, i]) > limit)
        if bad.any():
            k = int(np.argmax(bad))
            raise field_error(path, f"ATT.{name}", f"message {k} (t = {t[k]:.6g} s): "
                              f"{euler[k, i]:.4g} deg, outside +-{limit:g} deg")


def is_dataflash(head: bytes) -> bool:
    return head[:3] == MAGIC


__all__ = ["MAGIC", "dataflash_columns", "is_dataflash"]
