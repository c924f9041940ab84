"""Regression tests of the refusals: every impossible input or setup is refused in one line naming
file and field (exit 2, nothing written), or named in the output; plus the feasibility and
log-consistency checks on their own with closed-form numbers."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from quadsim.core.errors import InputError
from quadsim.logs import checks as logcheck
from quadsim.logs.flightlog import load_log, write_log
from quadsim.logs.generate import generate_flight
from quadsim.vehicle import guards
from quadsim.vehicle.params import MODELS_DIR, load_params

REPO = Path(__file__).resolve().parents[1]
STAND = REPO.parent / "shared" / "data" / "thrust_stand" / "kde2814_14inch_sweep.csv"
CF = (MODELS_DIR / "crazyflie21.toml").read_text()
PHYSICAL = (MODELS_DIR / "physical.toml").read_text()


def _one_line_error(capsys, *needles):
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert str(needle) in lines[0], (needle, lines[0])
    return lines[0]


def _files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*") if p.is_file())


#: one xdist worker runs this module's tests (pytest-xdist --dist loadgroup): its module-scoped
#: fixtures are built once, not once per worker
pytestmark = pytest.mark.xdist_group("test_guards")


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """Three gentle 3 s Crazyflie figure-8 flights (gyro noise 0.01 rad/s)."""
    from quadsim.logs.sensors import SensorModel

    folder = tmp_path_factory.mktemp("flights")
    params = load_params("crazyflie21")
    paths = []
    for seed in range(3):
        log, _ = generate_flight(params, "figure8", None, SensorModel(noise={"gyro": 0.01}),
                                 seed, duration=3.0, speed=0.5)
        paths.append(write_log(folder / f"f{seed}.csv.gz", log))
    return paths


@pytest.fixture(scope="module")
def lively(tmp_path_factory):
    """A 3 s Crazyflie figure 8 at 2 m/s: turns enough (~0.5 rad/s) to judge every axis."""
    log, _ = generate_flight(load_params("crazyflie21"), "figure8", None, None, 0,
                             duration=3.0, speed=2.0)
    return write_log(tmp_path_factory.mktemp("lively") / "lively.csv.gz", log)


def _variant(tmp_path, name, text, old, new):
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new))
    return path


# ----------------------------------------------------------------------------- gap


def test_gap_same_log_twice_refused(flights, tmp_path, capsys):
    from quadsim.gap.__main__ import main

    out = tmp_path / "gap.json"
    assert main(["--model", "crazyflie21", str(flights[0]), str(flights[0]),
                 "--json", str(out), "--quiet"]) == 2
    _one_line_error(capsys, flights[0], "LOG", "given twice")
    assert _files(tmp_path) == []


def test_gap_same_file_training_and_holdout_refused(flights, tmp_path, capsys):
    from quadsim.gap.__main__ import main

    assert main(["--model", "crazyflie21", str(flights[0]), str(flights[1]),
                 "--holdout", str(flights[1]), "--quiet"]) == 2
    _one_line_error(capsys, flights[1], "LOG", "--holdout")


@pytest.mark.parametrize("argv, needle", [(["--window", "-0.1"], "--window -0.1"),
                                          (["--window", "nan"], "--window nan")])
def test_gap_window_range(flights, argv, needle, capsys):
    from quadsim.gap.__main__ import main

    assert main(["--model", "crazyflie21", str(flights[0]), *argv]) == 2
    _one_line_error(capsys, needle)


def test_gap_unwritable_json_refused_before_work(flights, tmp_path, capsys):
    from quadsim.gap.__main__ import main

    blocker = tmp_path / "file"
    blocker.write_text("x")
    out = blocker / "gap.json"  # parent is a file: cannot be created
    assert main(["--model", "crazyflie21", *map(str, flights), "--json", str(out)]) == 2
    line = _one_line_error(capsys, out, "--json")
    assert "not a directory" in line
    assert _files(tmp_path) == [blocker]


def test_gap_nan_run_cut_out_with_note(flights, tmp_path, capsys):
    from quadsim.gap.__main__ import main

    paths = []
    for i, path in enumerate(flights):
        log = load_log(path)
        rotor = log.rotor_speed.copy()
        rotor[100:160, 1] = np.nan        # a dropout early in the flight
        paths.append(write_log(tmp_path / f"nan{i}.csv.gz", dataclasses.replace(
            log, rotor_speed=rotor)))
    out = tmp_path / "gap.json"
    assert main(["--model", "crazyflie21", *map(str, paths), "--json", str(out),
                 "--effects", "thrust_mismatch", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err and "kept the clean stretch" in err
    result = json.loads(out.read_text())
    assert result["schema"].startswith("quadsim.gap/")


def test_nan_everywhere_refused(flights):
    log = load_log(flights[0])
    rotor = log.rotor_speed.copy()
    rotor[::3, 0] = np.nan               # no clean stretch of 1 s
    with pytest.raises(InputError, match=r"rotor_speed: NaN/Inf in 33\.\d %"):
        logcheck.check_log(dataclasses.replace(log, rotor_speed=rotor))


def test_gap_gentle_gyro_in_degrees_refused(flights, tmp_path, capsys):
    from quadsim.gap.__main__ import main

    paths = []
    for i, path in enumerate(flights):
        log = load_log(path)
        assert np.degrees(np.abs(log.body_rate)).max() < 60  # below the magnitude limit
        paths.append(write_log(tmp_path / f"deg{i}.csv.gz", dataclasses.replace(
            log, body_rate=np.degrees(log.body_rate))))
    assert main(["--model", "crazyflie21", *map(str, paths), "--quiet"]) == 2
    line = _one_line_error(capsys, paths[0], ": wx:", "deg/s")
    gain = float(line.split("integrated gyro = ")[1].split(" x")[0])
    assert 40 < gain < 80   # 57.3 within the window-integration error


def test_gap_help_says_parquet(capsys):
    from quadsim.gap.__main__ import main

    with pytest.raises(SystemExit):
        main(["--help"])
    assert "Parquet" in capsys.readouterr().out


# ----------------------------------------------------------------------------- log checks


@pytest.mark.parametrize("change, field, hint", [
    (lambda log: dict(body_rate=log.body_rate * [1, -1, 1]), "wy", "sign"),
    (lambda log: dict(body_rate=log.body_rate[:, [1, 0, 2]]), "wx", "swapped"),
    (lambda log: dict(accel=log.accel / 9.81), "a", "in g"),
    (lambda log: dict(rotor_speed=log.rotor_speed * 60 / (2 * np.pi)), "rotor_*", "RPM"),
])
def test_log_consistency_catches(lively, change, field, hint):
    params = load_params("crazyflie21")
    log = load_log(lively)
    logcheck.check_log(log, params)  # the clean flight passes
    bad = dataclasses.replace(log, **change(log))
    with pytest.raises(InputError, match=hint) as info:
        logcheck.check_log(bad, params)
    assert str(lively) in str(info.value) and f": {field}" in str(info.value)


def test_log_consistency_passes_clean_flight(flights):
    params = load_params("crazyflie21")
    log, _ = logcheck.check_log(load_log(flights[0]), params)
    assert len(log) == len(load_log(flights[0]))
    # the rotor thrust over the flight matches the body-z force (exact in simulation)
    ratio = (params.thrust_factor * np.sum(log.rotor_speed ** 2, axis=1)).mean() / (
        params.mass * log.accel[:, 2].mean())
    assert ratio == pytest.approx(1.0, abs=1e-3)


def test_view_horizon_negative_refused(flights, tmp_path, capsys):
    from quadsim.view import main

    assert main(["--model", "crazyflie21", "--log", str(flights[0]), "--horizon", "-1",
                 "--rerun", str(tmp_path / "v.rrd")]) == 2
    _one_line_error(capsys, "--horizon -1")
    assert _files(tmp_path) == []


def test_view_help_says_parquet(capsys):
    from quadsim.view import main

    with pytest.raises(SystemExit):
        main(["--help"])
    assert ".parquet" in capsys.readouterr().out


# ----------------------------------------------------------------------------- feasibility


def test_openloop_mass_in_grams_refused(tmp_path, capsys):
    from quadsim.openloop import main

    model = _variant(tmp_path, "heavy.toml", PHYSICAL, "value = 0.837667,", "value = 837.667,")
    plots = tmp_path / "plots"
    assert main(["--model", str(model), "--plots", str(plots)]) == 2
    line = _one_line_error(capsys, model, "body.mass", "837.667 kg")
    # weight 837.667 * 9.81 N against b * 4 * 739.74^2 = 22.07 N
    assert "8218 N" in line and "22.07 N" in line
    assert not plots.exists()


def test_build_mjcf_ctrlrange_below_hover_control(tmp_path, capsys):
    from quadsim.build_mjcf import main

    out = tmp_path / "m.xml"
    assert main([str(REPO / "cad"), "--params", "crazyflie21", "-o", str(out)]) == 2
    line = _one_line_error(capsys, "crazyflie21.toml", "mass (CAD parts)", "ctrlrange")
    # hover control m g / (4 b) of the 0.8377 kg testbed on Crazyflie rotors, vs 2750^2
    hover = 0.837667 * 9.81 / (4 * 3.7028e-8)
    assert f"{hover:.4g}" in line and f"{2750.0 ** 2:.4g}" in line
    assert _files(tmp_path) == []


@pytest.mark.parametrize("old, new, field", [
    ('value = 0.037,', 'value = 37.0,', "body.mass"),                    # grams as kg
    ('value = 0.037,', 'value = 0.000037,', "body.mass"),                # 37 mg: thrust/weight 3086
    ('[[2.05e-05, 0.0, 0.0], [0.0, 2.05e-05, 0.0], [0.0, 0.0, 3.05e-05]]',
     '[[20.5, 0.0, 0.0], [0.0, 20.5, 0.0], [0.0, 0.0, 30.5]]', "body.inertia"),  # g mm^2 slip
    ('value = 2750.0,', 'value = 26304.0,', "rotors.max_speed"),       # RPM stored as rad/s
    ('value = 0.0275,', 'value = 0.06,', "rotors.radius"),  # 2 r = 0.12 m, hubs 0.0708 m apart
])
def test_params_slips_refused_by_ratios(tmp_path, old, new, field):
    path = _variant(tmp_path, "slip.toml", CF, old, new)
    with pytest.raises(InputError) as info:
        load_params(path)
    assert str(info.value).startswith(f"{path}: {field}:")


def test_feasibility_numbers_of_shipped_sets():
    cf = guards.feasibility(load_params("crazyflie21"))
    # T/W = 4 b w_max^2 / (m g) = 4 * 3.7028e-8 * 2750^2 / (0.037 * 9.81)
    assert cf["thrust_to_weight"] == pytest.approx(4 * 3.7028e-8 * 2750 ** 2 / (0.037 * 9.81),
                                                  rel=1e-12)
    assert cf["tip_speed_m_s"] == pytest.approx(2750 * 0.0275, rel=1e-12)
    for name in ("physical", "computational", "crazyflie21"):
        guards.check_vehicle(load_params(name))


# ----------------------------------------------------------------------------- fly


def test_fly_beyond_vehicle_refused_then_recorded(tmp_path, capsys):
    from quadsim.fly import main

    out = tmp_path / "f.csv.gz"
    argv = ["--model", "crazyflie21", "--path", "figure8", "--speed", "20", "--duration", "2",
            "-o", str(out), "--quiet"]
    assert main(argv) == 2
    _one_line_error(capsys, "--speed 20", "crazyflie21.toml", "saturated", "peak tilt")
    assert _files(tmp_path) == []
    assert main([*argv, "--allow-saturation"]) == 0
    assert "warning: path beyond the vehicle" in capsys.readouterr().err
    report = json.loads((tmp_path / "f.csv.gz.truth.json").read_text())["flight_report"]
    assert report["feasible"] is False
    assert report["saturated_fraction"] > 0.05 or report["peak_tilt_deg"] > 60


def test_fly_report_of_a_feasible_flight_and_progress():
    params = load_params("crazyflie21")
    seen = []
    _, truth = generate_flight(params, "hover", None, None, 0, duration=1.0,
                               progress=seen.append)
    report = truth["flight_report"]
    assert report["feasible"] and not report["diverged"]
    assert report["saturated_fraction"] == 0.0 and report["peak_tilt_deg"] < 1e-6
    assert report["tracking_error_max_m"] < 1e-9
    assert seen == sorted(seen) and seen[-1] == pytest.approx(1.0, abs=0.01)


# ----------------------------------------------------------------------------- identify, openloop


@pytest.mark.skipif(not STAND.is_file(), reason=f"real 14-inch sweep absent at {STAND}")
def test_identify_stand_radius_and_fm_flag(tmp_path, capsys):
    from quadsim.identify.__main__ import main

    assert main(["--stand", str(STAND)]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "stand thrust-stand" in x)
    assert "R = 0.1778 m, 14-inch from the file name" in line and "IMPLAUSIBLE" not in line
    renamed = tmp_path / "sweep.csv"
    shutil.copy(STAND, renamed)
    assert main(["--stand", str(renamed)]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "stand thrust-stand" in x)
    # FM ~ 1/R: the same sweep with the 10-inch radius reads 0.1778/0.127 x higher
    fm = float(line.split(") = ")[1].split()[0])
    assert fm > 0.8 and "IMPLAUSIBLE" in line


def test_openloop_compare_overlay_and_rerun_message(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from quadsim.openloop import main

    rrd = tmp_path / "o.rrd"
    assert main(["--model", "physical", "--compare", "computational", "--duration", "0.4",
                 "--step-time", "0.1", "--plots", str(tmp_path), "--rerun", str(rrd)]) == 0
    captured = capsys.readouterr()
    assert (tmp_path / "compare_physical_computational_openloop.png").is_file()
    assert f"wrote rerun recording {rrd}" in captured.err
    assert main(["--model", "physical", "--compare", "physical"]) == 2
    _one_line_error(capsys, "--compare", "twice")


CLI_MODULES = ("quadsim.build_mjcf", "quadsim.openloop", "quadsim.fly", "quadsim.view",
               "quadsim.convert", "quadsim.identify.__main__", "quadsim.sweep.__main__",
               "quadsim.inertia_report", "quadsim.gap.__main__")


@pytest.mark.parametrize("module", CLI_MODULES)
def test_usage_error_is_one_line(module, capsys):
    """An unknown flag (and missing required arguments): exit 2 and exactly one stderr line
    naming what is wrong, no usage block."""
    import importlib

    main = importlib.import_module(module).main
    with pytest.raises(SystemExit) as exit_info:
        main(["--no-such-flag"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "usage:" not in err, err
    assert "error:" in err and ("--no-such-flag" in err or "required" in err), err
