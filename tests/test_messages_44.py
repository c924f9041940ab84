"""Messages that name the real problem (issue 44, item 7), each as a user meets it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from quadsim.core.errors import InputError
from quadsim.logs.checks import check_rotors
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import load_params

SKELETON = Path(__file__).resolve().parents[1] / "docs" / "examples" / "cf_imu_skeleton.toml"


def _hover(speed: float, n: int = 200) -> FlightLog:
    t = np.arange(n) * 0.01
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return FlightLog(t, np.zeros((n, 3)), quat, accel=np.tile([0.0, 0.0, 9.81], (n, 1)),
                     rotor_speed=np.full((n, 4), speed))


def test_another_vehicles_log_is_named_as_such():
    """A PX4 Iris log (rotors near 500 rad/s) against crazyflie21: not "Hz as rad/s"."""
    params = load_params("crazyflie21")
    with pytest.raises(InputError, match=r"a log of another vehicle than .*crazyflie21.* "
                                         r"\(its rotors reach 500 rad/s, the set's max_speed"):
        check_rotors(_hover(500.0), params)


def test_a_unit_error_is_named_as_such():
    params = load_params("crazyflie21")
    hover = float(np.sqrt(params.mass * 9.81 / 4 / params.thrust_factor))     # rad/s
    with pytest.raises(InputError, match=r"RPM logged as rad/s\?"):
        check_rotors(_hover(hover * 60 / (2 * np.pi)), params)
    with pytest.raises(InputError, match=r"Hz logged as rad/s\?"):
        check_rotors(_hover(hover / (2 * np.pi)), params)
    check_rotors(_hover(hover), params)                      # the right unit passes


def test_openloop_writes_nothing_it_was_not_asked_for(tmp_path, monkeypatch, capsys):
    from quadsim.openloop import main as openloop_main

    monkeypatch.chdir(tmp_path)
    assert openloop_main(["--model", "physical", "--duration", "0.5", "--step-time", "0.1",
                          "--json"]) == 0
    assert list(tmp_path.iterdir()) == []


def test_a_toml_given_as_a_log_says_so(tmp_path):
    from quadsim.logs.flightlog import load_log

    path = tmp_path / "skeleton.toml"
    path.write_text('schema = "quadsim.vehicle.params/1"\n[body]\nmass = 1\n')
    with pytest.raises(InputError, match=r"skeleton.toml: header: a TOML file \(a parameter "
                                         r"set or skeleton\?\), not a flight log: were the log "
                                         r"and the vehicle arguments swapped\?"):
        load_log(path)


def test_a_stored_reference_given_as_a_log_says_so(tmp_path):
    """A ``.qref`` (``gap --write-reference``: a JSON header line, then a pickle) given where a
    flight log goes (``gap --per-flight X.qref``, ``view --log``, ``identify --logs``) was
    "not a UTF-8 text (CSV) file"; it is named, with where it goes."""
    from quadsim.logs import file_kind
    from quadsim.logs.flightlog import load_log

    path = tmp_path / "mine.qref"
    path.write_bytes(b'{"schema": "quadsim.gap.reference/1", "format": 1}\n'
                     b"\x80\x04\x95\x00\x00\x00\x00")
    assert file_kind(path) == "a quadsim stored reference (.qref)"
    shipped = Path(__file__).resolve().parents[1] / "models" / "references" / "crazyflie21.qref"
    assert file_kind(shipped) == "a quadsim stored reference (.qref)"     # as written
    with pytest.raises(InputError, match=r"mine.qref: header: a quadsim stored reference "
                                         r"\(\.qref\), not a flight log: give it to "
                                         r"quadsim.gap as --reference") as err:
        load_log(path)
    assert "\n" not in str(err.value)


def test_file_kind_names_logs_by_their_bytes(tmp_path):
    import gzip

    from quadsim.logs import file_kind

    gz = tmp_path / "f.csv.gz"
    gz.write_bytes(gzip.compress(b"t,x\n0,1\n"))
    assert file_kind(gz) == "a gzip-compressed file (a .csv.gz flight log?)"
    csv = tmp_path / "f.csv"
    csv.write_text("t,ax,ay\n0,1,2\n")
    assert file_kind(csv) == "a CSV flight log"
    assert file_kind(tmp_path / "missing") is None


def test_binary_bytes_with_a_bracket_are_no_toml_file(tmp_path):
    """A damaged or foreign binary named ``.csv.gz`` (not gzip) whose bytes happen to hold a
    newline then ``[`` was called "a TOML file ... were the log and the vehicle arguments
    swapped?" by ``gap``, ``view`` and ``identify --logs``; it is refused by its first bytes,
    as ``convert`` refuses it."""
    from quadsim.logs import file_kind
    from quadsim.logs.flightlog import load_log

    path = tmp_path / "flight.csv.gz"
    path.write_bytes(bytes([0x92, 0xEA, 0x8E, 0x05, 0x00, 0x0A]) + b"[\x00\xff" + bytes(64))
    assert file_kind(path) is None
    with pytest.raises(InputError, match=r"flight.csv.gz: header: first bytes 92ea8e05000a5b00 "
                                         r"match no log format"):
        load_log(path)


def test_rotor_order_status_confirmed_doubtful_or_not_told():
    """Generated figure-8 (crazyflie21, 6 s): the right order confirmed from rotor speeds
    and from commands alone; rotors 1 and 2 swapped doubtful, naming the map that fixes it."""
    import dataclasses
    import warnings

    from quadsim.effects import EffectSet
    from quadsim.logs.checks import rotor_order_status
    from quadsim.logs.generate import generate_flight
    from quadsim.logs.sensors import SensorModel

    params = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = generate_flight(params, "figure8", EffectSet(), SensorModel(noise={"gyro": 0.01}),
                                 0, duration=6.0, speed=1.0)
    own = rotor_order_status(log, params)
    assert own.confirmed and not own.doubtful and own.evidence < -25 and own.note == ""
    swapped = rotor_order_status(dataclasses.replace(
        log, rotor_speed=log.rotor_speed[:, [1, 0, 2, 3]]), params)
    assert swapped.doubtful and swapped.rival == (1, 0, 2, 3)
    assert "--rotor-map 2,1,3,4 fits better" in swapped.note
    commands = dataclasses.replace(log, rotor_speed=None,
                                   rotor_command=log.rotor_command[:, [1, 0, 2, 3]])
    status = rotor_order_status(commands, params)
    assert status.source == "commands" and status.doubtful


def test_skeleton_mass_in_grams_names_body_mass(tmp_path):
    from quadsim.identify.sanity import check_mass_scale
    from quadsim.identify.skeleton import load_skeleton

    text = SKELETON.read_text().replace(
        "value = 0.027", "value = 27")
    path = tmp_path / "grams.toml"
    path.write_text(text)
    skeleton, _ = load_skeleton(path)
    with pytest.raises(InputError, match=r"grams.toml: body.mass: 27 kg on rotors 0.0396 m "
                                         r"from the centre .*grams given as kg\? \(0.027 kg"):
        check_mass_scale(skeleton)
    check_mass_scale(load_skeleton(SKELETON)[0])   # 0.027 kg ok


def test_negative_r2_says_what_it_means():
    from quadsim.identify.sanity import r2_text

    assert r2_text(0.5) == "R^2 0.500"
    assert r2_text(-8.902).startswith("R^2 -8.902 (below 0: the fit predicts these samples "
                                      "worse than their mean does")


def test_swapped_logs_and_vehicle_are_named(tmp_path):
    import gzip

    from quadsim.identify.sanity import check_swapped

    log = tmp_path / "f.csv.gz"
    log.write_bytes(gzip.compress(b"t,x\n0,1\n"))
    skeleton = SKELETON
    with pytest.raises(InputError, match=r"f.csv.gz: --vehicle: a gzip-compressed file \(a "
                                         r"\.csv\.gz flight log\?\), not a skeleton TOML: "
                                         r"--logs and --vehicle swapped\?"):
        check_swapped([skeleton], log)
    check_swapped([log], skeleton)


def test_gap_help_lists_every_format(capsys):
    from quadsim.gap.__main__ import main as gap_main

    with pytest.raises(SystemExit):
        gap_main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    for name in ("CSV", ".csv.gz", "Parquet", "PX4 ULog", "Crazyflie uSD", "ArduPilot DataFlash"):
        assert name in text, name


def test_a_doubtful_rotor_order_makes_the_verdict_tentative_and_capped():
    """Per-flight on generated figure-8s: rotors 1 and 2 swapped in the judged flight (not
    refused here: called below the CLI's checks) -> tentative, at most 99 %, the note and
    the --rotor-map that fits better in the answer; the right order is confirmed."""
    import dataclasses
    import warnings

    from quadsim.effects import EffectSet
    from quadsim.gap.diagnose import diagnose_per_flight
    from quadsim.logs.generate import generate_flight
    from quadsim.logs.sensors import SensorModel

    params = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        flights = [generate_flight(params, "figure8", EffectSet(),
                                   SensorModel(noise={"gyro": 0.01}), seed, duration=6.0,
                                   speed=1.0)[0] for seed in (0, 1, 2, 7)]
    one = flights[3]
    swapped = dataclasses.replace(one, rotor_speed=one.rotor_speed[:, [1, 0, 2, 3]],
                                  rotor_command=one.rotor_command[:, [1, 0, 2, 3]])
    result = diagnose_per_flight([one, swapped], flights[:3], params)
    right, wrong = result.flights
    assert not right.tentative or right.outcome == "effect"
    assert wrong.tentative and wrong.probability <= 0.99
    assert "--rotor-map 2,1,3,4" in wrong.answer and "a wrong rotor order" in wrong.answer
    assert any("rotor order not confirmed" in n for n in wrong.notes)
    assert not any("rotor order" in n for n in right.notes)


def test_the_px4_iris_log_against_crazyflie21_is_another_vehicle():
    """The issue's case: PX4 SITL Iris rotors (~306 rad/s) against crazyflie21
    read 'Hz logged as rad/s?' (x 2 pi lands within max_speed); undone, the thrust is still
    1.5x the need: another vehicle."""
    params = load_params("crazyflie21")
    with pytest.raises(InputError, match="a log of another vehicle"):
        check_rotors(_hover(306.0), params)          # undone as Hz: 1.5x the need


def test_ctrl_c_while_a_command_starts_is_one_line(capsys):
    import signal

    import quadsim

    with pytest.raises(SystemExit) as stop:
        quadsim._interrupted_while_starting(signal.SIGINT, None)
    assert stop.value.code == 130
    assert capsys.readouterr().err == "error: interrupted\n"
    # imported as a library (here, by pytest), the package leaves Ctrl-C alone
    assert signal.getsignal(signal.SIGINT) is not quadsim._interrupted_while_starting


def test_a_held_out_result_never_contradicts_its_own_evidence():
    """Held out, each reading's ``log_evidence`` is what its probability weighs (training
    evidence plus the held-out log-likelihood): a reading more than 10 nats of evidence
    above another (more than any prior ratio or count of variants) is never less probable.
    The issue's case: ``no_difference`` at -1722.6 with probability 1.0 against a reading at
    -1045.9 with 1.7e-17."""
    from benchmarks.synthetic import synthetic_flight
    from quadsim.effects import make_effect
    from quadsim.gap import diagnose

    cf = load_params("crazyflie21")
    heavy = [make_effect("mass_offset", mass=0.003)]
    train = [synthetic_flight(cf, heavy, seed=s, duration=4.0) for s in (3, 4)]
    held = [synthetic_flight(cf, heavy, seed=5, duration=4.0)]
    rows = diagnose(train, cf, holdout=held, effects=["mass_offset", "com_offset",
                                                        "thrust_mismatch"])["verdict"]["posterior"]
    assert len(rows) >= 3
    for a in rows:
        for b in rows:
            if a["log_evidence"] > b["log_evidence"] + 10.0:
                assert a["probability"] >= b["probability"], (a["name"], b["name"])
    assert rows[0]["name"] == "mass_offset"


def test_per_flight_with_every_flight_refused_is_one_line_and_exit_2(tmp_path, capsys):
    """``gap --per-flight`` on logs that all fail to load judged nothing, yet printed a batch
    answer "0 flights judged against the reference flights: ; 2 refused" and exited 0: now
    the first refusal in one line (with the others named), exit 2, nothing written."""
    from quadsim.gap.__main__ import main

    first, second = tmp_path / "a.csv", tmp_path / "b.csv"
    first.write_text("x,y,z\n0,0,0\n1,0,0\n")                       # no t column
    second.write_text("t,x,y,z\n")                                 # no rows
    out = tmp_path / "out.json"
    assert main(["--model", "crazyflie21", "--per-flight", str(first), str(second),
                 "--json", str(out), "--quiet", "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    assert err[0].startswith(f"error: {first}: t: required column missing (time in s) (and 1 "
                             f"more flight(s) refused: {second})")
    assert not out.exists()


def test_help_texts_say_what_the_flags_do(capsys):
    """``openloop --help`` said it "saves PNGs" (only with ``--plots DIR``; none by default)
    and ``sweep --help`` called ``--quiet`` "no progress bar" (it also drops the closing
    "wrote ..." line, ``tests/test_sweep.py``)."""
    from quadsim.openloop import main as openloop
    from quadsim.sweep.__main__ import main as sweep

    for main in (openloop, sweep):
        with pytest.raises(SystemExit):
            main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "saves PNGs" not in text and "PNGs with --plots DIR" in text
    assert "--quiet no progress bar and no closing summary line" in text


def test_logs_swallowed_by_a_list_flag_are_named(tmp_path, capsys):
    """README's form ``gap --model M --command-reference REF... LOG...`` hands LOG... to
    ``--command-reference`` (a list flag takes every file after it); the refusal said only
    "give the flight logs to judge". It now says where they went."""
    from quadsim.gap.__main__ import main

    ref, log = tmp_path / "ref.csv", tmp_path / "log.csv"
    for path in (ref, log):
        path.write_text("t,ax\n0,1\n")
    assert main(["--model", "crazyflie21", "--command-reference", str(ref), str(log)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: LOG: give the flight logs to judge (or only --reference LOG... "
                   "--write-reference OUT.qref to write a stored reference); "
                   "--command-reference takes every file after it: give the flight logs "
                   "before it"]


def test_a_binary_file_given_as_a_toml_is_named_by_its_bytes(tmp_path):
    """``gap --model flight.csv.gz`` said "cannot read: 'utf-8' codec can't decode byte 0x8b
    in position 1: invalid start byte"; the file is now named for what it is."""
    import gzip

    from quadsim.vehicle.params import load_params

    log = tmp_path / "flight_00.csv.gz"
    log.write_bytes(gzip.compress(b"t,x\n0,1\n"))
    with pytest.raises(InputError, match=r"^\S*flight_00.csv.gz: header: not a TOML text file: "
                                         r"gzip-compressed \(a .csv.gz flight log\?\)$"):
        load_params(log)
    blob = tmp_path / "blob.toml"
    blob.write_bytes(b"ab\xff\x00")
    with pytest.raises(InputError, match=r"blob.toml: header: not a TOML text file: byte 0xff "
                                         r"at offset 2 is not UTF-8 text \(a binary file\?\)$"):
        load_params(blob)
