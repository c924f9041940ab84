"""Foreign flight logs (quadsim.logs, quadsim.convert): round trips through fixtures written
here with each format's own writer (pyulog for ULog; small encoders for DataFlash and uSD),
frame conversions, lag-free resampling, bad input; comparisons with the real files in
../shared/data skip when those are absent."""

from __future__ import annotations

import gzip
import os
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from quadsim.convert import main as convert_main
from quadsim.core.errors import InputError
from quadsim.core.frames import euler_to_quat, quat_to_euler, quat_to_rotmat
from quadsim.logs import detect_format, read_columns
from quadsim.logs.common import (
    P_FLIP,
    frd_to_body,
    ned_to_world,
    quat_ned_frd_to_world_body,
    quat_world_body_to_ned_frd,
    resample,
)
from quadsim.logs.flightlog import load_log
from quadsim.logs.samples import df_format, df_message
from quadsim.logs.usd import CF_GRAVITY, encode_usd, read_usd

DATA = Path(os.environ.get("QUADSIM_SHARED_DATA",
                           Path(__file__).resolve().parents[1] / ".." / "shared" / "data"))
N = 300
DT = 0.004


def _need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"real data not found at {path} (../shared/data next to the repo)")
    return path


# ----------------------------------------------------------------------------- frames


@pytest.mark.parametrize("roll", [0.3, -1.2, 2.5])
def test_known_roll_both_ways(roll):
    """A roll phi in NED/FRD is a roll phi in ours; pitch and yaw change sign
    (P = diag(1,-1,-1))."""
    q_ned = euler_to_quat([roll, 0.0, 0.0])
    np.testing.assert_allclose(quat_to_euler(quat_ned_frd_to_world_body(q_ned)),
                               [roll, 0, 0], atol=1e-12)
    np.testing.assert_allclose(quat_to_euler(quat_world_body_to_ned_frd(euler_to_quat(
        [roll, 0, 0]))), [roll, 0, 0], atol=1e-12)
    q = euler_to_quat([roll, 0.2, 0.7])
    np.testing.assert_allclose(quat_to_euler(quat_ned_frd_to_world_body(q)),
                               [roll, -0.2, -0.7], atol=1e-12)
    # R' = P R P, checked against the matrices independently of the quaternion shortcut
    np.testing.assert_allclose(quat_to_rotmat(quat_ned_frd_to_world_body(q)),
                               P_FLIP @ quat_to_rotmat(q) @ P_FLIP, atol=1e-12)


def test_vectors_ned_frd():
    np.testing.assert_allclose(ned_to_world([1.0, 2.0, -3.0]), [1.0, -2.0, 3.0])
    np.testing.assert_allclose(frd_to_body([0.0, 0.0, -9.81]), [0.0, 0.0, 9.81])
    # a body vector rotated to the world gives the same physical vector either way
    q = euler_to_quat([0.4, -0.3, 1.1])
    v = np.array([0.5, -0.2, 0.9])
    in_ned = quat_to_rotmat(q) @ v
    np.testing.assert_allclose(quat_to_rotmat(quat_ned_frd_to_world_body(q)) @ frd_to_body(v),
                               ned_to_world(in_ned), atol=1e-12)


# ----------------------------------------------------------------------------- resampling


def test_resample_sine_has_no_lag_and_no_extrapolation():
    w, dt = 2 * np.pi * 3.0, 0.01
    t_src = np.arange(0, 2, dt)
    t_out = np.arange(0.0033, 2.1, 0.0017)
    y = resample(t_src, np.sin(w * t_src), t_out)
    inside = t_out <= t_src[-1]
    err = y[inside] - np.sin(w * t_out[inside])
    assert np.abs(err).max() <= (w * dt) ** 2 / 8 + 1e-12   # linear-interpolation bound
    # no lag: the error is not correlated with the derivative (a delay tau would give
    # err ~ -tau w cos); fitted delay below 1e-4 of a sample
    cosine = w * np.cos(w * t_out[inside])
    tau = -np.sum(err * cosine) / np.sum(cosine ** 2)
    assert abs(tau) < 1e-4 * dt
    assert np.isnan(y[~inside]).all()


def test_resample_gap_is_nan():
    t_src = np.concatenate([np.arange(0, 1, 0.01), np.arange(1.5, 2, 0.01)])
    y = resample(t_src, t_src * 2.0, np.array([0.5, 1.2, 1.7, -0.1]))
    np.testing.assert_allclose(y[[0, 2]], [1.0, 3.4])
    assert np.isnan(y[1]) and np.isnan(y[3])


# ----------------------------------------------------------------------------- uSD


def _usd_fixture(version: int = 2) -> tuple[bytes, dict]:
    """Fixed-frequency events at 250 Hz with the Crazyflie variables (file units)."""
    rng = np.random.default_rng(3)
    truth = {"x": np.linspace(0, 1, N), "y": np.zeros(N), "z": np.full(N, 0.5),
             "gyro": rng.normal(0, 50, (N, 3)), "acc": rng.normal(0, 0.1, (N, 3)) + [0, 0, 1],
             "rpm": rng.integers(10000, 20000, (N, 4)), "pwm": rng.integers(0, 65535, (N, 4)),
             "vbat": rng.integers(3500, 4200, N)}
    quat = euler_to_quat(np.stack([np.zeros(N), np.zeros(N), np.linspace(0, 1, N)], -1))
    truth["quat"] = quat
    variables = [(f"stateEstimate.{a}", "f") for a in ("x", "y", "z", "qx", "qy", "qz", "qw")]
    variables += [(f"gyro.{a}", "f") for a in "xyz"] + [(f"acc.{a}", "f") for a in "xyz"]
    variables += [(f"rpm.m{i}", "H") for i in range(1, 5)]
    variables += [(f"pwm.m{i}_pwm", "H") for i in range(1, 5)] + [("pm.vbatMV", "H")]
    tick = 1000 if version == 1 else 1_000_000
    samples = []
    for k in range(N):
        values = (truth["x"][k], 0.0, 0.5, *quat[k, 1:], quat[k, 0], *truth["gyro"][k],
                  *truth["acc"][k], *truth["rpm"][k], *truth["pwm"][k], truth["vbat"][k])
        samples.append((round(5 * tick + k * DT * tick), values))
    # motion-capture pose at 100 Hz from 0.1 s to 0.5 s: x = 2 t, level, yaw 0
    pose = [(round(5 * tick + (0.1 + k * 0.01) * tick), (2 * (0.1 + k * 0.01), 0.2, 0.3,
                                                        0.0, 0.0, 0.0, 1.0)) for k in range(41)]
    pose_vars = [(f"locSrv.{a}", "f") for a in ("x", "y", "z", "qx", "qy", "qz", "qw")]
    events = {"fixedFrequency": (0xFFFF, variables, samples), "estPose": (9, pose_vars, pose)}
    return encode_usd(events, version=version), truth


@pytest.mark.parametrize("version", [1, 2])
def test_usd_round_trip(tmp_path, version):
    data, truth = _usd_fixture(version)
    path = tmp_path / "log00"
    path.write_bytes(data)
    assert detect_format(path) == "usd"
    log = load_log(path, warn=False)
    assert len(log) == N and log.rotor_count == 4
    np.testing.assert_allclose(log.t, np.arange(N) * DT, atol=1e-3 if version == 1 else 1e-9)
    np.testing.assert_allclose(log.position[:, 0], truth["x"], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(log.quat, truth["quat"], atol=1e-7)
    np.testing.assert_allclose(log.body_rate, np.radians(truth["gyro"]), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(log.accel, truth["acc"] * CF_GRAVITY, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(log.rotor_speed, truth["rpm"] * 2 * np.pi / 60, rtol=1e-12)
    np.testing.assert_allclose(log.rotor_command, truth["pwm"] / 65535, rtol=1e-12)
    np.testing.assert_allclose(log.vbat, truth["vbat"] / 1000, rtol=1e-12)
    events, got_version = read_usd(path)
    assert got_version == version and len(events["estPose"]["t"]) == 41
    # motion-capture pose instead of the state estimate: rows inside 0.1..0.5 s only,
    # position interpolated linearly (x = 2 t exactly)
    mocap = read_columns(path, topics={"pose": "estPose"})
    assert abs(mocap["t"][-1] - 0.4) < 1e-6 and len(mocap["t"]) == 101   # rows 0.1..0.5 s
    np.testing.assert_allclose(mocap["x"], 2 * (mocap["t"] + 0.1), atol=1e-6)
    np.testing.assert_allclose(mocap["z"], 0.3, atol=1e-7)


def test_usd_rotor_map(tmp_path):
    data, truth = _usd_fixture()
    path = tmp_path / "log00"
    path.write_bytes(data)
    cols = read_columns(path, rotor_map=(2, 3, 4, 1))
    np.testing.assert_allclose(cols["rotor_1"], truth["rpm"][:, 1] * 2 * np.pi / 60)
    np.testing.assert_allclose(cols["cmd_4"], truth["pwm"][:, 0] / 65535)


def _convert_fails(tmp_path, capsys, source, *extra, match):
    out = tmp_path / "out.csv.gz"
    assert convert_main([str(source), "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(source) in err
    assert match in err, err
    assert not out.exists()


def test_usd_bad_crc_and_truncation(tmp_path, capsys):
    data, _ = _usd_fixture()
    bad = tmp_path / "badcrc"
    bad.write_bytes(data[:100] + bytes([data[100] ^ 0xFF]) + data[101:])
    _convert_fails(tmp_path, capsys, bad, match="crc32")
    # truncated in the middle of an event, CRC recomputed so that only the layout is wrong
    body = data[:-4][:-7]
    cut = tmp_path / "truncated"
    cut.write_bytes(body + struct.pack("<I", zlib.crc32(body)))
    _convert_fails(tmp_path, capsys, cut, match="fixedFrequency: truncated event")


# ----------------------------------------------------------------------------- ULog


def _write_ulog(path: Path, topics: dict, start_us: int = 1_000_000) -> None:
    """A ULog file through pyulog's own writer (ULog.write_ulog), one topic at a time by the
    fuzzer's writer (quadsim.logs.samples). ``topics``: name -> (timestamps us, [(type, array
    size, field, values (N,) or (N, size))])."""
    pyulog = pytest.importorskip("pyulog", reason="pyulog not installed (quadsim[logs])")
    from quadsim.logs.samples import ulog_topic

    ULog = pyulog.ULog
    ulog = ULog(None)
    ulog._file_version = 1
    ulog._start_timestamp = start_us
    for msg_id, (name, (stamps, fields)) in enumerate(topics.items()):
        ulog_topic(ULog, ulog, msg_id, name, stamps, fields)
    ulog.write_ulog(str(path))


def _px4_topics(position: bool = True, motors: float = 0.6) -> dict:
    t_att = 1_000_000 + np.arange(N) * 4000               # 250 Hz attitude
    t_pos = 1_000_000 + np.arange(N // 2) * 8000          # 125 Hz position
    t_imu = 1_000_000 + np.arange(2 * N) * 2000           # 500 Hz IMU
    roll = 0.3 * np.sin(2 * np.pi * 0.5 * (t_att - t_att[0]) * 1e-6)
    q_ned = euler_to_quat(np.stack([roll, np.full(N, 0.1), np.full(N, 0.5)], -1))
    tp = (t_pos - t_pos[0]) * 1e-6
    topics = {
        "vehicle_attitude": (t_att, [("float", 4, "q", q_ned)]),
        "sensor_combined": (t_imu, [("float", 3, "gyro_rad", np.tile([0.1, 0.2, 0.3], (2 * N, 1))),
                                    ("float", 3, "accelerometer_m_s2",
                                     np.tile([0.0, 0.0, -9.81], (2 * N, 1)))]),
        "actuator_motors": (t_pos, [("float", 12, "control", np.hstack(
            [np.full((N // 2, 4), motors), np.full((N // 2, 8), np.nan)]))]),
        "esc_status": (t_pos, [("esc_report", 6, "esc", np.hstack(
            [np.full((N // 2, 4), 6000), np.zeros((N // 2, 2))]))]),
        "battery_status": (t_pos, [("float", 0, "voltage_v", np.linspace(16.2, 15.8, N // 2))]),
    }
    if position:
        topics["vehicle_local_position"] = (t_pos, [
            ("float", 0, "x", 1.0 + tp), ("float", 0, "y", np.full(N // 2, 2.0)),
            ("float", 0, "z", -0.5 - 0.1 * tp), ("float", 0, "vx", np.ones(N // 2)),
            ("float", 0, "vy", np.zeros(N // 2)), ("float", 0, "vz", np.full(N // 2, -0.1))])
    return topics


def test_ulog_round_trip(tmp_path):
    path = tmp_path / "flight.ulg"
    _write_ulog(path, _px4_topics())
    assert detect_format(path) == "ulog"
    log = load_log(path, warn=False)
    # rows: attitude instants where position exists (position ends 4 ms before attitude)
    assert len(log) == N - 1 and log.rotor_count == 4
    np.testing.assert_allclose(log.t, np.arange(N - 1) * 0.004, atol=1e-9)
    np.testing.assert_allclose(log.position[:, 0], 1.0 + log.t, atol=1e-6)
    np.testing.assert_allclose(log.position[:, 1], -2.0, atol=1e-6)       # east -> -y
    np.testing.assert_allclose(log.position[:, 2], 0.5 + 0.1 * log.t, atol=1e-6)  # down -> up
    np.testing.assert_allclose(log.velocity[:, 2], 0.1, atol=1e-6)
    roll = 0.3 * np.sin(2 * np.pi * 0.5 * log.t)
    np.testing.assert_allclose(quat_to_euler(log.quat), np.stack(
        [roll, np.full(len(log), -0.1), np.full(len(log), -0.5)], -1), atol=1e-6)
    np.testing.assert_allclose(log.body_rate, np.tile([0.1, -0.2, -0.3], (len(log), 1)), atol=1e-6)
    np.testing.assert_allclose(log.accel[:, 2], 9.81, atol=1e-5)
    np.testing.assert_allclose(log.rotor_speed, 6000 * 2 * np.pi / 60, rtol=1e-9)
    np.testing.assert_allclose(log.rotor_command, 0.6, atol=1e-6)
    np.testing.assert_allclose(log.vbat[0], 16.2, atol=1e-5)


def test_ulog_bad_inputs(tmp_path, capsys):
    # no position: an IMU + motors log (issue 44) with its attitude kept (issue 47),
    # converted with a warning, no position columns; the attitude is PX4's own, turned to ours
    path = tmp_path / "nopos.ulg"
    _write_ulog(path, _px4_topics(position=False))
    assert convert_main([str(path), "-o", str(tmp_path / "imu.csv.gz")]) == 0
    assert "vehicle_local_position x/y/z: not in the log: read as IMU + motors with the " \
        "attitude" in capsys.readouterr().err
    imu = load_log(tmp_path / "imu.csv.gz")
    assert imu.position is None and imu.quat is not None and not imu.has_pose
    euler = quat_to_euler(imu.quat)          # FRD/NED -> ours: roll kept, pitch, yaw negated
    np.testing.assert_allclose(euler[:, 1:], np.tile([-0.1, -0.5], (len(imu.t), 1)),
                               atol=1e-6)
    assert np.max(np.abs(euler[:, 0])) <= 0.3 + 1e-6 and np.ptp(euler[:, 0]) > 0.4
    assert imu.accel is not None and imu.body_rate is not None and imu.rotor_command is not None
    path = tmp_path / "range.ulg"
    _write_ulog(path, _px4_topics(motors=1500.0))
    _convert_fails(tmp_path, capsys, path, match="actuator_motors: commands span")
    path = tmp_path / "ok.ulg"
    _write_ulog(path, _px4_topics())
    _convert_fails(tmp_path, capsys, path, "--model", "crazyflie21", "--rotor-map", "1,2,3",
                   match="rotor map")


def test_convert_rotor_count_mismatch(tmp_path, capsys):
    data, _ = _usd_fixture()
    path = tmp_path / "log00"
    path.write_bytes(data)
    # the testbed parameter sets have 4 rotors: make a 6-rotor uSD log
    variables = [(f"stateEstimate.{a}", "f") for a in ("x", "y", "z", "qx", "qy", "qz", "qw")]
    variables += [(f"rpm.m{i}", "H") for i in range(1, 7)]
    samples = [(1000 * k, (0, 0, 0, 0, 0, 0, 1, *[1000] * 6)) for k in range(5)]
    six = tmp_path / "six"
    six.write_bytes(encode_usd({"fixedFrequency": (0xFFFF, variables, samples)}))
    _convert_fails(tmp_path, capsys, six, "--model", "crazyflie21", match="6 rotors in the log")
    # four rotors pass the count; --model then runs gap's channel checks, and this fixture's
    # random gyro follows no attitude (the quaternions turn about z only)
    _convert_fails(tmp_path, capsys, path, "--model", "crazyflie21",
                   match="rad rms about x over 0.1 s windows, the attitude quaternions not "
                         "at all")
    out = tmp_path / "ok.parquet"
    pytest.importorskip("pyarrow")
    assert convert_main([str(path), "-o", str(out)]) == 0
    assert len(load_log(out)) == N


# ----------------------------------------------------------------------------- DataFlash


def _write_dataflash(path: Path, *, att_columns: str = "TimeUS,Roll,Pitch,Yaw",
                     pwm: float = 1600.0) -> dict:
    """A DataFlash log with ATT (centidegrees), XKF1, IMU, RCOU, ESC, BAT and PARM."""
    out = bytearray(df_format(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"))
    layout = {129: ("PARM", "QNf", "TimeUS,Name,Value"), 130: ("ATT", "QccC", att_columns),
              131: ("XKF1", "QBffffff", "TimeUS,C,PN,PE,PD,VN,VE,VD"),
              132: ("IMU", "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
              133: ("RCOU", "QHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6"),
              134: ("ESC", "QBf", "TimeUS,Instance,RPM"), 135: ("BAT", "QBf", "TimeUS,Inst,Volt")}
    for type_id, (name, fmt, cols) in layout.items():
        out += df_format(type_id, name, fmt, cols)
    out += df_message(129, "QNf", 0, b"MOT_PWM_MIN", 1100.0)
    out += df_message(129, "QNf", 0, b"MOT_PWM_MAX", 1900.0)
    roll = np.radians(np.round(np.degrees(0.2 * np.sin(np.arange(N) * 0.05)) * 100) / 100)
    for k in range(N):
        t_us = 2_000_000 + k * 10_000                      # 100 Hz
        out += df_message(130, "QccC", t_us, round(np.degrees(roll[k]) * 100), 500, 9000)
        if k % 2 == 0:                                     # 50 Hz
            out += df_message(131, "QBffffff", t_us, 0, 0.01 * k, 1.0, -2.0, 1.0, 0.0, -0.5)
            out += df_message(131, "QBffffff", t_us, 1, 99.0, 99.0, 99.0, 0.0, 0.0, 0.0)  # core 1
            out += df_message(133, "QHHHHHH", t_us, *[int(pwm)] * 4, 1000, 1000)
            for i in range(4):
                out += df_message(134, "QBf", t_us + i, i, 5000.0 + 100 * i)
            out += df_message(135, "QBf", t_us, 0, 12.0)
        for j in range(2):                                 # 200 Hz
            out += df_message(132, "QBffffff", t_us + 5000 * j, 0, 0.1, 0.2, 0.3, 0.0, 0.0, -9.8)
    path.write_bytes(bytes(out))
    return {"roll": roll}


def test_dataflash_round_trip(tmp_path):
    pytest.importorskip("pymavlink", reason="pymavlink not installed (quadsim[logs])")
    path = tmp_path / "copter.bin"
    truth = _write_dataflash(path)
    assert detect_format(path) == "dataflash"
    log = load_log(path, warn=False)
    # rows: ATT instants covered by every message; ESC instances 1-3 start 1-3 us after the
    # first ATT row, so the common span starts at the second row (time restarts at 0)
    assert len(log) == N - 2 and log.rotor_count == 4
    np.testing.assert_allclose(log.t, np.arange(N - 2) * 0.01, atol=1e-9)
    euler = quat_to_euler(log.quat)
    np.testing.assert_allclose(euler[:, 0], truth["roll"][1:-1], atol=1e-9)
    np.testing.assert_allclose(euler[:, 1], np.radians(-5.0), atol=1e-9)
    np.testing.assert_allclose(euler[:, 2], np.radians(-90.0), atol=1e-9)
    np.testing.assert_allclose(log.position[:, 1:], np.tile([-1.0, 2.0], (N - 2, 1)), atol=1e-6)
    np.testing.assert_allclose(log.position[:, 0], log.t + 0.01, atol=1e-6)  # PN = 0.01 k
    np.testing.assert_allclose(log.velocity[:, 2], 0.5, atol=1e-6)
    np.testing.assert_allclose(log.body_rate, np.tile([0.1, -0.2, -0.3], (N - 2, 1)), atol=1e-6)
    np.testing.assert_allclose(log.accel[:, 2], 9.8, atol=1e-5)
    np.testing.assert_allclose(log.rotor_command, (1600 - 1100) / 800, atol=1e-12)
    np.testing.assert_allclose(log.rotor_speed[5], (5000 + 100 * np.arange(4)) * np.pi / 30,
                               rtol=1e-6)
    np.testing.assert_allclose(log.vbat, 12.0, atol=1e-6)


def test_dataflash_bad_inputs(tmp_path, capsys):
    pytest.importorskip("pymavlink", reason="pymavlink not installed (quadsim[logs])")
    path = tmp_path / "layout.bin"
    _write_dataflash(path, att_columns="TimeUS,R,P,Y")
    _convert_fails(tmp_path, capsys, path, match="ATT.Roll: unknown ArduPilot message layout")
    path = tmp_path / "pwm.bin"
    _write_dataflash(path, pwm=3000)
    _convert_fails(tmp_path, capsys, path, match="RCOU: motor outputs span")


def test_unknown_format_and_missing_file(tmp_path, capsys):
    path = tmp_path / "random.bin"
    path.write_bytes(b"\x00\x01binary junk")
    with pytest.raises(InputError, match="random.bin"):
        load_log(path)
    _convert_fails(tmp_path, capsys, tmp_path / "none.ulg", match="no such file")


# ----------------------------------------------------------------------------- real files


@pytest.mark.parametrize("k", [0, 1, 2])
def test_real_usd_reproduces_nominal_csv(k):
    raw = _need(DATA / "crazyflie21_brushless" / "usd_raw" / f"eckart0{k}")
    csv = _need(DATA / "crazyflie21_brushless" / "nominal" / f"flight_0{k}.csv.gz")
    cols = read_columns(raw)
    with gzip.open(csv, "rt") as handle:
        header = handle.readline().strip().split(",")
        table = np.loadtxt(handle, delimiter=",")
    assert sorted(header) == sorted(cols) and len(cols["t"]) == len(table)
    for i, name in enumerate(header):
        # the CSV keeps 7 significant digits: relative error <= 5e-7 (measured 5.0e-7)
        np.testing.assert_allclose(cols[name], table[:, i], rtol=6e-7, atol=1e-12,
                                   err_msg=name)


def test_real_px4_sitl_ulog():
    pytest.importorskip("pyulog")
    log = load_log(_need(DATA / "px4_ulog" / "sample_px4_events.ulg"), warn=False)
    assert log.rotor_count == 4 and len(log) > 500
    assert 1.9 < np.nanmax(log.position[:, 2]) < 2.5          # climbs to ~2.2 m, z up
    assert abs(np.median(log.accel[:, 2]) - 9.81) < 0.3       # FRD -> FLU: +g on z
    hover = np.nanmax(log.rotor_command, axis=1) > 0.3
    assert np.nanmedian(log.rotor_speed[hover]) > 100          # rad/s, spinning


def test_real_dataflash():
    pytest.importorskip("pymavlink")
    log = load_log(_need(DATA / "ardupilot_dataflash" / "copter_112.BIN"), warn=False)
    assert log.rotor_count == 4 and log.rotor_speed is None and log.vbat is None
    assert log.t[-1] > 600 and abs(np.median(log.accel[:, 2]) - 9.8) < 0.5


# ----------------------------------------------------------------------------- commands only


def test_command_model_recovers_a_known_lag_and_voltage_term():
    from quadsim.gap.logcheck import CommandModel, fit_command_model
    from quadsim.logs.flightlog import FlightLog

    rng = np.random.default_rng(0)
    t = np.arange(3000) * 0.002
    cmd = np.clip(0.5 + 0.2 * np.sin(np.outer(t, [3.0, 4.1, 5.3, 6.7])) +
                  0.02 * rng.standard_normal((len(t), 4)), 0, 1)
    vbat = 4.1 - 0.3 * t / t[-1]
    truth = CommandModel(np.array([50.0, 60, 70, 80]), np.array([3000.0, 3100, 3200, 3300]),
                         np.array([800.0, 820, 840, 860]), 3.95, 0.03, 0.0, 0, "truth")
    speed = truth.speeds(t, cmd, vbat)
    log = FlightLog(t, np.zeros((len(t), 3)), np.tile([1.0, 0, 0, 0], (len(t), 1)),
                    rotor_speed=speed, rotor_command=cmd, vbat=vbat)
    model = fit_command_model([log])
    assert abs(model.tau - 0.03) < 0.03 * 0.02          # 2 % (optimiser tolerance)
    np.testing.assert_allclose(model.b, truth.b, rtol=0.01)
    # c is fitted around the median voltage, so compare the predicted speeds
    assert model.rms < 0.5                              # rad/s, of ~1600


@pytest.mark.parametrize("hidden, expected", [
    (("mass_offset", {"mass": 0.004}), "mass_offset"),
    (("thrust_mismatch", {"rotor_2": -0.08}), "thrust_mismatch"),
])
def test_command_only_diagnosis_names_the_same_effect(hidden, expected):
    """Generated flights: the verdict with measured speeds and with speeds synthesised from
    the commands (model fitted on nominal reference flights) is the same effect."""
    from benchmarks.synthetic import synthetic_flight
    from quadsim.effects import make_effect
    from quadsim.gap import diagnose
    from quadsim.gap.logcheck import fit_command_model, synthesise_speeds, without_speeds
    from quadsim.vehicle.params import load_params

    cf = load_params("crazyflie21")
    reference = [synthetic_flight(cf, [], seed=s, duration=3.0) for s in (30, 31)]
    flights = [synthetic_flight(cf, [make_effect(hidden[0], **hidden[1])], seed=s, duration=4.0)
               for s in (32, 33)]
    model = fit_command_model(reference)
    only_cmd = [synthesise_speeds(without_speeds(g), model) for g in flights]
    names = ["mass_offset", "thrust_mismatch", "com_offset"]
    a = diagnose(flights, cf, kstep=False, max_combination=1, effects=names)
    b = diagnose(only_cmd, cf, kstep=False, max_combination=1, effects=names)
    assert a["verdict"]["effect"] == b["verdict"]["effect"] == expected


def test_convert_rate_and_crop(tmp_path):
    path = tmp_path / "flight.ulg"
    _write_ulog(path, _px4_topics())
    out = tmp_path / "f.csv"
    assert convert_main([str(path), "-o", str(out), "--rate", "500", "--start", "0.2",
                         "--end", "0.8"]) == 0
    log = load_log(out)
    # uniform 2 ms steps, 0.6 s kept, time restarts at 0; position follows x = 1 + t_orig
    np.testing.assert_allclose(np.diff(log.t), 0.002, atol=1e-9)
    assert abs(log.t[-1] - 0.6) < 0.0021
    offset = log.position[:, 0] - log.t          # = 1 + first kept time, within one step of 0.2
    assert np.ptp(offset) < 1e-5 and 1.2 - 1e-6 <= offset[0] <= 1.2 + 0.002 + 1e-6


def test_gap_cli_command_reference(tmp_path, capsys):
    """A command-only log: refused in one line without a reference or a motor map,
    diagnosed with a reference."""
    import dataclasses
    import re

    from benchmarks.synthetic import synthetic_flight
    from quadsim.gap.__main__ import main as gap_main
    from quadsim.logs.flightlog import write_log
    from quadsim.vehicle.params import load_params

    cf = load_params("crazyflie21")
    ref = [write_log(tmp_path / f"ref{s}.csv", synthetic_flight(cf, [], seed=s, duration=2.0))
           for s in (40, 41)]
    only = [write_log(tmp_path / f"cmd{s}.csv", dataclasses.replace(
        synthetic_flight(cf, [], seed=s, duration=2.0), rotor_speed=None)) for s in (42, 43)]
    no_map = tmp_path / "nomap.toml"   # crazyflie21 without its motor map: nothing to map
    no_map.write_text(re.sub(r"\[motor_map\].*?(?=\n\[\[rotor\]\])", "",
                             load_params("crazyflie21").path.read_text(), flags=re.S))
    args = ["--model", str(no_map), *map(str, only), "--quiet", "--effects", "mass_offset"]
    assert gap_main(args) == 2
    assert "logs without rotor speeds need a command -> speed map" in capsys.readouterr().err
    out = tmp_path / "gap.json"
    assert gap_main(args + ["--command-reference", *map(str, ref), "--json", str(out)]) == 0
    assert out.exists()
