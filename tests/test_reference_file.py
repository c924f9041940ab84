"""Stored reference files (:mod:`quadsim.gap.reffile`): written and read back bit for bit,
the same answers as the reference logs; refused in one line when foreign, truncated,
altered, of another format or calibrated for another run, a pickle naming anything outside
the allowed classes refused before it runs; the crazyflie21 set's shipped file loads with
this code and fits the set it ships with."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pickle
from pathlib import Path

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import InputError
from quadsim.effects import make_effect
from quadsim.gap import reffile
from quadsim.gap.__main__ import main
from quadsim.gap.reffile import (
    FORMAT,
    SCHEMA,
    binding_of,
    effects_hash,
    mismatch,
    params_hash,
    read_header,
    read_reference,
    shipped_reference,
)
from quadsim.logs.flightlog import write_log
from quadsim.vehicle.params import load_params

from _helpers import drag_flights

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def flight_files(tmp_path_factory):
    """Three short synthetic flights with a rotor drag (two references, one judged)."""
    return drag_flights(tmp_path_factory.mktemp("flights"))


@pytest.fixture(scope="module")
def written(flight_files, tmp_path_factory):
    """A stored reference of the two reference flights (``--effects mass_offset``), written
    with no LOG to judge."""
    out = tmp_path_factory.mktemp("ref") / "two.qref"
    assert main(["--model", "crazyflie21", "--reference", *map(str, flight_files[:2]),
                 "--effects", "mass_offset", "--no-cache", "--quiet",
                 "--write-reference", str(out), "--reference-source", "two test flights"]) == 0
    return out


def _judge(tmp_path, flight, name, *refs, extra=()):
    out = tmp_path / f"{name}.json"
    assert main(["--model", "crazyflie21", "--per-flight", str(flight), "--reference",
                 *map(str, refs), "--effects", "mass_offset", "--workers", "1", "--no-cache",
                 "--quiet", "--json", str(out), *extra]) == 0
    return json.loads(out.read_text())


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def test_header_readable_without_unpickling(written, flight_files):
    header = json.loads(written.read_bytes().partition(b"\n")[0])
    assert header == read_header(written)
    assert header["schema"] == SCHEMA and header["format"] == FORMAT
    assert header["model"] == {"name": "crazyflie21",
                               "sha256": params_hash(load_params("crazyflie21"))}
    assert header["effects"] == ["mass_offset"] and header["window_s"] == 0.1
    assert header["effects_file"] is None and header["count"] == 2
    assert header["source"] == "two test flights"
    assert [r["sha256"] for r in header["references"]] == [
        hashlib.sha256(p.read_bytes()).hexdigest() for p in flight_files[:2]]
    assert "--write-reference" in header["command"]
    payload = written.read_bytes().partition(b"\n")[2]
    assert header["stage"]["bytes"] == len(payload)
    assert header["stage"]["sha256"] == hashlib.sha256(payload).hexdigest()


def test_round_trip_bit_for_bit(written, flight_files, tmp_path):
    """The stage read back holds the computed stage's arrays bit for bit, and judging a
    flight against the file writes the JSON the reference logs give (apart from the
    ``reference_file`` it names and the answer's sentence saying so)."""
    from quadsim.gap.diagnose import calibrated_stage
    from quadsim.logs.checks import check_logs
    from quadsim.logs.flightlog import load_log

    cf = load_params("crazyflie21")
    logs, _ = check_logs([load_log(p) for p in flight_files[:2]], cf)
    fresh = calibrated_stage(logs, cf, effects=["mass_offset"], window_s=0.1, base=()).reference
    read = read_reference(written).stage.reference
    arrays = 0
    for f in dataclasses.fields(fresh):
        a, b = getattr(fresh, f.name), getattr(read, f.name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), f.name
            arrays += 1
    assert arrays >= 6            # theta, se_pool, scatter, sigma, tau, lof_mean at least
    logs_json = _judge(tmp_path, flight_files[2], "logs", *flight_files[:2])
    file_json = _judge(tmp_path, flight_files[2], "file", written)
    stored = file_json.pop("reference_file")
    assert stored["file"] == "two.qref" and stored["shipped"] is False and stored["count"] == 2
    sentence = file_json["verdict"]["answer"][len(logs_json["verdict"]["answer"]):]
    # after the answer's full stop (added where the answer has none)
    assert sentence.startswith((". Judged", " Judged")) and logs_json["verdict"]["answer"].rstrip(
        ).endswith(".") == sentence.startswith(" ")
    assert sentence.lstrip(". ").startswith("Judged against the 2 nominal flights (stored "
                                            "reference two.qref, written ")
    file_json["verdict"]["answer"] = logs_json["verdict"]["answer"]
    assert file_json == logs_json
    # written while judging: the same stage bytes as written alone, the logs' JSON
    both = _judge(tmp_path, flight_files[2], "both", *flight_files[:2],
                  extra=("--write-reference", str(tmp_path / "both.qref")))
    assert both == logs_json
    assert ((tmp_path / "both.qref").read_bytes().partition(b"\n")[2]
            == written.read_bytes().partition(b"\n")[2])


def _rewrite(path: Path, out: Path, header=None, payload=None) -> Path:
    line, _, rest = path.read_bytes().partition(b"\n")
    head = json.loads(line) if header is None else header
    body = rest if payload is None else payload
    out.write_bytes(json.dumps(head).encode() + b"\n" + body)
    return out


def _with_payload(path: Path, out: Path, payload: bytes) -> Path:
    head = json.loads(path.read_bytes().partition(b"\n")[0])
    head["stage"].update(bytes=len(payload), sha256=hashlib.sha256(payload).hexdigest())
    return _rewrite(path, out, head, payload)


def _refused(argv, capsys) -> str:
    assert main(argv) == 2
    return _error(capsys)


def test_refusals_one_line(written, flight_files, tmp_path, capsys):
    judge = ["--model", "crazyflie21", "--per-flight", str(flight_files[2]), "--effects",
             "mass_offset", "--quiet", "--reference"]
    head = json.loads(written.read_bytes().partition(b"\n")[0])
    older = dict(head, format=FORMAT + 1)
    bad = _rewrite(written, tmp_path / "format.qref", older)
    line = _refused([*judge, str(bad)], capsys)
    assert line == (f"error: {bad}: format: written by format {FORMAT + 1}, this quadsim "
                    f"reads {FORMAT}: write it again with `{head['command']}`")
    cut = tmp_path / "cut.qref"
    cut.write_bytes(written.read_bytes()[:-100])
    line = _refused([*judge, str(cut)], capsys)
    assert line.startswith(f"error: {cut}: stage: {head['stage']['bytes'] - 100} bytes where "
                           f"the header says {head['stage']['bytes']} (truncated")
    flipped = bytearray(written.read_bytes())
    flipped[-10] ^= 1
    (tmp_path / "flip.qref").write_bytes(bytes(flipped))
    assert "stage: its SHA-256 is not the header's" in _refused(
        [*judge, str(tmp_path / "flip.qref")], capsys)
    foreign = tmp_path / "foreign.qref"
    foreign.write_bytes(b"\x80\x04not json\n")
    assert _refused([*judge, str(foreign)], capsys) == (
        f"error: {foreign}: header: not a quadsim stored reference (its first line is not "
        f"the JSON header of {SCHEMA})")
    schema = _rewrite(written, tmp_path / "schema.qref", dict(head, schema="other/1"))
    assert f"{schema}: schema: 'other/1'" in _refused([*judge, str(schema)], capsys)
    # calibrated for another run: --window, --effects, another parameter set's content
    line = _refused([*judge, str(written), "--window", "0.12"], capsys)
    assert line.startswith(f"error: {written}: window_s: calibrated with --window 0.1 s, "
                           "this run's is 0.12 s")
    judge_all = [a for a in judge if a not in ("--effects", "mass_offset")]
    line = _refused([*judge_all, str(written)], capsys)
    assert line.startswith(f"error: {written}: effects: calibrated for --effects mass_offset, "
                           "this run's the whole library")
    text = (REPO / "models" / "crazyflie21.toml").read_text()
    cf = load_params("crazyflie21")
    edited = tmp_path / "crazyflie21.toml"
    assert text.count("time_constant = { value = 0.05,") == 1
    edited.write_text(text.replace("time_constant = { value = 0.05,",
                                   "time_constant = { value = 0.051,"))
    other = load_params(edited)         # the motor lag 1 ms longer, all else the same
    assert other.motor_map.time_constant == 0.051
    line = _refused(["--model", str(edited), *judge[2:], str(written)], capsys)
    assert line.startswith(f"error: {written}: model: calibrated for crazyflie21 (sha256 "
                           f"{params_hash(cf)[:12]}), this run's model is crazyflie21 "
                           f"(sha256 {params_hash(other)[:12]})")
    # a .qref with logs, --write-reference from a .qref, over an input
    assert "is given alone" in _refused([*judge, str(written), str(flight_files[0])], capsys)
    assert "needs --reference LOG..." in _refused(
        ["--model", "crazyflie21", "--reference", str(written), "--write-reference",
         str(tmp_path / "again.qref")], capsys)
    assert not (tmp_path / "again.qref").exists()
    assert _refused(["--model", "crazyflie21", str(flight_files[2]), "--bare", "--reference",
                     str(written)], capsys) == (
        "error: --bare: not used with --reference (the parameter set alone is the reference "
        "model)")
    assert _refused(["--model", "crazyflie21", str(flight_files[2]), "--reference-source",
                     "x"], capsys) == "error: --reference-source: only used with --write-reference"
    before = flight_files[0].read_bytes()
    assert _refused(["--model", "crazyflie21", "--reference", *map(str, flight_files[:2]),
                     "--write-reference", str(flight_files[0])], capsys).startswith(
        f"error: {flight_files[0]}: --write-reference: output name must end in .qref")
    assert flight_files[0].read_bytes() == before
    assert "LOG: give the flight logs to judge" in _refused(["--model", "crazyflie21"], capsys)
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*.tmp"))


class _Run:
    """A pickle that, unpickled unrestricted, would run ``os.system``."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


class _Write:
    """A pickle naming a quadsim function (not a class): refused as well."""

    def __reduce__(self):
        from quadsim.core.files import atomic_write_text

        return (atomic_write_text, ("/tmp/never", "x"))


def test_pickle_outside_the_whitelist_runs_nothing(written, flight_files, tmp_path, capsys):
    marker = tmp_path / "ran"
    evil = _with_payload(written, tmp_path / "evil.qref", pickle.dumps(_Run(marker), protocol=4))
    argv = ["--model", "crazyflie21", "--per-flight", str(flight_files[2]), "--effects",
            "mass_offset", "--quiet", "--reference", str(evil)]
    line = _refused(argv, capsys)
    assert line.startswith(f"error: {evil}: stage: names posix.system, outside what a stored "
                           "reference may hold") or line.startswith(
        f"error: {evil}: stage: names os.system,")
    assert "nothing in it run" in line and not marker.exists()
    other = _with_payload(written, tmp_path / "fn.qref", pickle.dumps(_Write(), protocol=4))
    with pytest.raises(InputError, match="stage: names quadsim.core.files.atomic_write_text"):
        read_reference(other)
    wrong = _with_payload(written, tmp_path / "dict.qref", pickle.dumps({"a": 1}, protocol=4))
    with pytest.raises(InputError, match="stage: a dict, not a quadsim.gap.calibrate.Calibrated"):
        read_reference(wrong)


def test_content_hashes():
    """params_hash: the numbers, not the name, description, sources or path; effects_hash:
    each effect's name and values."""
    cf = load_params("crazyflie21")
    same = dataclasses.replace(cf, name="renamed", description="x", path=None, sources={})
    assert params_hash(same) == params_hash(cf)
    heavier = dataclasses.replace(cf, mass=np.nextafter(cf.mass, 1.0))   # one ulp
    assert params_hash(heavier) != params_hash(cf)
    assert len(params_hash(cf)) == 64 and int(params_hash(cf), 16) >= 0
    drag = make_effect("rotor_drag", coefficient=1e-6)
    assert effects_hash(()) is None
    assert effects_hash((drag,)) == effects_hash((make_effect("rotor_drag", coefficient=1e-6),))
    assert effects_hash((drag,)) != effects_hash((make_effect("rotor_drag",
                                                              coefficient=1.1e-6),))
    run = binding_of(cf, window_s=0.1)
    header = {"model": {"name": "crazyflie21", "sha256": params_hash(cf)},
              "effects_file": None, "effects": None, "window_s": 0.1}
    assert mismatch(header, run) is None
    assert mismatch(header, binding_of(cf, base=(drag,), effects_file="e.toml",
                                       window_s=0.1)).startswith(
        "effects_file: calibrated on top of the effects of none, this run's --effects-file: "
        "e.toml")


def test_shipped_reference_fits_its_set(tmp_path):
    """The crazyflie21 set's shipped file: read with this code, written for this set's
    content (models/crazyflie21.toml), the whole library and the default window, from 20
    flights; a set without one has none."""
    path = shipped_reference("crazyflie21")
    assert path is not None and path.name == "crazyflie21.qref"
    stored = read_reference(path)
    cf = load_params("crazyflie21")
    assert stored.header["model"]["sha256"] == params_hash(cf)
    assert mismatch(stored.header, binding_of(cf, window_s=0.1)) is None
    assert stored.stage.count == 20 and len(stored.header["references"]) == 20
    assert stored.stage.reference.sigma.shape == stored.stage.reference.tau.shape
    assert all(np.isfinite(stored.stage.reference.sigma))
    assert shipped_reference("physical") is None


def test_generated_flight_against_the_shipped_reference(tmp_path, capsys):
    """No --reference: --per-flight judges against the set's shipped reference and says so
    (JSON ``reference_file``, the answer); --bare is refused with --per-flight; a set
    without one still needs --reference."""
    cf = load_params("crazyflie21")
    path = tmp_path / "g.csv.gz"
    write_log(path, synthetic_flight(cf, [], seed=5, duration=4.0))
    out = tmp_path / "g.json"
    assert main(["--model", "crazyflie21", "--per-flight", str(path), "--workers", "1",
                 "--quiet", "--json", str(out), "--no-cache"]) == 0
    result = json.loads(out.read_text())
    assert result["reference_file"]["shipped"] is True
    assert result["reference_file"]["count"] == 20 and len(result["reference"]) == 20
    assert "Judged against the set's own 20 nominal flights (shipped reference " \
           "crazyflie21.qref, written " in result["verdict"]["answer"]
    assert len(result["flights"]) == 1 and result["flights"][0]["outcome"] in (
        "effect", "unexplained", "no_significant_gap")
    assert main(["--model", "crazyflie21", "--per-flight", str(path), "--bare"]) == 2
    assert "--bare: not used with --per-flight" in _error(capsys)
    assert main(["--model", "physical", "--per-flight", str(path)]) == 2
    capsys.readouterr()


def test_shipped_reference_left_where_it_cannot_serve(tmp_path, monkeypatch, capsys):
    """A shipped file of another format (a quadsim that reads format FORMAT + 1) or logs
    without rotor speeds (where the set ships no commands file): --per-flight refused in one
    line naming why."""
    from quadsim.logs.flightlog import FlightLog

    cf = load_params("crazyflie21")
    log = synthetic_flight(cf, [], seed=5, duration=2.0)
    path = write_log(tmp_path / "g.csv.gz", log)
    monkeypatch.setattr(reffile, "FORMAT", FORMAT + 1)
    assert main(["--model", "crazyflie21", "--per-flight", str(path), "--quiet"]) == 2
    assert _error(capsys).startswith(
        "error: --per-flight needs --reference LOG... (nominal flights): the set's shipped "
        f"reference crazyflie21.qref does not fit this run: {shipped_reference('crazyflie21')}"
        f": format: written by format {FORMAT}, this quadsim reads {FORMAT + 1}")
    monkeypatch.setattr(reffile, "FORMAT", FORMAT)
    commands = FlightLog(log.t, log.position, log.quat, log.velocity, log.body_rate,
                         log.accel, rotor_command=log.rotor_command)
    only = write_log(tmp_path / "c.csv.gz", commands)
    real = reffile.shipped_reference      # the set's commands file (its own test) left out
    monkeypatch.setattr(reffile, "shipped_reference",
                        lambda name, commands=False: None if commands else real(name))
    assert main(["--model", "crazyflie21", "--per-flight", str(only), "--quiet"]) == 2
    assert "does not fit this run: logs without rotor speeds" in _error(capsys)


def test_shipped_file_in_wheel_and_sdist_lists():
    """setup.py copies models/references/*.qref into the wheel (kept in its folder) and
    MANIFEST.in puts it into the sdist."""
    setup = (REPO / "setup.py").read_text()
    assert '"references/*.qref"' in setup
    assert "*.qref" in (REPO / "MANIFEST.in").read_text()
    assert reffile.SHIPPED_FOLDER == "references"
