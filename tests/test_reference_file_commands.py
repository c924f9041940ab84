"""Stored references for logs with motor commands only (:mod:`quadsim.gap.reffile`, "Command-only
references"): the command -> speed model kept in the header exactly (float.hex), a command-only
flight judged against the file as against the logs it was written from, bit for bit (per
flight and held out; with ``--command-reference``, and with the motor map balanced rotor by
rotor); ``--command-reference`` with such a file refused; the crazyflie21 set's shipped
commands file loads, fits the set and is the default for command-only logs."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import InputError
from quadsim.effects import make_effect
from quadsim.gap import reffile
from quadsim.gap.__main__ import main
from quadsim.gap.logcheck import (
    BalancedModel,
    CommandModel,
    MapCommandModel,
    command_model_from_params,
    fit_command_model,
)
from quadsim.gap.reffile import (
    binding_of,
    mismatch,
    model_from_json,
    model_to_json,
    params_hash,
    read_header,
    read_reference,
    shipped_reference,
)
from quadsim.logs.flightlog import write_log
from quadsim.vehicle.params import load_params

from _helpers import commands_through_map


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """Four short synthetic flights with a rotor drag, each with speeds (``speeds/``) and
    with its rotor-speed columns cut (``cmd/``): two references, two judged."""
    folder = tmp_path_factory.mktemp("cmdflights")
    (folder / "speeds").mkdir()
    (folder / "cmd").mkdir()
    cf = load_params("crazyflie21")
    drag = [make_effect("rotor_drag", coefficient=1e-6)]
    speeds, cmd = [], []
    for k, seed in enumerate((70, 71, 72, 73)):
        log = commands_through_map(synthetic_flight(cf, drag, seed=seed, duration=4.0), cf)
        speeds.append(write_log(folder / "speeds" / f"f{k}.csv.gz", log))
        cmd.append(write_log(folder / "cmd" / f"f{k}.csv.gz",
                             dataclasses.replace(log, rotor_speed=None)))
    return speeds, cmd


def _write(out: Path, refs, *extra) -> Path:
    assert main(["--model", "crazyflie21", "--reference", *map(str, refs), *extra,
                 "--effects", "mass_offset", "--no-cache", "--quiet",
                 "--write-reference", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def fitted(flights, tmp_path_factory):
    """Written from the two command-only references and their originals as
    ``--command-reference``."""
    speeds, cmd = flights
    return _write(tmp_path_factory.mktemp("cref") / "cmd.qref", cmd[:2],
                  "--command-reference", *map(str, speeds[:2]))


def _judge(tmp_path, name, logs, *refs, per_flight=True, holdout=None):
    out = tmp_path / f"{name}.json"
    mode = ["--per-flight"] if per_flight else []
    assert main(["--model", "crazyflie21", *mode, *map(str, logs),
                 *(["--holdout", str(holdout)] if holdout else []), "--reference",
                 *map(str, refs), "--effects", "mass_offset", "--workers", "1",
                 "--no-cache", "--quiet", "--json", str(out)]) == 0
    return json.loads(out.read_text())


def _same_but_the_file(file_json: dict, logs_json: dict, name: str) -> None:
    """``file_json`` is ``logs_json`` but for ``reference_file`` and the answer's sentence
    naming the file."""
    stored = file_json.pop("reference_file")
    assert stored["file"] == name and stored["judges"] == "commands"
    key = "verdict" if file_json.get("verdict") else None
    got = file_json["verdict"]["answer"] if key else file_json["answer"]
    want = logs_json["verdict"]["answer"] if key else logs_json["answer"]
    assert got.startswith(want.rstrip(". ")) and (
        f"nominal flights, commands only (stored reference {name}, written " in got)
    if key:
        file_json["verdict"]["answer"] = want
    else:
        file_json["answer"] = want
    assert file_json == logs_json


def test_header_keeps_the_fitted_command_model_exactly(fitted, flights):
    """The header says "commands" and holds the model fitted on the --command-reference logs
    (an independent fit on the same loaded logs), every float bit for bit."""
    from quadsim.logs.checks import check_logs
    from quadsim.logs.flightlog import load_log

    header = read_header(fitted)
    assert header["judges"] == "commands" and header["command_model"]["type"] == "fitted"
    cf = load_params("crazyflie21")
    speeds, _ = flights
    logs, _ = check_logs([load_log(p) for p in speeds[:2]], cf)
    fresh = fit_command_model(logs)
    stored = read_reference(fitted).command_model(cf)
    assert isinstance(stored, CommandModel)
    for name in ("a", "b", "c"):
        assert getattr(stored, name).tobytes() == getattr(fresh, name).tobytes(), name
    for name in ("v_ref", "tau", "rms", "samples", "source"):
        assert getattr(stored, name) == getattr(fresh, name), name
    assert 0.0 <= stored.tau < 0.5 and len(header["command_references"]) == 2


def test_command_only_flight_as_against_the_logs(fitted, flights, tmp_path):
    """Per flight and held out: judged against the file with no --command-reference, the JSON
    of the logs with --command-reference (but for the file it names)."""
    speeds, cmd = flights
    logs_json = _judge(tmp_path, "logs", [cmd[2]], *cmd[:2], "--command-reference",
                       *speeds[:2])
    _same_but_the_file(_judge(tmp_path, "file", [cmd[2]], fitted), logs_json, "cmd.qref")
    held = _judge(tmp_path, "hlogs", [cmd[2]], *cmd[:2], "--command-reference", *speeds[:2],
                  per_flight=False, holdout=cmd[3])
    _same_but_the_file(_judge(tmp_path, "hfile", [cmd[2]], fitted, per_flight=False,
                              holdout=cmd[3]), held, "cmd.qref")
    # a log with speeds against a commands file: judged as it is, as against the logs
    mixed = _judge(tmp_path, "mlogs", [speeds[2]], *cmd[:2], "--command-reference",
                   *speeds[:2])
    _same_but_the_file(_judge(tmp_path, "mfile", [speeds[2]], fitted), mixed, "cmd.qref")


def test_balanced_motor_map_round_trip(flights, tmp_path):
    """Without --command-reference the references' speeds come from the set's motor map
    balanced rotor by rotor on them: stored as such, the same answers as the logs."""
    _, cmd = flights
    out = _write(tmp_path / "map.qref", cmd[:2])
    header = read_header(out)
    assert header["command_model"]["type"] == "balanced"
    assert header["command_model"]["model"]["type"] == "motor_map"
    model = read_reference(out).command_model(load_params("crazyflie21"))
    assert isinstance(model, BalancedModel) and isinstance(model.model, MapCommandModel)
    assert model.factors.shape == (4,) and np.all(np.abs(model.factors - 1.0) <= 0.5)
    _same_but_the_file(_judge(tmp_path, "file", [cmd[2]], out),
                       _judge(tmp_path, "logs", [cmd[2]], *cmd[:2]), "map.qref")


def test_model_json_inverse_exact():
    """model_to_json / model_from_json: each kind back bit for bit (NaN v_ref too); a
    malformed one refused naming the field."""
    cf = load_params("crazyflie21")
    rng = np.random.default_rng(3)
    fitted = CommandModel(rng.normal(size=4), rng.normal(size=4), rng.normal(size=4),
                          float("nan"), 1 / 3, 0.1 + 1e-17, 123, "test")
    back = model_from_json(json.loads(json.dumps(model_to_json(fitted))), cf)
    assert all(getattr(back, k).tobytes() == getattr(fitted, k).tobytes() for k in "abc")
    assert np.isnan(back.v_ref) and back.tau == 1 / 3 and back.rms == fitted.rms
    balanced = BalancedModel(command_model_from_params(cf), np.array([0.9, 1.1, 1 / 3, 1.0]))
    again = model_from_json(json.loads(json.dumps(model_to_json(balanced))), cf)
    assert again.factors.tobytes() == balanced.factors.tobytes()
    assert again.model.tau == balanced.model.tau and again.source == balanced.source
    t = np.arange(200) * 0.002
    u = np.full((200, 4), 0.5)
    assert np.array_equal(again.speeds(t, u, None), balanced.speeds(t, u, None))
    with pytest.raises(InputError, match="x.qref: command_model.type: 'other'"):
        model_from_json({"type": "other"}, cf, "x.qref")
    with pytest.raises(InputError, match="command_model.tau: missing"):
        model_from_json({"type": "motor_map", "rms": "nan", "source": ""}, cf)


def test_refusals(fitted, flights, tmp_path, capsys):
    """--command-reference with a commands file; a header saying "commands" without a
    model: one line each, exit 2."""
    speeds, cmd = flights
    argv = ["--model", "crazyflie21", "--per-flight", str(cmd[2]), "--effects",
            "mass_offset", "--quiet", "--reference"]
    assert main([*argv, str(fitted), "--command-reference", str(speeds[0])]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        f"error: {fitted}: command_model: this stored reference holds the command -> speed "
        "model")
    line, _, rest = fitted.read_bytes().partition(b"\n")
    head = dict(json.loads(line), command_model=None)
    bad = tmp_path / "bad.qref"
    bad.write_bytes(json.dumps(head).encode() + b"\n" + rest)
    assert main([*argv, str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f'error: {bad}: command_model: a "commands" file holds one, a "speeds" '
                   "file none"]


def test_shipped_commands_file_fits_its_set():
    """crazyflie21_commands.qref: read with this code, for this set's content, the whole
    library and the default window, 20 command-only flights and the 20 originals as command
    references, a fitted model with a lag inside the fit's bounds."""
    path = shipped_reference("crazyflie21", commands=True)
    assert path is not None and path.name == "crazyflie21_commands.qref"
    stored = read_reference(path)
    cf = load_params("crazyflie21")
    assert stored.judges == "commands" and stored.header["model"]["sha256"] == params_hash(cf)
    assert mismatch(stored.header, binding_of(cf, window_s=0.1)) is None
    assert stored.stage.count == 20 and len(stored.header["command_references"]) == 20
    assert [r["file"][4:] for r in stored.header["references"]] == [
        r["file"][8:] for r in stored.header["command_references"]]
    model = stored.command_model(cf)
    assert isinstance(model, CommandModel) and 5e-4 < model.tau < 0.5
    assert read_reference(shipped_reference("crazyflie21")).judges == "speeds"
    assert shipped_reference("physical", commands=True) is None


def test_synthesis_note_reads_as_a_sentence():
    """The CLI's note on synthesised speeds names the model: the shipped commands file's
    fitted one read "... from fitted on 20 reference log(s)"; a set's motor map as before."""
    from quadsim.gap.__main__ import synthesis_note

    cf = load_params("crazyflie21")
    fitted = read_reference(shipped_reference("crazyflie21", commands=True)).command_model(cf)
    assert synthesis_note(fitted.source).startswith(
        "note: rotor speeds synthesised for the command-only logs from the command -> speed "
        "model fitted on 20 reference log(s): ")
    assert synthesis_note("the motor map of crazyflie21 (x)") == (
        "note: rotor speeds synthesised for the command-only logs from the motor map of "
        "crazyflie21 (x)")


def test_generated_command_only_flights_against_the_shipped_files(tmp_path, monkeypatch,
                                                                  capsys):
    """No --reference: command-only logs (and a mix with a log with speeds) are judged
    against the commands file, and the answer and JSON say so; without that file shipped,
    --per-flight is refused as before."""
    cf = load_params("crazyflie21")
    log = synthetic_flight(cf, [], seed=5, duration=4.0)
    only = write_log(tmp_path / "c.csv.gz", dataclasses.replace(log, rotor_speed=None))
    full = write_log(tmp_path / "s.csv.gz", log)
    out = tmp_path / "c.json"
    assert main(["--model", "crazyflie21", "--per-flight", str(only), str(full),
                 "--workers", "1", "--quiet", "--json", str(out), "--no-cache"]) == 0
    result = json.loads(out.read_text())
    assert result["reference_file"]["file"] == "crazyflie21_commands.qref"
    assert result["reference_file"]["shipped"] is True
    assert result["reference_file"]["judges"] == "commands"
    assert ("Judged against the set's own 20 nominal flights, commands only (shipped "
            "reference crazyflie21_commands.qref, written ") in result["verdict"]["answer"]
    assert len(result["flights"]) == 2 and all(f["outcome"] in (
        "effect", "unexplained", "no_significant_gap") for f in result["flights"])
    real = reffile.shipped_reference
    monkeypatch.setattr(reffile, "shipped_reference",
                        lambda name, commands=False: None if commands else real(name))
    assert main(["--model", "crazyflie21", "--per-flight", str(only), "--quiet"]) == 2
    assert "crazyflie21.qref does not fit this run: logs without rotor speeds" in \
        capsys.readouterr().err


def test_command_only_flight_against_references_with_speeds(flights, tmp_path, capsys):
    """A command-only flight against references that log speeds and commands: the references
    are judged alike (their speeds cut and synthesised by the command model their own speeds
    fit), so the flight is judged, with the numbers of the explicit command-only run
    (``--reference cmd/ --command-reference speeds/``); against a stored reference written
    from those references with their speeds it is refused in one line naming --reference."""
    speeds, cmd = flights
    auto = _judge(tmp_path, "auto", [cmd[2]], *speeds[:2])
    explicit = _judge(tmp_path, "explicit", [cmd[2]], *cmd[:2], "--command-reference",
                      *map(str, speeds[:2]))
    a, e = auto["flights"][0], explicit["flights"][0]
    assert a["outcome"] != "refused", a["answer"]
    for key in ("outcome", "verdict", "probability", "params", "ci", "lack_of_fit"):
        assert a[key] == e[key], key
    stored = _write(tmp_path / "speeds.qref", speeds[:2])
    capsys.readouterr()
    assert main(["--model", "crazyflie21", "--per-flight", str(cmd[2]), "--reference",
                 str(stored), "--effects", "mass_offset", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {cmd[2]}: rotor_speed: not logged; "
                                               "speeds.qref was written from references with "
                                               "rotor speeds and commands"), err
    assert "give --reference LOG..." in err[0]
