"""Small, physically consistent flights written in each foreign format by its own writer: the
fixtures of the importer tests and of the fuzzer (``benchmarks/fuzz_logs.py``).

The flight (:func:`sample_flight`): a circle of radius ``RADIUS_M`` = 0.5 m at 1 m height
flown at ``OMEGA`` = 1 rad/s, yaw 0, the attitude tilted so that body z lies along the
needed specific force ``a + g e_z`` (m/s^2, world); body rate from the quaternions
(central differences), specific force ``R^T (a + g e_z)``, four rotors at a constant
1500 rad/s, commands 0.5, battery 3.9 V. Everything in SI and our frames (world z up, body
FLU, quaternions wxyz body to world); ``duration_s`` at ``rate_hz``.

Writers (each the inverse of its importer; the values are the flight's, converted to the
format's units and frames):

* :func:`ulog_bytes` -- PX4 ULog through pyulog's own ``ULog.write_ulog`` (topics
  ``vehicle_attitude``, ``vehicle_local_position``, ``sensor_combined``,
  ``actuator_motors``, ``esc_status``, ``battery_status``; parameters ``MAV_TYPE`` 2 and
  ``CA_ROTOR_COUNT`` 4); needs pyulog.
* :func:`dataflash_bytes` -- ArduPilot DataFlash: FMT, PARM, ATT (deg), XKF1, IMU, RCOU,
  ESC, BAT, packed here (pymavlink has no writer); read back by pymavlink.
* :func:`usd_bytes` -- Crazyflie uSD v2 through :func:`quadsim.logs.usd.encode_usd`.

Example::

    >>> from quadsim.logs.samples import sample_flight, usd_bytes
    >>> Path("log00").write_bytes(usd_bytes(sample_flight()))
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass

import numpy as np

from ..core.frames import euler_to_quat, quat_to_euler, quat_to_rotmat
from .common import quat_ned_frd_to_world_body
from .flightlog import body_rate_from_quat
from .usd import encode_usd

__all__ = ["SampleFlight", "dataflash_bytes", "sample_flight", "ulog_bytes", "usd_bytes"]

RADIUS_M = 0.5
OMEGA = 1.0          # rad/s around the circle
HEIGHT_M = 1.0
ROTOR_SPEED = 1500.0  # rad/s
COMMAND = 0.5
VBAT = 3.9           # V
G = 9.81             # m/s^2
_FLIP = np.array([1.0, -1.0, -1.0])  # NED <-> ours, FRD <-> FLU (diagonal of P)


@dataclass(frozen=True)
class SampleFlight:
    """t (N,) s from 0; position, velocity (N, 3) world; quat (N, 4) wxyz; body_rate (N, 3)
    rad/s; accel (N, 3) m/s^2 body; rotor_speed, command (N, 4); vbat (N,) V."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    body_rate: np.ndarray
    accel: np.ndarray
    rotor_speed: np.ndarray
    command: np.ndarray
    vbat: np.ndarray


def sample_flight(duration_s: float = 2.0, rate_hz: float = 100.0) -> SampleFlight:
    """The circle flight of the module docstring."""
    n = round(duration_s * rate_hz) + 1
    t = np.arange(n) / rate_hz
    c, s = np.cos(OMEGA * t), np.sin(OMEGA * t)
    position = np.stack([RADIUS_M * c, RADIUS_M * s, np.full(n, HEIGHT_M)], axis=1)
    velocity = RADIUS_M * OMEGA * np.stack([-s, c, np.zeros(n)], axis=1)
    force = -RADIUS_M * OMEGA**2 * np.stack([c, s, np.zeros(n)], axis=1) + [0.0, 0.0, G]
    unit = force / np.linalg.norm(force, axis=1, keepdims=True)
    euler = np.stack([np.arcsin(-unit[:, 1]), np.arctan2(unit[:, 0], unit[:, 2]),
                      np.zeros(n)], axis=1)
    quat = euler_to_quat(euler)
    accel = np.einsum("nji,nj->ni", quat_to_rotmat(quat), force)
    return SampleFlight(t=t, position=position, velocity=velocity, quat=quat,
                        body_rate=body_rate_from_quat(t, quat), accel=accel,
                        rotor_speed=np.full((n, 4), ROTOR_SPEED), command=np.full((n, 4), COMMAND),
                        vbat=np.full(n, VBAT))


# ----------------------------------------------------------------------------- ULog


def ulog_topic(ULog, ulog, msg_id: int, name: str, stamps: np.ndarray, fields: list) -> None:
    """One topic: ``fields`` = [(type, array size, field, values (N,) or (N, size))];
    type ``esc_report`` makes the nested ``esc[i].esc_rpm`` of ``esc_status``."""
    fmt = object.__new__(ULog.MessageFormat)
    fmt.name, fmt.fields = name, [("uint64_t", 0, "timestamp")]
    data = ULog.Data.__new__(ULog.Data)
    data.multi_id, data.msg_id, data.name, data.timestamp_idx = 0, msg_id, name, 0
    data.field_data = [ULog._FieldData("timestamp", "uint64_t")]
    data.data = {"timestamp": np.asarray(stamps, dtype=np.uint64)}
    for type_str, size, field, values in fields:
        if type_str == "esc_report":
            sub = object.__new__(ULog.MessageFormat)
            sub.name, sub.fields = "esc_report", [("int32_t", 0, "esc_rpm")]
            ulog._message_formats["esc_report"] = sub
            fmt.fields.append(("esc_report", size, field))
            for i in range(size):
                key = f"{field}[{i}].esc_rpm"
                data.field_data.append(ULog._FieldData(key, "int32_t"))
                data.data[key] = np.asarray(values[:, i], dtype=np.int32)
            continue
        fmt.fields.append((type_str, size, field))
        dtype = ULog._UNPACK_TYPES[type_str][2]
        keys = [field] if size == 0 else [f"{field}[{i}]" for i in range(size)]
        values = np.asarray(values).reshape(len(stamps), -1)
        for i, key in enumerate(keys):
            data.field_data.append(ULog._FieldData(key, type_str))
            data.data[key] = values[:, i].astype(dtype)
    ulog._message_formats[name] = fmt
    ulog._data_list.append(data)


def ulog_bytes(flight: SampleFlight, *, start_us: int = 1_000_000,
               params: dict | None = None) -> bytes:
    """The flight as a PX4 ULog (pyulog's writer); every topic at the flight's instants;
    ``params`` override the parameters (MAV_TYPE, CA_ROTOR_COUNT)."""
    from pyulog import ULog

    ulog = ULog(None)
    ulog._file_version = 1
    ulog._start_timestamp = start_us
    ulog._initial_parameters.update({"MAV_TYPE": 2, "CA_ROTOR_COUNT": 4, **(params or {})})
    stamps = np.clip(start_us + np.round(flight.t * 1e6), 0, None).astype(np.int64)
    n = len(stamps)
    rpm = flight.rotor_speed * 60.0 / (2.0 * np.pi)
    topics = {
        "vehicle_attitude": [("float", 4, "q", quat_ned_frd_to_world_body(flight.quat))],
        "vehicle_local_position": [("float", 0, a, (flight.position * _FLIP)[:, i])
                                   for i, a in enumerate("xyz")]
        + [("float", 0, a, (flight.velocity * _FLIP)[:, i]) for i, a in
           enumerate(("vx", "vy", "vz"))],
        "sensor_combined": [("float", 3, "gyro_rad", flight.body_rate * _FLIP),
                            ("float", 3, "accelerometer_m_s2", flight.accel * _FLIP)],
        "actuator_motors": [("float", 12, "control",
                             np.hstack([flight.command, np.full((n, 8), np.nan)]))],
        "esc_status": [("esc_report", 8, "esc", np.hstack([
            np.clip(np.nan_to_num(np.round(rpm)), -2**31, 2**31 - 1), np.zeros((n, 4))]))],
        "battery_status": [("float", 0, "voltage_v", flight.vbat)],
    }
    for msg_id, (name, fields) in enumerate(topics.items()):
        ulog_topic(ULog, ulog, msg_id, name, stamps, fields)
    out = io.BytesIO()
    ulog.write_ulog(out)
    return out.getvalue()


# ----------------------------------------------------------------------------- DataFlash


def _df_sizes(fmt: str) -> str:
    """struct codes of a DataFlash format (c, C: int16 / uint16 in hundredths)."""
    return (fmt.replace("n", "4s").replace("N", "16s").replace("Z", "64s")
            .replace("c", "h").replace("C", "H"))


def df_format(type_id: int, name: str, fmt: str, columns: str) -> bytes:
    """A DataFlash FMT message describing message ``type_id``."""
    size = 3 + struct.calcsize("<" + _df_sizes(fmt))
    return b"\xa3\x95\x80" + struct.pack("<BB4s16s64s", type_id, size, name.encode(),
                                          fmt.encode(), columns.encode())


def df_message(type_id: int, fmt: str, *values) -> bytes:
    """One DataFlash message of type ``type_id`` with layout ``fmt``."""
    return b"\xa3\x95" + bytes([type_id]) + struct.pack("<" + _df_sizes(fmt), *values)


def dataflash_bytes(flight: SampleFlight, *, start_us: int = 2_000_000,
                    params: dict | None = None, omit: tuple[str, ...] = ()) -> bytes:
    """The flight as an ArduPilot DataFlash log (FMT, PARM, ATT, XKF1, IMU, RCOU, ESC, BAT);
    PWM 1000-2000 us (MOT_PWM_MIN/MAX), FRAME_CLASS 1 (quad); ``params`` override those;
    the message kinds in ``omit`` (e.g. ``("XKF1",)``: no position) are not written."""
    out = bytearray(df_format(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"))
    layout = {129: ("PARM", "QNf", "TimeUS,Name,Value"),
              130: ("ATT", "Qfff", "TimeUS,Roll,Pitch,Yaw"),
              131: ("XKF1", "QBffffff", "TimeUS,C,PN,PE,PD,VN,VE,VD"),
              132: ("IMU", "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
              133: ("RCOU", "QHHHH", "TimeUS,C1,C2,C3,C4"),
              134: ("ESC", "QBf", "TimeUS,Instance,RPM"), 135: ("BAT", "QBf", "TimeUS,Inst,Volt")}
    for type_id, (name, fmt, columns) in layout.items():
        out += df_format(type_id, name, fmt, columns)
    values = {"FRAME_CLASS": 1.0, "MOT_PWM_MIN": 1000.0, "MOT_PWM_MAX": 2000.0, **(params or {})}
    for name, value in values.items():
        out += df_message(129, "QNf", start_us, name.encode(), value)
    euler = np.degrees(quat_to_euler(quat_ned_frd_to_world_body(flight.quat)))
    pos, vel = flight.position * _FLIP, flight.velocity * _FLIP
    gyro, acc = flight.body_rate * _FLIP, flight.accel * _FLIP
    pwm = np.clip(np.nan_to_num(np.round(1000.0 + 1000.0 * flight.command)), 0, 65535).astype(int)
    rpm = flight.rotor_speed * 60.0 / (2.0 * np.pi)
    for k, t in enumerate(flight.t):
        t_us = max(0, start_us + round(t * 1e6))
        rows = {"ATT": (130, "Qfff", t_us, *euler[k]),
                "XKF1": (131, "QBffffff", t_us, 0, *pos[k], *vel[k]),
                "IMU": (132, "QBffffff", t_us, 0, *gyro[k], *acc[k]),
                "RCOU": (133, "QHHHH", t_us, *pwm[k])}
        for kind, message in rows.items():
            if kind not in omit:
                out += df_message(*message)
        for i in range(4 if "ESC" not in omit else 0):
            out += df_message(134, "QBf", t_us, i, rpm[k, i])
        if "BAT" not in omit:
            out += df_message(135, "QBf", t_us, 0, flight.vbat[k])
    return bytes(out)


# ----------------------------------------------------------------------------- uSD


def _uint16(values: np.ndarray) -> np.ndarray:
    """Round into the uint16 range (the firmware's saturation; NaN -> 0)."""
    return np.clip(np.nan_to_num(np.round(values)), 0, 65535).astype(int)


def usd_bytes(flight: SampleFlight, *, version: int = 2) -> bytes:
    """The flight as a Crazyflie uSD log (fixed-frequency event; firmware units: gyro deg/s,
    acc g, rpm, pwm 0-65535, mV)."""
    from .usd import CF_GRAVITY

    variables = [(f"stateEstimate.{a}", "f") for a in
                 ("x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz")]
    variables += [(f"gyro.{a}", "f") for a in "xyz"] + [(f"acc.{a}", "f") for a in "xyz"]
    variables += [(f"rpm.m{i}", "H") for i in range(1, 5)]
    variables += [(f"pwm.m{i}_pwm", "H") for i in range(1, 5)] + [("pm.vbatMV", "H")]
    tick = 1000 if version == 1 else 1_000_000
    rpm = _uint16(flight.rotor_speed * 60.0 / (2.0 * np.pi))
    pwm = _uint16(flight.command * 65535)
    samples = []
    for k, t in enumerate(flight.t):
        values = (*flight.position[k], *flight.velocity[k], *flight.quat[k],
                  *np.degrees(flight.body_rate[k]), *(flight.accel[k] / CF_GRAVITY),
                  *rpm[k], *pwm[k], *_uint16(flight.vbat[k:k + 1] * 1000))
        samples.append((round((5.0 + t) * tick), values))
    return encode_usd({"fixedFrequency": (0xFFFF, variables, samples)}, version=version)
