"""``python -m quadsim.openloop``: the report's experiment, its refusals and its errors."""

import json

import numpy as np
import pytest

from quadsim.openloop import main
from quadsim.sim.step_response import response_metrics

SHORT = ["--duration", "1.0", "--step-time", "0.2", "--no-plots", "--json"]


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_open_loop_physical_diverges_like_a_double_integrator(capsys):
    code, out, err = _run(capsys, "--model", "physical", *SHORT)
    assert code == 0, err
    result = json.loads(out)["results"][0]
    assert result["engines"] == ["analytic", "mujoco"]
    assert all(abs(p[0]) < 1e-9 for p in result["poles"])       # twelve poles at the origin
    for engine in ("mujoco", "analytic"):
        metrics = result["metrics"][engine]
        assert not any(m["settles"] for m in metrics.values())
        assert 1.8 < metrics["collective"]["growth_exponent"] < 2.2
    assert max(result["engine_difference"].values()) < 1e-8


def test_report_set_mujoco_refuses_analytic_runs(capsys):
    code, out, err = _run(capsys, "--model", "report", *SHORT)
    assert code == 0
    result = json.loads(out)["results"][0]
    assert result["engines"] == ["analytic"]
    assert "triangle inequality" in result["refused"]["mujoco"]
    code, out, err = _run(capsys, "--model", "report", "--duration", "0.5", "--step-time",
                          "0.1", "--no-plots")
    assert "analytic model still runs" in out
    assert err.count("\n") == 1 and "mujoco refused report" in err


def test_lqr_closed_loop_settles_and_writes_plots(capsys, tmp_path):
    code, out, err = _run(capsys, "--model", "physical", "--controller", "lqr",
                          "--duration", "4", "--step-time", "0.5", "--plots", str(tmp_path),
                          "--json")
    assert code == 0, err
    document = json.loads(out)
    png = tmp_path / "physical_lqr.png"
    assert document["plots"] == [str(png)]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    result = document["results"][0]
    assert all(p[0] < 0 for p in result["poles"])
    metrics = result["metrics"]["analytic"]
    assert metrics["collective"]["settles"] and metrics["yaw"]["settles"]
    assert metrics["collective"]["final"] > 0      # more thrust -> settles higher


def test_bad_input_is_one_line(capsys, tmp_path):
    code, _, err = _run(capsys, "--model", "no_such_model")
    assert code == 2 and err.count("\n") == 1
    assert "valid names are" in err and "physical" in err
    bad = tmp_path / "bad.toml"
    bad.write_text('schema = "quadsim.vehicle.params/1"\n[body]\nmass = 3\n')
    code, _, err = _run(capsys, "--model", str(bad))
    assert code == 2 and err.count("\n") == 1 and "bad.toml" in err and "body.mass" in err
    code, _, err = _run(capsys, "--model", "physical", "--duration", "-1")
    assert code == 2 and "positive" in err


def test_response_metrics_closed_forms():
    t = np.linspace(0, 10, 1001)
    first_order = 1 - np.exp(-t)
    m = response_metrics(t, first_order, bound=10)
    assert m["settles"] and m["RiseTime"] == pytest.approx(np.log(9), abs=0.02)
    parabola = 0.3 * t**2
    m = response_metrics(t, parabola, bound=1.0)
    assert not m["settles"] and m["growth_exponent"] == pytest.approx(2.0, abs=1e-9)
    assert m["time_to_bound"] == pytest.approx(np.sqrt(1 / 0.3), abs=0.01)


def test_compare_models_and_rerun_recording(capsys, tmp_path):
    rrd = tmp_path / "openloop.rrd"
    code, out, err = _run(capsys, "--model", "physical", "--compare", "report", "--duration",
                          "0.5", "--step-time", "0.1", "--no-plots", "--rerun", str(rrd))
    assert code == 0, err
    assert "model comparison" in out and "physical" in out and "report" in out
    assert rrd.stat().st_size > 1000
