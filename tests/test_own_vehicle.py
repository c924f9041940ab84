"""Your own vehicle: identify --logs recovers a known vehicle from its (generated) flights and
writes a set every command accepts; bad inputs give one-line errors; ground and idle spans are
cut; command-only logs are diagnosed in every role; the shipped data are found."""

from __future__ import annotations

import dataclasses
import re
import tomllib
import warnings

import numpy as np
import pytest

from quadsim.core.errors import QuadsimWarning
from quadsim.identify.__main__ import main as identify_main
from quadsim.logs.flightlog import FlightLog, load_log, write_log
from quadsim.vehicle.params import MODELS_DIR, load_params

from _helpers import commands_through_map

CF = (MODELS_DIR / "crazyflie21.toml").read_text()


def skeleton_text(text: str = CF, *, drop=("thrust_factor", "drag_factor", "max_speed"),
                  motor_map: bool = False, inertia: bool = True) -> str:
    """crazyflie21.toml without what a user cannot measure by hand."""
    lines = [line for line in text.splitlines()
             if not any(line.startswith(f"{key} =") for key in drop)
             and (inertia or not line.startswith("inertia ="))]
    out = "\n".join(lines)
    if not motor_map:
        out = re.sub(r"\[motor_map\].*?(?=\n\[\[rotor\]\])", "", out, flags=re.S)
    return out + "\n"


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    from benchmarks.synthetic import synthetic_flight

    folder = tmp_path_factory.mktemp("flights")
    cf = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return [write_log(folder / f"f{s}.csv.gz",
                          synthetic_flight(cf, [], seed=s, duration=6.0, rate_hz=200.0))
                for s in (1, 2, 3)]


def _identify(tmp_path, logs, skeleton: str, capsys=None):
    skel = tmp_path / "skeleton.toml"
    skel.write_text(skeleton)
    out = tmp_path / "vehicle.toml"
    code = identify_main(["--logs", *map(str, logs), "--vehicle", str(skel), "-o", str(out)])
    return code, out


def test_identify_logs_recovers_the_thrust_factor_and_writes_a_loadable_set(tmp_path, flights,
                                                                              capsys):
    code, out = _identify(tmp_path, flights, skeleton_text())
    assert code == 0
    truth = load_params("crazyflie21")
    params = load_params(out)          # every check: units, physical inertia, guards
    # exact generated flights with sensor noise: b within 0.5 %
    assert abs(params.thrust_factor / truth.thrust_factor - 1) < 0.005
    data = tomllib.loads(out.read_text())
    source = data["rotors"]["thrust_factor"]["source"]
    assert "identify --logs" in source and "f1.csv.gz" in source and "R^2" in source
    # the motor map reproduces the logged speeds from the logged commands within 1 %
    log = load_log(flights[0])
    predicted = params.motor_map.speed_at(log.rotor_command, log.vbat)
    assert np.sqrt(np.mean((predicted - log.rotor_speed) ** 2)) < 0.01 * log.rotor_speed.mean()
    # well excited generated flights: inertia x, y and d (given the true Izz) within 3 %
    np.testing.assert_allclose(np.diag(params.inertia)[:2], np.diag(truth.inertia)[:2],
                               rtol=0.03)
    assert abs(params.drag_factor / truth.drag_factor - 1) < 0.03
    assert "time_constant" in data["motor_map"]
    assert any(n.startswith("thrust curve") for n in data["notes"])
    # what the data cannot determine is named in the file
    assert any("Izz" in w or "inertia" in w or "d not identified" in w
               for w in data.get("warnings", [])) or "Izz" in data["body"]["inertia"]["source"]
    # accepted by a command
    from quadsim.fly import main as fly_main

    assert fly_main(["--model", str(out), "--path", "hover", "--duration", "1", "--quiet",
                     "-o", str(tmp_path / "hover.csv.gz")]) == 0


def test_output_and_flags_are_checked_before_any_work(tmp_path, flights, capsys):
    skel = tmp_path / "skeleton.toml"
    skel.write_text(skeleton_text())
    before = skel.read_bytes()
    # the skeleton as output: refused, the input untouched
    assert identify_main(["--logs", str(flights[0]), "--vehicle", str(skel), "-o",
                          str(skel)]) == 2
    assert skel.read_bytes() == before
    assert identify_main(["--logs", str(flights[0]), "--vehicle", str(skel), "-o",
                          str(tmp_path / "v.toml"), "--json"]) == 2
    assert "--json: belongs to the bench-table identification" in capsys.readouterr().err
    assert identify_main(["--logs", str(flights[0]), "-o", str(tmp_path / "v.toml")]) == 2
    assert "--vehicle" in capsys.readouterr().err
    assert not (tmp_path / "v.toml").exists()


def test_rotors_in_another_order_are_refused(tmp_path, flights, capsys):
    text = skeleton_text()
    # swap the positions of rotors 1 and 3 (front-right <-> rear-left): same spins, wrong place
    text = text.replace("[0.0354, -0.0354, 0.0]", "TMP").replace(
        "[-0.0354, 0.0354, 0.0]", "[0.0354, -0.0354, 0.0]").replace("TMP", "[-0.0354, 0.0354, 0.0]")
    code, out = _identify(tmp_path, flights, text)
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert "another order" in err and err.startswith("error: ") and err.count("\n") == 1


def test_reversed_spins_are_refused(tmp_path, flights, capsys):
    text = skeleton_text().replace('"ccw"', '"X"').replace('"cw"', '"ccw"').replace('"X"', '"cw"')
    code, out = _identify(tmp_path, flights, text)
    err = capsys.readouterr().err
    assert code == 2 and not out.exists() and "spin the other way" in err


def test_mixed_vehicles_are_refused(tmp_path, flights, capsys):
    heavy = load_log(flights[0])
    # the same flight with 20 % more specific force: a heavier vehicle's thrust at this mass
    other = write_log(tmp_path / "other.csv.gz",
                      dataclasses.replace(heavy, accel=heavy.accel * 1.2, path=None))
    code, out = _identify(tmp_path, [flights[1], other], skeleton_text())
    err = capsys.readouterr().err
    assert code == 2 and not out.exists() and "different vehicles" in err


@pytest.mark.parametrize("cut, message", [
    ("mass =", "body.mass: missing"),
    ("position =", "rotor[0].position"),
])
def test_skeleton_without_mass_or_geometry_is_refused(tmp_path, flights, capsys, cut, message):
    text = "\n".join(line for line in skeleton_text().splitlines() if not line.startswith(cut))
    code, out = _identify(tmp_path, flights, text)
    err = capsys.readouterr().err
    assert code == 2 and not out.exists() and message in err, err


def test_command_only_logs_give_the_thrust_map(tmp_path, flights, capsys):
    only = [write_log(tmp_path / f"cmd{i}.csv.gz",
                      dataclasses.replace(load_log(p), rotor_speed=None, path=None))
            for i, p in enumerate(flights)]
    text = skeleton_text(drop=("thrust_factor", "drag_factor"))
    code, out = _identify(tmp_path, only, text)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    params = load_params(out)
    truth = load_params("crazyflie21")
    # b Omega^2 of the logged commands (and voltages) against the true b Omega^2 of the
    # logged speeds: within 3 % RMS
    log = load_log(flights[0])
    thrust = params.thrust_factor * params.motor_map.speed_at(log.rotor_command, log.vbat) ** 2
    true = truth.thrust_factor * log.rotor_speed ** 2
    assert np.sqrt(np.mean((thrust / true - 1) ** 2)) < 0.03
    assert "no rotor speeds in any log" in captured.err
    # without max_speed the speed scale is unknown: refused in one line
    code, _ = _identify(tmp_path, only, skeleton_text())
    assert code == 2 and "max_speed: missing" in capsys.readouterr().err


# ----------------------------------------------------------------------------- spans


def _ground_log(t_ground: float = 2.0, t_air: float = 3.0, rate: float = 100.0) -> FlightLog:
    t = np.arange(int((t_ground + t_air) * rate)) / rate
    air = t >= t_ground
    z = np.where(air, 0.5 * np.sin(2 * np.pi * 0.5 * (t - t_ground)) ** 2 + 0.1, 0.0)
    position = np.stack([np.zeros_like(t), np.zeros_like(t), z], 1)
    velocity = np.gradient(position, t, axis=0)
    quat = np.tile([1.0, 0, 0, 0], (len(t), 1))
    speed = np.where(air[:, None], 1600.0, 0.0) * np.ones((1, 4))
    accel = np.tile([0.0, 0.0, 9.81], (len(t), 1))
    return FlightLog(t, position, quat, velocity=velocity, body_rate=np.zeros((len(t), 3)),
                     accel=accel, rotor_speed=speed)


def test_ground_span_is_cut_with_a_note():
    from quadsim.logs.spans import cut_ground

    log, note = cut_ground(_ground_log())
    assert note is not None and "cut: idle, ground 0.00-1.99 s" in note
    assert abs(log.t[0] - 2.0) < 0.011 and len(log.t) == 300


def test_all_ground_log_is_refused():
    from quadsim.core.errors import InputError
    from quadsim.logs.spans import cut_ground

    log = _ground_log(t_ground=3.0, t_air=0.0)
    with pytest.raises(InputError, match="no airborne stretch"):
        cut_ground(log)


def test_a_hover_is_not_ground():
    from quadsim.logs.spans import cut_ground

    log = _ground_log(t_ground=0.0, t_air=3.0)
    log = dataclasses.replace(log, position=np.zeros_like(log.position),
                              velocity=np.zeros_like(log.position))
    assert cut_ground(log)[1] is None


# ----------------------------------------------------------------------------- commands only


def test_gap_command_only_holdout_and_reference(tmp_path, capsys):
    """Command-only logs in every role run on the set's motor map; a set without one is
    refused in one line naming the way out."""
    from benchmarks.synthetic import synthetic_flight
    from quadsim.gap.__main__ import main as gap_main

    cf = load_params("crazyflie21")
    only = [write_log(tmp_path / f"cmd{s}.csv", dataclasses.replace(commands_through_map(
        synthetic_flight(cf, [], seed=s, duration=2.0), cf), rotor_speed=None))
        for s in (42, 43)]
    out = tmp_path / "gap.json"
    args = ["--model", "crazyflie21", str(only[0]), "--holdout", str(only[1]), "--quiet",
            "--effects", "mass_offset", "--json", str(out)]
    assert gap_main(args) == 0 and out.exists()
    no_map = tmp_path / "nomap.toml"
    no_map.write_text(skeleton_text(drop=()))
    assert gap_main(["--model", str(no_map), *args[2:-2]]) == 2
    assert "motor_map: logs without rotor speeds" in capsys.readouterr().err


# ----------------------------------------------------------------------------- package data


def test_shipped_data_are_found():
    from quadsim.core.shipped import shipped_dir
    from quadsim.inertia_report import DEFAULT_CAD

    assert (shipped_dir("models") / "physical.toml").is_file()
    assert (DEFAULT_CAD / "testbed.toml").is_file()
    with pytest.raises(ValueError):
        shipped_dir("nothing")
    # in a checkout the MJCF goes to models/, never into an installed package's data
    from quadsim.core.shipped import is_installed_copy
    from quadsim.sim.model import default_output

    assert not is_installed_copy(MODELS_DIR)
    assert default_output("testbed") == MODELS_DIR / "testbed.xml"
