"""quadsim.identify: interval coverage on synthetic data, the real 10-inch sweep against a
direct least-squares reference, the bifilar correction, the audit, and the CLI."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from quadsim.identify import (
    FM_PLAUSIBLE,
    audit_report,
    figure_of_merit,
    fit_curve,
    fit_thrust_stand,
    held_out_scores,
    identify_testbed,
    lumped_inertia,
)
from quadsim.identify.__main__ import main
from quadsim.identify.benchdata import load_thrust_stand, load_torque_thrust_ratio
from quadsim.identify.bifilar import bifilar_inertia, published_bifilar_inertia
from quadsim.identify.testbed import curve_effect
from quadsim.vehicle.params import load_params

STAND_10IN = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "thrust_stand"
              / "kde2814_10inch_sweep.csv")
needs_stand = pytest.mark.skipif(not STAND_10IN.is_file(),
                                 reason="../shared/data/thrust_stand (real 10-inch sweep) absent")


@pytest.fixture(scope="module")
def ident():
    return identify_testbed()


def _coverage(truth: dict, model: str, noise: float, reps: int = 200, seed: int = 7) -> dict:
    rng = np.random.default_rng(seed)
    speed = np.tile(np.linspace(150.0, 750.0, 11), 3)
    clean = truth.get("b", 0) * speed**2 + truth.get("c", 0) * speed + truth.get("d", 0) * speed**2
    hits = dict.fromkeys(truth, 0)
    for _ in range(reps):
        fit = fit_curve(speed, clean + rng.normal(0.0, noise, speed.size), model,
                        factor_name="d" if "d" in truth else "b")
        for name, value in truth.items():
            low, high = fit.interval(name)
            hits[name] += low <= value <= high
    return {name: count / reps for name, count in hits.items()}


def test_thrust_intervals_cover_known_b_and_c_at_the_stated_rate():
    coverage = _coverage({"b": 9.7e-6, "c": 1.5e-3}, "quadratic+linear", noise=0.05)
    for name, rate in coverage.items():
        assert 0.90 <= rate <= 0.99, (name, rate)


def test_drag_interval_covers_known_d_at_the_stated_rate():
    coverage = _coverage({"d": 1.4e-7}, "quadratic", noise=5e-4)
    assert 0.90 <= coverage["d"] <= 0.99, coverage


def test_fit_recovers_power_law_exactly():
    speed = np.linspace(100.0, 800.0, 12)
    fit = fit_curve(speed, 5e-5 * speed**1.75, "power")
    assert fit["k"] == pytest.approx(5e-5, rel=1e-6) and fit["n"] == pytest.approx(1.75, rel=1e-8)


def test_held_out_scores_find_a_thrust_curve_effect_only_when_there_is_one():
    rng = np.random.default_rng(3)
    speed = np.broadcast_to(np.linspace(0.0, 740.0, 11), (4, 3, 11)).copy()
    noise = rng.normal(0.0, 0.03, speed.shape)
    command = np.arange(40.0, 150.0, 10.0)
    offset = 9.3e-6 * speed**2 + np.where(speed > 0, 0.3, 0.0) + noise
    effect = curve_effect(held_out_scores(speed, offset, axis=0, scheme="m"), command)
    assert effect.best_model == "quadratic+offset" and effect.share > 0.8
    quadratic = 9.7e-6 * speed**2 + noise
    effect = curve_effect(held_out_scores(speed, quadratic, axis=1, scheme="t"), command)
    assert effect.share < 0.1 and len(effect.biased_commands) <= 2


@needs_stand
def test_real_10inch_sweep_matches_direct_least_squares():
    data = np.genfromtxt(STAND_10IN, delimiter=",", names=True)
    omega = data["speed_rpm"] * 2 * math.pi / 60
    b_ref = np.sum(data["thrust_N"] * omega**2) / np.sum(omega**4)
    d_ref = np.sum(np.abs(data["torque_Nm"]) * omega**2) / np.sum(omega**4)
    stand = fit_thrust_stand(load_thrust_stand(STAND_10IN))
    assert stand.thrust["b"] == pytest.approx(b_ref, rel=0.02)
    assert stand.torque["d"] == pytest.approx(d_ref, rel=0.02)
    # the ratio stored in the package is this sweep's ratio
    running = omega > 0
    ratio_ref = (np.sum(np.abs(data["torque_Nm"][running]) * data["thrust_N"][running])
                 / np.sum(data["thrust_N"][running] ** 2))
    assert load_torque_thrust_ratio()["ratio"][0] == pytest.approx(ratio_ref, rel=1e-5)


def test_figure_of_merit_is_ideal_over_actual_power():
    b, d, rho, radius, omega = 9.7e-6, 1.4e-7, 1.225, 0.127, 500.0
    thrust, torque = b * omega**2, d * omega**2
    ideal = thrust**1.5 / math.sqrt(2 * rho * math.pi * radius**2)
    assert figure_of_merit(b, d, rho, radius) == pytest.approx(ideal / (torque * omega), rel=1e-12)


def test_bifilar_correction_reproduces_hand_value():
    # 0.838 * 9.81 * 0.12^2 * 4.10^2 / (4 pi^2 * 0.4), worked by hand: 0.126015 kg m^2
    assert bifilar_inertia(0.838, 9.81, 0.12, 0.4, 4.10) == pytest.approx(0.126015, rel=2e-5)
    # the report's formula gives its published 0.1931 (Table 4.15)
    assert published_bifilar_inertia(0.838, 9.81, 0.12, 0.4, 4.10) == pytest.approx(0.1931,
                                                                                    rel=1e-3)


def test_lumped_model_with_report_inputs_gives_report_values(ident):
    assert ident.lumped_report_inputs == pytest.approx([0.00444, 0.00444, 0.00825], rel=5e-3)
    single = lumped_inertia(sphere_mass=1.0, sphere_radius=0.1, arm_length=0.2, point_mass=0.1)
    assert single == pytest.approx([0.004 + 0.008, 0.004 + 0.008, 0.004 + 0.016])


def test_identified_numbers(ident):
    assert ident.thrust_factor == pytest.approx(1.008e-5, rel=2e-3)
    assert np.mean(ident.top_point_b) == pytest.approx(9.664e-6, rel=1e-3)
    assert FM_PLAUSIBLE[0] <= ident.figure_of_merit <= FM_PLAUSIBLE[1]
    assert not ident.bifilar.physical and "cannot come from this vehicle" in ident.inertia_warning
    assert ident.motor_map.max_speed == pytest.approx(739.74, abs=0.01)


def test_audit_finds_each_listed_error(ident):
    findings = {f.key: f for f in audit_report(ident, load_params("report", check=False))}
    for key in ("two_pi_thrust_factor", "drag_unmeasured", "bifilar_missing_square",
                "published_inertia_unphysical", "bifilar_periods_not_this_vehicle"):
        assert findings[key].found, key
    assert findings["two_pi_thrust_factor"].numbers["ratio"] == pytest.approx(2 * math.pi,
                                                                              rel=1e-3)
    assert findings["drag_unmeasured"].numbers["published_fm"] < FM_PLAUSIBLE[0]


def test_audit_passes_a_set_without_those_errors(ident):
    clean = {f.key: f.found for f in audit_report(ident, load_params("physical"))}
    assert not clean["two_pi_thrust_factor"]
    assert not clean["drag_unmeasured"]
    assert not clean["published_inertia_unphysical"]


def test_cli_json_has_stable_keys(capsys):
    assert main(["--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"thrust_factor", "motor_map", "drag_factor", "figure_of_merit", "inertia", "audit",
            "warnings", "computational_thrust_factor"} <= set(out)
    assert out["thrust_factor"]["pooled"]["quadratic"]["params"]["b"] == pytest.approx(1.008e-5,
                                                                                      rel=2e-3)


def test_cli_bad_input_is_one_line(tmp_path, capsys):
    bad = tmp_path / "lift.csv"
    bad.write_text("pwm[pwm],mass_1[kg]\n50,0.1\n")
    assert main(["--force-lift", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and "lift.csv" in err
