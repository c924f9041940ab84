"""Importers under corrupted logs and the cases a new user hit: no hang, no traceback, no
silent garbage, no lost input. Each refusal: exit 2, one line naming the file and the field,
nothing written, the input unchanged. Logs are written here by each format's writer
(quadsim.logs.samples); the corruptions are the fuzzer's (benchmarks.corrupt)."""

from __future__ import annotations

import dataclasses
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from quadsim.convert import main as convert_main
from quadsim.core.bounded import Budget, run_bounded
from quadsim.core.errors import InputError, run_cli
from quadsim.logs.flightlog import FlightLog, load_log, write_log
from quadsim.logs.samples import dataflash_bytes, sample_flight, ulog_bytes, usd_bytes
from quadsim.logs.usd import encode_usd

pyulog = pytest.importorskip("pyulog", reason="pyulog not installed (quadsim[logs])")


from _helpers import one_line as _one_line  # noqa: E402


def _csv(path: Path, flight=None, **changes) -> Path:
    f = flight or sample_flight(duration_s=3.0, rate_hz=200.0)
    log = FlightLog(t=f.t, position=f.position, quat=f.quat, velocity=f.velocity,
                    body_rate=f.body_rate, accel=f.accel, rotor_speed=f.rotor_speed,
                    rotor_command=f.command, vbat=f.vbat)
    write_log(path, dataclasses.replace(log, **changes))
    return path


# ----------------------------------------------------------------------------- bounded parse


def test_pyulog_hang_reproduced_and_refused_within_its_budget(tmp_path, capsys, monkeypatch):
    import multiprocessing

    from benchmarks.corrupt import hanging_ulog_bytes
    from quadsim import logs

    path = tmp_path / "hang.ulg"
    path.write_bytes(hanging_ulog_bytes())
    # the hang itself: pyulog alone does not return within 3 s on these 546 bytes
    proc = multiprocessing.get_context("fork").Process(target=pyulog.ULog, args=(str(path),))
    proc.start()
    proc.join(3.0)
    hung = proc.is_alive()
    proc.kill()
    proc.join()
    assert hung
    monkeypatch.setattr(logs, "PARSE_TIME_S", 2.0)
    monkeypatch.setattr(logs, "PARSE_TIME_S_PER_MB", 0.0)
    out = tmp_path / "out.csv"
    began = time.perf_counter()
    assert convert_main([str(path), "-o", str(out)]) == 2
    assert time.perf_counter() - began < 2.0 + 3.0   # the budget plus start-up
    _one_line(capsys, str(path), "no result within 2 s")
    assert not out.exists()


def test_memory_budget_refuses_a_runaway_allocation(tmp_path):
    def allocate():
        return bytearray(3 * 1024**3)   # 3 GiB against a 0.5 GiB budget

    with pytest.raises(InputError, match="x.bin: test: over the memory budget of 0.5 GiB"):
        run_bounded(allocate, label="x.bin", what="test",
                    budget=Budget(time_s=20, memory_bytes=2**29))


def test_library_output_is_one_note_not_terminal_lines(tmp_path, capfd):
    data = bytearray(dataflash_bytes(sample_flight(duration_s=3.0)))
    data[20000:20040] = bytes(range(40))          # pymavlink reports and skips these
    path = tmp_path / "noisy.bin"
    path.write_bytes(bytes(data))
    out = tmp_path / "out.csv"
    code = convert_main([str(path), "-o", str(out)])
    captured = capfd.readouterr()
    lines = captured.err.strip().splitlines()
    assert all(line.startswith(("warning: ", "error: ")) for line in lines), lines
    assert captured.out.count("\n") <= 1 and "bad header" not in captured.out
    if code == 0:
        assert any("framing: lost" in line for line in lines), lines


def test_messages_never_echo_raw_file_bytes(tmp_path, capsys):
    path = tmp_path / "ctl"  # an event name with an escape sequence and a newline
    path.write_bytes(encode_usd({"fixed\x1b[31m\nEVIL": (7, [("x", "f")], [(0, (1.0,))])}))
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 2
    err = _one_line(capsys, str(path))
    assert "\x1b" not in err and "\\x1b" in err


def test_numpy_warnings_become_one_collapsed_line(capsys):
    @run_cli
    def main(argv=None):
        for _ in range(1000):
            np.log(np.zeros(1))
        return 0

    assert main([]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["warning: RuntimeWarning: divide by zero encountered in log"]


# ----------------------------------------------------------------------------- fuzz sample


@pytest.mark.parametrize("fmt,count", [("ulog", 110), ("usd", 150), ("dataflash", 40)])
def test_fuzz_sample_no_garbage_uncaught_or_hang(tmp_path, fmt, count):
    """300 deterministic corruptions (a slice of benchmarks/fuzz_logs.py), the importer in one
    bounded worker per format: every case a clean refusal or a plausible log."""
    from benchmarks.corrupt import judge_batch

    results, _ = run_bounded(judge_batch, fmt, list(range(count)), str(tmp_path),
                             label=fmt, what="fuzz batch", budget=Budget(time_s=120))
    bad = [r for r in results if r[1] not in ("refusal", "plausible")]
    assert not bad, bad[:5]
    outcomes = {r[1] for r in results}
    assert outcomes == {"refusal", "plausible"}   # both kinds occur: the judge can tell


def test_fuzz_cases_through_the_worker(tmp_path):
    from benchmarks.corrupt import judge, make_case

    for fmt in ("ulog", "dataflash"):
        for index in range(4):
            outcome, message = judge(make_case(fmt, index), tmp_path, time_s=20.0)
            assert outcome in ("refusal", "plausible"), (fmt, index, message)


# ----------------------------------------------------------------------------- validation


def test_clean_sample_logs_load_exactly(tmp_path):
    pytest.importorskip("pymavlink")
    flight = sample_flight()
    for name, data in (("a.ulg", ulog_bytes(flight)), ("a.bin", dataflash_bytes(flight)),
                       ("a00", usd_bytes(flight))):
        (tmp_path / name).write_bytes(data)
        log = load_log(tmp_path / name, warn=False)
        assert len(log) == len(flight.t) and log.notes == ()
        np.testing.assert_allclose(log.position, flight.position, atol=1e-6)
        np.testing.assert_allclose(log.quat, flight.quat, atol=1e-6)
        np.testing.assert_allclose(log.accel, flight.accel, atol=1e-5)


@pytest.mark.parametrize("name,value,field", [
    ("CA_ROTOR_COUNT", float("nan"), "CA_ROTOR_COUNT"), ("MAV_TYPE", float("inf"), "MAV_TYPE"),
    ("CA_ROTOR_COUNT", 1e9, "CA_ROTOR_COUNT")])
def test_ulog_parameters_validated_like_user_input(tmp_path, capsys, name, value, field):
    path = tmp_path / "p.ulg"
    path.write_bytes(ulog_bytes(sample_flight(), params={name: value}))
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 2
    _one_line(capsys, str(path), field, "parameter")


@pytest.mark.parametrize("name,value", [("FRAME_CLASS", float("nan")), ("FRAME_CLASS", 6.0),
                                        ("MOT_PWM_MIN", float("inf"))])
def test_dataflash_parameters_validated_like_user_input(tmp_path, capsys, name, value):
    pytest.importorskip("pymavlink")
    path = tmp_path / "p.bin"
    path.write_bytes(dataflash_bytes(sample_flight(), params={name: value}))
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 2
    _one_line(capsys, str(path), name)


@pytest.mark.parametrize("scale", [2.0, 0.0, 1e30])
def test_ulog_quaternions_checked_before_normalisation(tmp_path, capsys, scale):
    flight = sample_flight()
    quat = flight.quat.copy()
    quat[50] *= scale
    path = tmp_path / "q.ulg"
    path.write_bytes(ulog_bytes(dataclasses.replace(flight, quat=quat)))
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 2
    _one_line(capsys, str(path), "vehicle_attitude.q", "sample 50")


@pytest.mark.parametrize("signal,value,field", [
    ("position", 1e13, "x..z"), ("velocity", 5e3, "vx..vz"), ("accel", 1e4, "ax..az"),
    ("vbat", -550.0, "vbat")])
def test_physical_ranges_refused_after_import(tmp_path, capsys, signal, value, field):
    flight = sample_flight()
    array = np.array(getattr(flight, signal), dtype=float)
    array[40] = value
    if signal == "vbat":  # the uSD and ULog writers cannot store -550 V: a CSV
        path = _csv(tmp_path / "r.csv", flight=flight, vbat=array)
    else:
        path = tmp_path / "r.ulg"
        path.write_bytes(ulog_bytes(dataclasses.replace(flight, **{signal: array})))
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 2
    _one_line(capsys, str(path), field)


def test_position_jump_refused(tmp_path, capsys):
    flight = sample_flight()
    position = flight.position.copy()
    position[60:, 0] += 50.0          # 50 m in 10 ms
    path = _csv(tmp_path / "j.csv", flight=flight, position=position)
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 2
    _one_line(capsys, str(path), "x..z", "m/s")


def test_optional_topic_with_equal_timestamps_does_not_trim_the_flight(tmp_path):
    """battery_status with every timestamp equal: left out with a note, the flight kept."""
    flight = sample_flight()
    data = ulog_bytes(flight)
    ulog = pyulog.ULog(__import__("io").BytesIO(data))
    for d in ulog.data_list:
        if d.name == "battery_status":
            d.data["timestamp"][:] = d.data["timestamp"][0]
    buffer = __import__("io").BytesIO()
    ulog.write_ulog(buffer)
    path = tmp_path / "eq.ulg"
    path.write_bytes(buffer.getvalue())
    log = load_log(path, warn=False)
    assert len(log) == len(flight.t) and log.vbat is None
    assert any("battery_status" in n and "lost" in n for n in log.notes), log.notes


def test_truncated_ulog_states_the_bytes_lost(tmp_path):
    data = ulog_bytes(sample_flight())
    path = tmp_path / "cut.ulg"
    path.write_bytes(data[:len(data) // 2 + 7])
    log = load_log(path, warn=False)
    assert len(log) < 0.6 * 201
    assert any("framing: lost bytes" in n for n in log.notes), log.notes


def test_damaged_magic_is_named_not_read_as_csv(tmp_path, capsys):
    data = bytearray(ulog_bytes(sample_flight()))
    data[1] ^= 0xFF
    path = tmp_path / "bad.ulg"
    path.write_bytes(bytes(data))
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 2
    err = _one_line(capsys, str(path), "header", "ULog magic")
    assert "UTF-8" not in err


# ----------------------------------------------------------------------------- user-hit cases


def test_gap_on_a_one_second_log(tmp_path, capsys):
    from quadsim.gap.__main__ import main as gap

    path = _csv(tmp_path / "short.csv", flight=sample_flight(duration_s=1.0, rate_hz=500.0))
    out = tmp_path / "gap.json"
    assert gap(["--model", "crazyflie21", str(path), "--quiet", "--workers", "1",
                "--json", str(out)]) == 2
    _one_line(capsys, str(path), "t:", "at least 2 s")
    assert not out.exists()


def test_gap_window_shorter_than_the_samples(tmp_path, capsys):
    from quadsim.gap.__main__ import main as gap

    path = _csv(tmp_path / "f.csv")
    assert gap(["--model", "crazyflie21", str(path), "--quiet", "--window", "0.0001"]) == 2
    _one_line(capsys, "--window 0.0001")


def test_gap_copy_of_a_training_flight_as_holdout(tmp_path, capsys):
    from quadsim.gap.__main__ import main as gap

    path = _csv(tmp_path / "train.csv")
    copy = tmp_path / "copy.csv"
    copy.write_bytes(path.read_bytes())
    assert gap(["--model", "crazyflie21", str(path), "--holdout", str(copy), "--quiet"]) == 2
    _one_line(capsys, str(copy), "same bytes as")


def test_json_into_a_missing_folder_creates_nothing(tmp_path, capsys):
    from quadsim.gap.__main__ import main as gap

    path = _csv(tmp_path / "f.csv")
    target = tmp_path / "nonexistent" / "dir" / "out.json"
    assert gap(["--model", "crazyflie21", str(path), "--json", str(target), "--quiet"]) == 2
    _one_line(capsys, str(target), "does not exist")
    assert not (tmp_path / "nonexistent").exists()


def test_convert_refuses_to_overwrite_its_input(tmp_path, capsys):
    path = _csv(tmp_path / "in.csv")
    before = path.read_bytes()
    assert convert_main([str(path), "-o", str(path), "--start", "1", "--end", "2"]) == 2
    _one_line(capsys, str(path), "also an input")
    assert path.read_bytes() == before


@pytest.mark.parametrize("rate,match", [("1e9", "must be <= 100000"), ("0", "must be > 0")])
def test_convert_rate_checked_before_any_work(tmp_path, capsys, rate, match):
    path = tmp_path / "f.ulg"
    path.write_bytes(ulog_bytes(sample_flight()))
    out = tmp_path / "o.csv"
    assert convert_main([str(path), "-o", str(out), "--rate", rate]) == 2
    _one_line(capsys, "--rate", match)
    assert not out.exists()


def test_convert_keeps_absolute_time_at_full_precision(tmp_path):
    flight = sample_flight(duration_s=2.0, rate_hz=500.0)
    source = _csv(tmp_path / "abs.csv", flight=flight, t=flight.t + 1.7e9)
    out = tmp_path / "out.csv"
    assert convert_main([str(source), "-o", str(out)]) == 0
    log = load_log(out)
    assert len(np.unique(log.t)) == len(flight.t)
    np.testing.assert_allclose(log.t - 1.7e9, flight.t, atol=1e-6)


@pytest.mark.parametrize("scale,hint", [(1000.0, "mm"), (100.0, "cm")])
def test_positions_in_mm_with_velocity_in_m_s(tmp_path, capsys, scale, hint):
    flight = sample_flight(duration_s=3.0, rate_hz=200.0)
    path = _csv(tmp_path / "mm.csv", flight=flight, position=flight.position * scale)
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 2
    _one_line(capsys, str(path), "x..z", f"positions in {hint}?")


def test_vtol_ulog_noted_and_refused_against_a_multirotor_set(tmp_path, capsys):
    path = tmp_path / "vtol.ulg"
    path.write_bytes(ulog_bytes(sample_flight(), params={"MAV_TYPE": 22}))
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 0
    assert "warning: " in capsys.readouterr().err and "VTOL" in load_log(
        path, warn=False).notes[0]
    out = tmp_path / "o2.csv"
    assert convert_main([str(path), "-o", str(out), "--model", "crazyflie21"]) == 2
    _one_line(capsys, str(path), "vehicle", "VTOL, not a multirotor")
    assert not out.exists()


def test_drag_factor_x1000_refused(tmp_path, capsys):
    from quadsim.vehicle.params import load_params

    text = Path(load_params("crazyflie21").path).read_text()
    assert "value = 2.2217e-10" in text
    model = tmp_path / "d1000.toml"
    model.write_text(text.replace("value = 2.2217e-10", "value = 2.2217e-07"))
    path = _csv(tmp_path / "f.csv")
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv"), "--model", str(model)]) == 2
    _one_line(capsys, str(model), "rotors.drag_factor", "figure of merit 0.00042")


def test_fly_negative_mass_offset(tmp_path, capsys):
    from quadsim.fly import main as fly

    out = tmp_path / "f.csv.gz"
    assert fly(["--model", "physical", "--path", "hover", "--effect", "mass_offset:mass=-1",
                "-o", str(out), "--quiet"]) == 2
    _one_line(capsys, "mass_offset", "-0.1623 kg")
    assert not out.exists()


def test_sweep_too_large_refused_before_any_work(tmp_path, capsys):
    pytest.importorskip("pyarrow")
    from quadsim.sweep.__main__ import main as sweep

    out = tmp_path / "s.parquet"
    began = time.perf_counter()
    assert sweep(["--effect", "mass_offset:mass=0..0.1", "--samples", "100000000",
                  "-o", str(out), "--workers", "2"]) == 2
    assert time.perf_counter() - began < 5.0
    _one_line(capsys, "--samples", "1e+08 simulations", "--allow-large")
    assert not out.exists()


def test_rotor_order_refused_with_the_map_to_use():
    """A generated figure-8 (crazyflie21, 200 Hz, gyro noise 0.01 rad/s); PX4's order fed
    as the set's order is refused naming --rotor-map 1,4,2,3; the true order passes."""
    from quadsim.effects import EffectSet
    from quadsim.logs.checks import check_rotor_order
    from quadsim.logs.generate import generate_flight
    from quadsim.logs.sensors import SensorModel
    from quadsim.vehicle.params import load_params

    params = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = generate_flight(params, "figure8", EffectSet(),
                                 SensorModel(noise={"gyro": 0.01}), 0, duration=6.0)
    check_rotor_order(log, params)
    px4 = dataclasses.replace(log, rotor_speed=log.rotor_speed[:, [0, 2, 3, 1]])
    with pytest.raises(InputError, match=r"rotor_\*: rotor order: .*--rotor-map 1,4,2,3"):
        check_rotor_order(px4, params)


def test_body_rate_in_the_world_frame_refused():
    """A real nominal Crazyflie flight (skips without ../shared/data): its gyro passes; the
    same rates turned into the world frame are refused as such."""
    from quadsim.core.frames import quat_to_rotmat
    from quadsim.logs.checks import check_gyro, cut_nan

    path = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
            / "crazyflie21_brushless" / "nominal" / "flight_10.csv.gz")
    if not path.exists():
        pytest.skip(f"real data not found at {path}")
    log, _ = cut_nan(load_log(path, warn=False))
    assert check_gyro(log) is None
    world = np.einsum("nij,nj->ni", quat_to_rotmat(log.quat), log.body_rate)
    with pytest.raises(InputError, match=r"wx..wz: .*world frame"):
        check_gyro(dataclasses.replace(log, body_rate=world))


def test_scalar_last_quaternion_named_and_a_true_axis_swap_kept():
    """A generated flight's quaternions written scalar-last under the scalar-first names
    (x, y, z, w in qw..qz) are refused naming qw..qz and the order; the gyro's x and y
    swapped instead keep their own message ("axes swapped?"); the log as written passes."""
    from quadsim.effects import EffectSet
    from quadsim.logs.checks import check_gyro
    from quadsim.logs.generate import generate_flight
    from quadsim.logs.sensors import SensorModel
    from quadsim.vehicle.params import load_params

    params = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = generate_flight(params, "figure8", EffectSet(),
                                 SensorModel(noise={"gyro": 0.01}), 0, duration=6.0)
    assert check_gyro(log) is None
    xyzw = dataclasses.replace(log, quat=log.quat[:, [1, 2, 3, 0]])
    with pytest.raises(InputError, match=r"qw..qz: the gyro follows the attitude only with "
                                         r"the quaternion columns read as x, y, z, w"):
        check_gyro(xyzw)
    swapped = dataclasses.replace(log, body_rate=log.body_rate[:, [1, 0, 2]])
    with pytest.raises(InputError, match=r"w[xy]: gyro w[xy] follows the attitude's [xy] "
                                         r"axis .*axes swapped\?"):
        check_gyro(swapped)


def test_time_in_ms_names_the_time_column(tmp_path, capsys):
    flight = sample_flight(duration_s=3.0, rate_hz=200.0)
    path = _csv(tmp_path / "ms.csv", flight=flight, t=flight.t * 1000.0)
    assert convert_main([str(path), "-o", str(tmp_path / "o.csv")]) == 2
    _one_line(capsys, str(path), ": t: ", "looks like milliseconds")
