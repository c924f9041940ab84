"""Flight-log loader/writer: round trip, determinism, and each bad input the loader rejects."""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import numpy as np
import pytest

from quadsim.core.errors import InputError, QuadsimWarning
from quadsim.core.frames import euler_to_quat
from quadsim.logs.flightlog import FlightLog, body_rate_from_quat, load_log, write_log

REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "crazyflie21_brushless"


def _log(n: int = 200, rotors: int = 4) -> FlightLog:
    """A synthetic flight: slow yaw spin and a climb, all columns present."""
    t = np.arange(n) * 0.01
    yaw_rate = 0.5
    quat = euler_to_quat(np.stack([np.zeros(n), np.zeros(n), yaw_rate * t], -1))
    position = np.stack([np.sin(t), np.cos(t), 0.1 * t], -1)
    velocity = np.stack([np.cos(t), -np.sin(t), np.full(n, 0.1)], -1)
    body_rate = np.tile([0.0, 0.0, yaw_rate], (n, 1))
    accel = np.tile([0.0, 0.0, 9.81], (n, 1))
    speed = np.full((n, rotors), 1500.0) + np.arange(rotors)
    command = np.full((n, rotors), 0.4)
    return FlightLog(t=t, position=position, quat=quat, velocity=velocity, body_rate=body_rate,
                     accel=accel, rotor_speed=speed, rotor_command=command,
                     vbat=np.linspace(4.1, 3.9, n))


def _write_text(tmp_path: Path, text: str, name: str = "bad.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _csv(log: FlightLog, tmp_path: Path) -> list[str]:
    path = write_log(tmp_path / "good.csv", log)
    return path.read_text().splitlines()


def test_round_trip_and_bytes_deterministic(tmp_path):
    log = _log()
    a = write_log(tmp_path / "a.csv.gz", log)
    b = write_log(tmp_path / "b.csv.gz", log)
    assert a.read_bytes() == b.read_bytes()
    assert gzip.decompress(a.read_bytes()).startswith(b"t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx")
    back = load_log(a)
    for name in ("t", "position", "velocity", "quat", "body_rate", "accel", "rotor_speed",
                 "rotor_command", "vbat"):
        # %.10g keeps 10 significant digits
        np.testing.assert_allclose(getattr(back, name), getattr(log, name), rtol=1e-9, atol=1e-12)
    assert back.rotor_count == 4 and back.notes == ()


def test_to_trajectory_differentiates_missing_signals():
    full = _log()
    bare = FlightLog(t=full.t, position=full.position, quat=full.quat)
    traj = bare.to_trajectory()
    # central differences of sin/cos at 10 ms: error ~ h^2/6 ~ 2e-5 (interior samples)
    np.testing.assert_allclose(traj.velocity[1:-1], full.velocity[1:-1], atol=1e-4)
    np.testing.assert_allclose(traj.body_rate[1:-1], full.body_rate[1:-1], atol=1e-4)
    assert traj.rotor_speed.shape == (len(full.t), 0)


def test_body_rate_from_quat_ignores_sign_flips():
    log = _log()
    quat = log.quat.copy()
    quat[50:] *= -1.0  # same attitude, opposite sign
    np.testing.assert_allclose(body_rate_from_quat(log.t, quat)[1:-1], log.body_rate[1:-1],
                               atol=1e-4)


@pytest.mark.parametrize("column, says", [("t", "required column missing"),
                                          ("x", "missing while y, z present"),
                                          ("qw", "required with a position")])
def test_missing_required_column(tmp_path, column, says):
    lines = _csv(_log(), tmp_path)
    header = lines[0].split(",")
    keep = [i for i, h in enumerate(header) if h != column]
    text = "\n".join(",".join(line.split(",")[i] for i in keep) for line in lines)
    with pytest.raises(InputError, match=rf"bad.csv: {column}: {says}"):
        load_log(_write_text(tmp_path, text))


def _edit(tmp_path, column: str, row: int, value: str) -> Path:
    lines = _csv(_log(), tmp_path)
    index = lines[0].split(",").index(column)
    cells = lines[row].split(",")
    cells[index] = value
    lines[row] = ",".join(cells)
    return _write_text(tmp_path, "\n".join(lines))


def test_time_not_increasing(tmp_path):
    with pytest.raises(InputError, match=r"bad.csv: t: line 11: time .* does not increase"):
        load_log(_edit(tmp_path, "t", 10, "0.05"))


def test_nan_in_required_column_is_an_error(tmp_path):
    with pytest.raises(InputError, match=r"bad.csv: y: line 31: non-finite value"):
        load_log(_edit(tmp_path, "y", 30, "nan"))


def test_nan_run_in_optional_column_warns(tmp_path):
    lines = _csv(_log(), tmp_path)
    index = lines[0].split(",").index("wx")
    for row in range(40, 45):
        cells = lines[row].split(",")
        cells[index] = "inf" if row == 40 else ""
        lines[row] = ",".join(cells)
    path = _write_text(tmp_path, "\n".join(lines))
    with pytest.warns(QuadsimWarning, match=r"bad.csv: wx: line 41: .*run of 5 sample"):
        log = load_log(path)
    assert np.isnan(log.body_rate[39:44, 0]).all() and np.isfinite(log.body_rate[44, 0])
    quiet = load_log(path, warn=False)
    assert len(quiet.notes) == 1 and "wx" in quiet.notes[0]


def test_sample_rate_jump_warns(tmp_path):
    lines = _csv(_log(), tmp_path)
    del lines[100:120]  # a 0.21 s dropout in 10 ms samples
    with pytest.warns(QuadsimWarning, match=r"t: line 101: sample-rate jump, step 0.21 s"):
        load_log(_write_text(tmp_path, "\n".join(lines)))


def test_not_a_number(tmp_path):
    with pytest.raises(InputError, match=r"bad.csv: vz: line 6: 'abc' is not a number"):
        load_log(_edit(tmp_path, "vz", 5, "abc"))


def test_rpm_instead_of_rad_s(tmp_path):
    log = _log()
    rpm = FlightLog(**{**log.__dict__, "rotor_speed": log.rotor_speed * 60 / (2 * np.pi)})
    path = write_log(tmp_path / "rpm.csv", rpm)
    with pytest.raises(InputError, match=r"rpm.csv: rotor_\*: line 2: .*looks like RPM"):
        load_log(path)


def test_degrees_instead_of_radians(tmp_path):
    log = _log()
    rate = log.body_rate.copy()
    rate[77] = [np.degrees(2.0), 0.0, 0.0]  # a 2 rad/s roll written as 114.6 deg/s
    path = write_log(tmp_path / "deg.csv", FlightLog(**{**log.__dict__, "body_rate": rate}))
    with pytest.raises(InputError, match=r"deg.csv: wx..wz: line 79: .*looks like deg/s"):
        load_log(path)


def test_g_instead_of_m_s2(tmp_path):
    log = _log()
    path = write_log(tmp_path / "g.csv", FlightLog(**{**log.__dict__, "accel": log.accel / 9.81}))
    with pytest.raises(InputError, match=r"g.csv: ax..az: .*looks like g"):
        load_log(path)


def test_milliseconds_or_microseconds_instead_of_seconds(tmp_path):
    """``t`` in ms (a 100 Hz log's 10 ms steps read as 10 s) or in us is refused naming the
    unit; a 2.5 Hz log (0.4 s steps, below MAX_TIME_STEP) passes the time check."""
    log = _log()
    step = float(np.median(np.diff(log.t)))
    for scale, unit in ((1e3, "milliseconds"), (1e6, "microseconds")):
        path = write_log(tmp_path / f"t{unit}.csv", FlightLog(**{**log.__dict__,
                                                              "t": log.t * scale}))
        told = re.escape(f"t{unit}.csv: t: median step {step * scale:.4g} s")
        with pytest.raises(InputError, match=rf"{told} .*looks like {unit}"):
            load_log(path)
    slow = FlightLog(**{**log.__dict__, "t": log.t * (0.4 / step)})
    try:        # its velocity no longer integrates to its positions: refused, but not for t
        load_log(write_log(tmp_path / "slow.csv", slow), warn=False)
    except InputError as exc:
        assert "slow.csv: t:" not in str(exc), exc


def test_non_unit_quaternion(tmp_path):
    with pytest.raises(InputError, match=r"bad.csv: qw..qz: line 4: quaternion norm"):
        load_log(_edit(tmp_path, "qw", 3, "0.5"))


def test_incomplete_group_and_ragged_row(tmp_path):
    lines = _csv(_log(), tmp_path)
    text = "\n".join(line.rsplit(",", 1)[0] if i == 0 else line for i, line in enumerate(lines))
    with pytest.raises(InputError, match=r"bad.csv: line 2: 26 fields, header has 25"):
        load_log(_write_text(tmp_path, text))
    header = lines[0].replace("vy,", "vyy,")
    with pytest.raises(InputError, match=r"bad.csv: vy: missing while vx, vz present"):
        load_log(_write_text(tmp_path, "\n".join([header] + lines[1:])))


def test_missing_file_is_one_line_error(tmp_path):
    with pytest.raises(InputError, match=r"nope.csv: no such file"):
        load_log(tmp_path / "nope.csv")


def test_real_crazyflie_log_loads():
    path = REAL / "nominal" / "flight_00.csv.gz"
    if not path.exists():
        pytest.skip(f"real data not found at {path} (../shared/data next to the repo)")
    log = load_log(path, warn=False)
    assert log.rotor_count == 4 and len(log) > 1000
    # hovering Crazyflie: specific force about g on body z; rotor speeds ~1.5e3 rad/s
    assert 9.0 < np.median(log.accel[:, 2]) < 10.6
    assert 1000 < np.median(log.rotor_speed) < 3000
    # logged gyro agrees with the rate differentiated from the mocap quaternions
    derived = body_rate_from_quat(log.t, log.quat)
    assert np.median(np.abs(derived - log.body_rate)) < 0.5


def test_minimal_log_with_bom_and_crlf(tmp_path):
    path = tmp_path / "min.csv"
    path.write_text("t,x,y,z,qw,qx,qy,qz\r\n0,0,0,1,1,0,0,0\r\n0.01,0,0,1.5,1,0,0,0\r\n",
                    encoding="utf-8-sig")
    log = load_log(path)
    assert log.velocity is None and log.rotor_count == 0
    np.testing.assert_allclose(log.position[:, 2], [1.0, 1.5])
    np.testing.assert_allclose(log.to_trajectory().velocity[:, 2], [50.0, 50.0])


def test_parquet_round_trip_is_exact_and_deterministic(tmp_path):
    pytest.importorskip("pyarrow")
    log = _log()
    a = write_log(tmp_path / "a.parquet", log)
    b = write_log(tmp_path / "b.parquet", log)
    assert a.read_bytes() == b.read_bytes()
    back = load_log(a)
    for name in ("t", "position", "velocity", "quat", "body_rate", "accel", "rotor_speed",
                 "rotor_command", "vbat"):
        np.testing.assert_array_equal(getattr(back, name), getattr(log, name))  # float64 kept
    # the same validation as CSV: RPM where rad/s is expected is refused, naming the column
    rpm = FlightLog(t=log.t, position=log.position, quat=log.quat,
                    rotor_speed=log.rotor_speed * 60 / (2 * np.pi) * 10)
    bad = write_log(tmp_path / "rpm.parquet", rpm)
    with pytest.raises(InputError, match=r"rpm\.parquet: rotor_\*: line 2: .*looks like RPM"):
        load_log(bad)


def test_corrupt_parquet_is_one_line_error(tmp_path):
    pytest.importorskip("pyarrow")
    path = tmp_path / "broken.parquet"
    path.write_bytes(b"PAR1 this is not parquet")
    with pytest.raises(InputError, match=r"broken\.parquet: not a readable Parquet file") as err:
        load_log(path)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("tail", [b"garbage-after-magic", b"\x00" * 64], ids=["text", "zeros"])
def test_corrupt_gzip_is_one_line_error(tmp_path, tail):
    """A .csv.gz whose bytes start with gzip's magic but whose deflate stream is corrupt
    (zlib.error, not an OSError) is refused in one line naming the file, like a truncated one
    (EOFError)."""
    path = tmp_path / "broken.csv.gz"
    path.write_bytes(b"\x1f\x8b\x08\x00" + tail)
    with pytest.raises(InputError, match=r"broken\.csv\.gz: gzip: corrupt data") as err:
        load_log(path)
    assert "\n" not in str(err.value)
    full = gzip.compress(b"t,x\n0,0\n")
    cut = tmp_path / "cut.csv.gz"
    cut.write_bytes(full[:-6])
    with pytest.raises(InputError, match=r"cut\.csv\.gz: gzip: corrupt data"):
        load_log(cut)
