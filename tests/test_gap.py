"""Gap diagnosis on generated logs: each library effect is found blind, no effect gives
`unexplained`, the JSON follows its schema and is deterministic, bad input is refused."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import InputError
from quadsim.effects import make_effect
from quadsim.gap import diagnose, diagnose_per_flight
from quadsim.gap.__main__ import main
from quadsim.gap.report import to_json, validate
from quadsim.logs.flightlog import FlightLog, write_log
from quadsim.vehicle.params import load_params


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


# effect(s) hidden in the flights, the library name the diagnosis must give, the parameter
# checked against its confidence interval and its true value. Magnitudes are realistic for
# the 37 g Crazyflie (e.g. a 4 g payload, a 4 mm CoM shift, 8 % weaker rotor, 30 ms lag).
CASES = {
    "mass_offset": ([("mass_offset", {"mass": 0.004})], "mass_offset.mass", 0.004),
    "com_offset": ([("com_offset", {"x": 0.004, "y": -0.003})], "com_offset.x", 0.004),
    "inertia_error": ([("inertia_error", {"xx": 0.3, "yy": 0.3, "zz": 0.2})],
                      "inertia_error.xx", 0.3),
    "thrust_mismatch": ([("thrust_mismatch", {"rotor_2": -0.08})], "thrust_mismatch.rotor_2",
                        -0.08),
    "thrust_curve": ([("thrust_curve", {"linear": 3e-6})], "thrust_curve.linear", 3e-6),
    "battery_sag": ([("battery_sag", {"rate": 0.01})], "battery_sag.full_voltage", 4.2),
    "ground_effect": ([("ground_effect", {"gain": 1.5})], "ground_effect.gain", 1.5),
    "rotor_drag": ([("rotor_drag", {"coefficient": 1e-6})], "rotor_drag.coefficient", 1e-6),
    "body_drag": ([("body_drag", {"cd_area": 0.01, "cd_area_vertical": 0.01})],
                  "body_drag.cd_area", 0.01),
    "motor_lag": ([("motor_lag", {"time_constant": 0.03})], "motor_lag.time_constant", 0.03),
    "gyroscopic": ([("gyroscopic", {"rotor_inertia": 5e-8})], "gyroscopic.rotor_inertia", 5e-8),
    "wind": ([("wind", {"vx": 1.0, "vy": -0.5}), ("rotor_drag", {"coefficient": 1e-6})],
             "wind.vx", 1.0),
    # rotor 3 leans 3.4 deg; its axis' x component is sin(0.06) sin(0.6) (Rodrigues)
    "canted_rotor": ([("canted_rotor", {"rotor": 3, "angle": 0.06, "azimuth": 0.6})],
                     "canted_rotor.tilt_x", float(np.sin(0.06) * np.sin(0.6))),
}


def _flights(params, hidden, *, seeds=(0, 1), duration=5.0):
    effects = [make_effect(name, **values) for name, values in hidden]
    return [synthetic_flight(params, effects, seed=s, duration=duration) for s in seeds]


@pytest.mark.parametrize("name", sorted(CASES))
def test_each_library_effect_is_named_top1_with_parameter_in_its_ci(cf, name):
    hidden, key, truth = CASES[name]
    result = diagnose(_flights(cf, hidden), cf, kstep=False, max_combination=1)
    verdict = result["verdict"]
    assert verdict["effect"] == name
    assert result["effects"][0]["name"] == name
    if name == "canted_rotor":   # the right rotor of four, found from the training flights
        assert verdict["fixed"] == {"canted_rotor.rotor": 3.0}
    if name == "battery_sag":
        # the motor map is refitted on the flights, so full_voltage is the voltage at which
        # that map holds (its mean speed factor is collinear with the map's slope): within
        # the 0.15 V the battery falls over a flight of the true full voltage.
        assert abs(verdict["params"][key] - truth) < 0.15
        return
    assert abs(verdict["params"][key] - truth) <= verdict["ci"][key]
    # The CI is informative: narrower than a third of the true value.
    assert verdict["ci"][key] < abs(truth) / 3
    assert verdict["reduction"] > 0.15


def test_no_effect_is_no_significant_gap(cf):
    result = diagnose(_flights(cf, [], seeds=(3, 4)), cf, kstep=False)
    assert result["verdict"]["outcome"] == "no_significant_gap"
    assert result["verdict"]["effect"] == "no_significant_gap"
    assert all(c["at_floor"] for c in result["verdict"]["channels"].values())
    assert max(e["reduction"] for e in result["effects"]) < 0.05


def test_json_follows_schema_and_is_deterministic(cf, tmp_path):
    pytest.importorskip("jsonschema", reason="jsonschema (test extra) validates the schema")
    logs = _flights(cf, [("thrust_mismatch", {"rotor_3": 0.06})], seeds=(5, 6, 7), duration=4.0)
    paths = []
    for k, log in enumerate(logs):
        paths.append(str(write_log(tmp_path / f"flight_{k}.csv.gz", log)))
    outputs = []
    html = tmp_path / "gap.html"
    for run in range(2):
        out = tmp_path / f"gap{run}.json"
        report = ["--report", str(html)] if run == 0 else []     # the HTML of the first run
        assert main(["--model", "crazyflie21", *paths, "--json", str(out), "--quiet",
                     "--effects", "thrust_mismatch", "com_offset", "mass_offset", *report]) == 0
        outputs.append(out.read_bytes())
    assert outputs[0] == outputs[1]
    document = json.loads(outputs[0])
    validate(document)
    assert document["schema"] == "quadsim.gap/3"
    assert document["verdict"]["effect"] == "thrust_mismatch"
    # --effects: the set's shipped reference (the whole library) does not fit: the set alone
    assert "reference_file" not in document and any(
        n.startswith("judged against the parameter set alone: its shipped reference "
                     "crazyflie21.qref does not fit this run (effects: calibrated for the "
                     "whole library, this run's --effects thrust_mismatch com_offset "
                     "mass_offset)") for n in document["notes"])
    assert document["train"] and document["holdout"]
    assert not set(document["train"]) & set(document["holdout"])  # split by flight
    assert set(document["where"]["regime"]) >= {"hover", "fast_forward", "near_ground"}
    assert abs(sum(document["where"]["band"].values()) - 1) < 1e-6
    # the default smoothing's -3 dB frequency (~9.9 Hz at the fit's 100 Hz): the band above
    # 20 Hz was never compared and is not listed
    assert 9.0 < document["where"]["band_top_hz"] < 11.0
    assert list(document["where"]["band"]) == ["0-1 Hz", "1-5 Hz", "5-20 Hz"]
    for horizon in ("0.05", "1"):
        assert document["where"]["kstep_before"][horizon]["position_rms_m"] is not None
    text = html.read_text()
    assert text.count("<svg") >= 2 and "quadsim.gap/3" in text       # figures inline
    # the answer first, the evidence with units, the JSON in a collapsed appendix
    assert (text.index('<div class="answer">') < text.index("<table>") < text.index("<details>")
            < text.index("&quot;schema&quot;"))
    assert re.search(r'<td class="value">[-+0-9.e]+ N m</td>', text)
    assert document["verdict"]["outcome"] == "effect"
    assert all(c["unit"] in ("N", "N m", "rad/s")
               for c in document["verdict"]["channels"].values())


def test_per_flight_mode_names_only_the_flight_that_differs(cf):
    pytest.importorskip("jsonschema", reason="jsonschema (test extra) validates the schema")
    reference = _flights(cf, [], seeds=(10, 11), duration=4.0)
    tested = [synthetic_flight(cf, [], seed=12, duration=4.0),
              synthetic_flight(cf, [make_effect("com_offset", x=-0.005)], seed=13, duration=4.0)]
    result = diagnose_per_flight(tested, reference, cf,
                                 effects=["com_offset", "mass_offset", "thrust_mismatch"])
    validate(json.loads(to_json(result)))
    verdicts = [f["verdict"] for f in result["flights"]]
    assert verdicts == ["no_significant_gap", "com_offset"]
    assert [f["outcome"] for f in result["flights"]] == ["no_significant_gap", "effect"]
    assert abs(result["flights"][1]["params"]["com_offset.x"] + 0.005) < 5e-4


def test_too_little_excitation_is_reported_not_fitted(cf):
    """High above the ground, ground effect cannot be fitted: a warning, never the verdict."""
    logs = []
    for seed in (20, 21):
        log = synthetic_flight(cf, [], seed=seed, duration=4.0)
        logs.append(FlightLog(log.t, log.position + [0, 0, 2.0], log.quat, log.velocity,
                              log.body_rate, log.accel, log.rotor_speed, log.rotor_command,
                              log.vbat))
    result = diagnose(logs, cf, kstep=False, effects=["ground_effect", "mass_offset"])
    ground = next(e for e in result["effects"] if e["name"] == "ground_effect")
    assert "too little excitation" in ground["warning"]
    assert result["verdict"]["outcome"] != "effect"


def test_bad_input(cf, tmp_path, capsys):
    log = synthetic_flight(cf, [], seed=0, duration=2.0)
    three = FlightLog(log.t, log.position, log.quat, log.velocity, log.body_rate, log.accel,
                      log.rotor_speed[:, :3])
    with pytest.raises(InputError, match="3 rotors in the log, the model 'crazyflie21' has 4"):
        diagnose([log, three], cf)
    commands_only = FlightLog(log.t, log.position, log.quat, rotor_command=log.rotor_command)
    with pytest.raises(InputError, match="needs measured rotor speeds"):
        diagnose([log, commands_only], cf)
    single = diagnose([log], cf, kstep=False, effects=["mass_offset"])
    assert any("single flight" in note for note in single["notes"])
    path = str(write_log(tmp_path / "one.csv", log))
    assert main(["--model", "no_such_model", path, "--quiet"]) == 2
    # per flight without references: the set's shipped one calibrated for the whole library
    assert main(["--model", "crazyflie21", "--per-flight", path, "--quiet", "--effects",
                 "mass_offset"]) == 2
    assert main(["--model", "crazyflie21", path, "--json", str(tmp_path / "x.txt")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("error: ") for line in err)
    assert not (tmp_path / "x.txt").exists()
    assert np.isfinite(single["verdict"]["heldout_gap_before"])


# ----------------------------------------------------------------- verdicts, physics, checks


def test_collinear_pair_is_listed_with_magnitudes_and_plausibility(cf):
    """A 4 g payload: the verdict names the most plausible of the collinear explanations and
    lists the uniform loss of thrust per Omega^2 with its magnitude (4 g on 37 g is -9.8 %)."""
    result = diagnose(_flights(cf, [("mass_offset", {"mass": 0.004})]), cf, kstep=False,
                      max_combination=1, effects=["mass_offset", "thrust_factor", "com_offset"])
    verdict = result["verdict"]
    assert verdict["outcome"] == "effect" and verdict["effect"] == "mass_offset"
    alts = {a["name"]: a for a in verdict["alternatives"]}
    assert {"mass_offset", "thrust_factor"} <= set(alts)
    assert "g heavier" in alts["mass_offset"]["magnitude"]
    assert "% thrust per Ω² on all 4 rotors" in alts["thrust_factor"]["magnitude"]
    # -dm / (m + dm) = -0.004 / 0.041 = -9.76 %, within 0.5 points
    assert abs(alts["thrust_factor"]["params"]["thrust_factor.change"] + 0.004 / 0.041) < 5e-3
    assert all(a["plausible"] for a in alts.values())
    assert alts["thrust_factor"]["separate_by"].startswith("weigh the vehicle")
    assert "Mz" in alts["thrust_factor"]["torque_yaw"]
    assert verdict["answer"].startswith("Behaves as if +4")
    assert verdict["units"] == {"mass_offset.mass": "kg"}
    # the readings the answer states: each once, in words, those of probability >= READING_P
    from quadsim.gap.judge import READING_P

    stated = [a for a in verdict["alternatives"] if a["probability"] >= READING_P]
    assert [a["name"] for a in stated] == verdict["readings"]
    assert all(verdict["answer"].count(a["magnitude"]) == 1 for a in stated)


def test_mass_candidate_not_handicapped_by_unmodelled_drag(cf):
    """Force residuals are compared at the nominal mass: with drag the model lacks, a pure
    payload is explained at least as well by the mass as by a thrust scale (before: 0.865 vs
    0.882, thrust named)."""
    drag = [("rotor_drag", {"coefficient": 1e-6}), ("body_drag", {"cd_area": 0.005})]
    result = diagnose(_flights(cf, drag + [("mass_offset", {"mass": 0.004})]), cf, kstep=False,
                      max_combination=1, effects=["mass_offset", "thrust_factor"])
    red = {e["name"]: e["reduction"] for e in result["effects"]}
    assert red["mass_offset"] >= red["thrust_factor"] - 1e-3
    assert abs(result["verdict"]["params"]["mass_offset.mass"] - 0.004) < 3e-4


def test_battery_sag_acts_on_the_command_channel_only(cf):
    """At measured rotor speeds a battery changes no force; it changes the speed a command
    gives (speed factor V / V_full)."""
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import fit_motor_map, residuals

    log = synthetic_flight(cf, [make_effect("battery_sag", rate=0.01)], seed=2, duration=3.0)
    states = prepare([log], cf)[0].fit
    params = fit_motor_map([states], cf)
    plain = residuals(states, params, [], rotor_channel=True)
    sag = residuals(states, params, [make_effect("battery_sag", full_voltage=4.0)],
                    rotor_channel=True)
    np.testing.assert_array_equal(plain[:, :6], sag[:, :6])
    assert np.abs(plain[:, 6:] - sag[:, 6:]).max() > 10.0  # rad/s: ~5 % of 1600 rad/s


def test_wrong_parameter_set_is_caught_before_fitting(cf):
    logs = _flights(cf, [], seeds=(0, 1), duration=2.0)
    with pytest.raises(InputError, match=r"needs b = .* 0\.08\d*x the model's .* median logged "
                                         r"rotor speed"):
        diagnose(logs, load_params("physical"), kstep=False)
    assert abs(diagnose(logs, cf, kstep=False, effects=["mass_offset"])["checks"]
               ["thrust_factor_ratio"] - 1) < 0.01


def test_fit_at_a_bound_is_never_identified(cf):
    """A 100 g payload on the 37 g vehicle is beyond the mass bound (2 m): the fit stops at
    the bound and must not count as identified."""
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import candidates_for, fit_candidate, noise_floor

    states = [f.fit for f in prepare(_flights(cf, [("mass_offset", {"mass": 0.1})],
                                              duration=2.0), cf)]
    cand = next(c for c in candidates_for(cf, False) if c.name == "mass_offset")
    fit = fit_candidate(cand, states, cf, noise_floor(cf, False) * 100, rotor_channel=False)
    assert fit.theta[0] == pytest.approx(2 * cf.mass, rel=1e-3)
    assert fit.identifiable == [False]


def test_low_battery_needs_a_discharge(cf):
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.judge import regime_masks

    log = synthetic_flight(cf, [], seed=1, duration=2.0)
    flat = FlightLog(log.t, log.position, log.quat, log.velocity, log.body_rate, log.accel,
                     log.rotor_speed, log.rotor_command,
                     4.0 + 0.005 * np.random.default_rng(0).standard_normal(len(log.t)))
    assert not regime_masks(prepare([flat], cf)[0].fit, cf)["low_battery"].any()
    draining = regime_masks(prepare([log], cf)[0].fit, cf)["low_battery"]  # 0.15 V drop
    assert 0.1 < draining.mean() < 0.3


def test_drag_refit_unbiased_on_perfect_model_data(cf):
    """Perfect-model flights at the docs' noise level: b and d refits stay at 0 within their
    CI (the issue's -0.9 at the bound was not reproduced on these flights)."""
    from quadsim.gap.diagnose import BASELINE, prepare
    from quadsim.gap.fitting import (
        fit_candidate,
        fit_motor_map,
        noise_floor,
        noise_scale,
        residuals,
    )

    states = [f.fit for f in prepare(_flights(cf, [], seeds=(1, 2), duration=4.0), cf)]
    params = fit_motor_map(states, cf)
    sigma = noise_scale(np.concatenate([residuals(s, params, [], rotor_channel=True)
                                        for s in states]), 0.01, floor=noise_floor(params, True))
    fit = fit_candidate(BASELINE, states, params, sigma, rotor_channel=True)
    drag, ci = fit.params()["nominal_refit.drag"], fit.ci()["nominal_refit.drag"]
    assert abs(drag) <= max(ci, 0.01) and ci < 0.1


def test_loader_warnings_collapse_per_kind():
    from quadsim.gap.__main__ import collapse_warnings

    lines = collapse_warnings([f"f{k}.csv: t: line 7: sample-rate jump, step 0.0{k} s"
                               for k in range(1, 6)] + ["g.csv: vbat: missing"])
    assert lines == ["f1.csv: t: line 7: sample-rate jump, step 0.01 s (and 4 more files alike)",
                     "g.csv: vbat: missing"]


def test_log_ends_are_neither_fitted_nor_scored(cf, monkeypatch):
    """A log whose accelerometer is a filtered finite difference of delayed motion capture
    (benchmarks.pipeline) carries filter transients at its ends; the diagnosis drops the
    first and last EDGE_S = 0.2 s, after which the nominal force residual of the whole
    prepared flight is at its interior level (> 0.5 s from the ends)."""
    import sys

    from benchmarks.pipeline import realistic_log
    from quadsim.gap import diagnose as _  # noqa: F401  (module below)

    module = sys.modules["quadsim.gap.diagnose"]
    from quadsim.gap.fitting import residuals

    log = realistic_log(synthetic_flight(cf, seed=3, duration=4.0, noise=None), cf, seed=3)

    def force_rms_ratio():
        states = module.prepare([log], cf)[0].states
        force = residuals(states, cf, [], rotor_channel=False)[:, :3]
        inner = (states.t > log.t[0] + 0.5) & (states.t < log.t[-1] - 0.5)
        return states, float(np.sqrt(np.mean(force**2)) / np.sqrt(np.mean(force[inner]**2)))

    states, ratio = force_rms_ratio()
    # s (one 100 Hz sample)
    assert states.t[0] == pytest.approx(log.t[0] + module.EDGE_S, abs=0.011)
    assert states.t[-1] == pytest.approx(log.t[-1] - module.EDGE_S, abs=0.011)
    assert ratio < 1.3
    monkeypatch.setattr(module, "EDGE_S", 0.0)
    assert force_rms_ratio()[1] > 3.0     # without the trim the ends dominate


def _closed_loop_drag_refits(cf, rotor_noise: float, yaw_amplitude: float, *,
                             ivs: tuple = (True,)) -> list:
    """nominal_refit on one closed-loop quadsim.fly flight (perfect model, analytic engine):
    hover with a yaw oscillation of ``yaw_amplitude`` rad at 2 rad/s, the docs' sensor noise
    and rotor-speed noise ``rotor_noise`` x the hover speed. Per entry of ``ivs`` (True: the
    instrumental-variable refit, False: plain least squares), all on the same flight:
    (drag, its 95 % CI, identifiable)."""
    from dataclasses import replace

    from quadsim.gap import fitting
    from quadsim.gap.diagnose import BASELINE, prepare
    from quadsim.logs.generate import generate_flight
    from quadsim.logs.sensors import SensorModel
    from quadsim.sim.paths import make_reference
    from quadsim.vehicle.params import hover_speed

    ref = replace(make_reference("hover", duration=8.0), yaw_function=lambda t: (
        yaw_amplitude * np.sin(2.0 * np.asarray(t)),
        2.0 * yaw_amplitude * np.cos(2.0 * np.asarray(t))))
    noise = {"position": 5e-4, "velocity": 0.01, "attitude": 2e-3, "gyro": 0.02, "accel": 0.1,
             "rotor": rotor_noise * hover_speed(cf)}
    log, _ = generate_flight(cf, ref, None, SensorModel(noise=noise), 1, engine="analytic",
                             duration=8.0)
    states = [f.fit for f in prepare([log], cf)]
    params = fitting.fit_motor_map(states, cf)
    sigma = fitting.noise_scale(np.concatenate([fitting.residuals(s, params, [], rotor_channel=True)
                                                for s in states]), 0.01,
                                floor=fitting.noise_floor(params, True))
    out = []
    for iv in ivs:
        saved = fitting.drag_refit_iv
        if not iv:
            fitting.drag_refit_iv = lambda *a: (float("nan"), float("nan"))
        try:
            fit = fitting.fit_candidate(BASELINE, states, params, sigma, rotor_channel=True)
        finally:
            fitting.drag_refit_iv = saved
        i = fit.candidate.parameter_names.index("nominal_refit.drag")
        out.append((fit.params()["nominal_refit.drag"], fit.ci()["nominal_refit.drag"],
                    fit.identifiable[i]))
    return out


def test_drag_refit_not_diluted_by_rotor_speed_noise(cf):
    """Errors in variables: rotor-speed noise attenuates the least-squares d
    refit towards -100 %. Closed-loop Crazyflie, yaw oscillation 0.3 rad: noiseless rotor
    speeds give the reference value (the engine and the residual model differ by ~2 % in
    yaw); with 2 % of hover rotor noise plain least squares gives about -0.12 (dilution), the
    instrumental-variable refit stays within its CI of the noiseless value. In hover without
    yaw the refit was -0.9 (at its bound) with a CI that looked meaningful; now d is reported
    as not identified."""
    [(clean, clean_ci, _)] = _closed_loop_drag_refits(cf, 0.0, 0.3)
    # the refit with and without the instrumental variable on one noisy flight
    (noisy, noisy_ci, ok), (ols, ols_ci, _) = _closed_loop_drag_refits(cf, 0.02, 0.3,
                                                                       ivs=(True, False))
    assert clean_ci < 0.05 and abs(clean) < 0.05
    assert ok and abs(noisy - clean) <= noisy_ci and noisy_ci < 0.1
    assert abs(ols - clean) > ols_ci      # the uncorrected fit is biased beyond its CI
    [(_, _, hover_ok)] = _closed_loop_drag_refits(cf, 0.005, 0.0)
    assert not hover_ok


@pytest.mark.parametrize("model", ["crazyflie21", "physical"])
def test_every_candidate_magnitude_is_worded_with_a_unit(model):
    """Item 7: each candidate's magnitude is a physical statement with a unit, never the raw
    ``effect.parameter = value`` form (e.g. battery_sag.full_voltage = +3.682 V)."""
    import re

    from quadsim.gap.diagnose import BASELINE
    from quadsim.gap.fitting import candidates_for, describe, typical_scales

    params = load_params(model)
    units = re.compile(r"( g\b| mm\b| %| ms\b| mN\b| N\b| m/s| V\b| kg m²| g cm²| cm²| s\b"
                       r"| deg\b)")
    seen = set()
    for has_vbat in (False, True):
        for cand in candidates_for(params, True, has_vbat) + [BASELINE]:
            values = dict(zip(cand.parameter_names, typical_scales(cand, params)))
            if "battery_sag.full_voltage" in values:
                values["battery_sag.full_voltage"] = 3.682
            text = describe(cand.name, values, {k: 0.1 * abs(v) for k, v in values.items()},
                            params, cand.fixed_values)
            for key in values:
                assert f"{key} =" not in text and key not in text, (key, text)
            for part in text.split(", "):
                assert units.search(part), (cand.name, part)
            seen |= set(values)
    assert "battery_sag.full_voltage" in seen and "battery_sag.rate" in seen
    assert len(seen) >= 20
    text = describe("battery_sag", {"battery_sag.full_voltage": 3.682},
                    {"battery_sag.full_voltage": 0.01}, params)
    assert "3.68 ± 0.01 V" in text and "36.8 mV" in text


def _map_flight(command: np.ndarray, lag_s: float, dt: float = 0.01, seed: int = 0):
    """Commands (N, 4) and a measured speed 1000 x command delayed by ``lag_s`` with noise."""
    from types import SimpleNamespace

    t = np.arange(len(command)) * dt
    speed = np.stack([np.interp(t - lag_s, t, command[:, i]) for i in range(4)], 1) * 1000.0
    speed = speed + np.random.default_rng(seed).normal(0.0, 0.5, speed.shape)   # rad/s
    return SimpleNamespace(t=t, command=command, rotor_speed=speed)


def test_motor_map_is_static_and_survives_a_narrow_command_range(cf):
    """The map speed = 1000 x command (rad/s) is recovered although the speed lags 30 ms:
    fitted on 0.5 s means the slope is within 1 % (a fit on raw samples of a 2 Hz manoeuvre
    is diluted by cos(2 pi 2 0.03) = 0.93); references whose commands span 0.2 % of their
    mean give the proportional map, right to 0.2 % at a 5 % higher command."""
    from quadsim.gap.fitting import fit_motor_map, speed_of_command

    t = np.arange(0, 20, 0.01)
    wide = 0.5 + 0.1 * np.sin(2 * np.pi * 2.0 * t)[:, None] * np.ones(4)
    flight = _map_flight(wide, 0.03)
    slope = np.diff(fit_motor_map([flight], cf).motor_map.speed, axis=1)[:, 0]
    assert np.allclose(slope, 1000.0, rtol=0.01)
    raw = np.polyfit(flight.command[:, 0], flight.rotor_speed[:, 0], 1)[0]
    assert raw < 0.95 * 1000.0            # what the raw-sample fit would have given
    narrow = 0.5 + 0.0005 * np.sin(2 * np.pi * 0.3 * t)[:, None] * np.ones(4)
    tuned = fit_motor_map([_map_flight(narrow, 0.03, seed=1)], cf)
    assert np.allclose(speed_of_command(tuned, np.full((1, 4), 0.525)), 525.0, rtol=0.002)


def test_a_command_flat_on_the_maps_windows_reads_no_timing():
    """map_lag on commands whose 0.5 s window means do not vary: a constant 0.57 and a 2 Hz
    sine of 0.1 (its period divides the window). Their window means differ by round-off
    alone (2e-13 and 2e-14 of their size, below FLAT_COMMAND), where a straight line through
    them is rank-deficient: numpy's RankWarning (an error here; before, raised on each lag
    tried) and a slope of round-off. No timing is read: ("lag", 0.0) and the raw window
    means for both forms. A 0.3 Hz sine of 0.05 % (its means span 0.19 %, seven decades
    above the rule) has its 30 ms timing read as before."""
    import warnings

    from quadsim.gap.residual import FLAT_COMMAND, _moving_mean, flat_command, map_lag

    t = np.arange(0, 20, 0.01)
    ones = np.ones(4)
    cases = {"constant": np.full((len(t), 4), 0.57),
             "2 Hz": 0.5 + 0.1 * np.sin(2 * np.pi * 2.0 * t)[:, None] * ones,
             "narrow": 0.5 + 0.0005 * np.sin(2 * np.pi * 0.3 * t)[:, None] * ones}
    for name, command in cases.items():
        flight = _map_flight(command, 0.03)
        raw = _moving_mean(flight.command, 0.01)
        rel = np.ptp(raw[:, 0]) / np.max(np.abs(raw[:, 0]))
        with warnings.catch_warnings():
            warnings.simplefilter("error", np.exceptions.RankWarning)
            line, gain = map_lag([flight], [0.01], _moving_mean(flight.rotor_speed, 0.01))
        if name == "narrow":
            assert rel > 1e6 * FLAT_COMMAND and not flat_command(raw[:, 0])
            assert line[0] == ("lag", 0.03) and gain[0] == ("delay", 0.03)
            continue
        assert 0.0 < rel < 1e-12 and flat_command(raw[:, 0]), name
        for timing, means in (line, gain):
            assert timing == ("lag", 0.0)
            np.testing.assert_array_equal(means, raw)
    assert flat_command(np.zeros(5)) and flat_command(np.zeros(0))


def test_motor_map_takes_the_line_only_where_the_data_support_it(cf):
    """Commands spanning 6 % of their mean (wide enough for a slope): a motor whose speed is
    1000 x command gets the gain through the origin (the line's intercept would be the
    noise's; at a 5 % higher command right to 0.01 %), one with speed 150 + 800 x command
    the line (right to 0.2 % there): the information criterion, not the range alone."""
    from quadsim.gap.fitting import fit_motor_map, speed_of_command

    t = np.arange(0, 60, 0.01)
    command = 0.5 + 0.015 * np.sin(2 * np.pi * 0.2 * t)[:, None] * np.ones(4)
    flight = _map_flight(command, 0.03, seed=2)
    tuned = fit_motor_map([flight], cf)
    np.testing.assert_allclose(tuned.motor_map.speed[:, 0], 0.0)
    np.testing.assert_allclose(speed_of_command(tuned, np.full((1, 4), 0.525)), 525.0,
                               rtol=1e-4)
    offset = _map_flight(command, 0.03, seed=3)
    offset.rotor_speed = 150.0 + 0.8 * offset.rotor_speed
    tuned = fit_motor_map([offset], cf)
    assert np.all(tuned.motor_map.speed[:, 0] > 100.0)
    np.testing.assert_allclose(speed_of_command(tuned, np.full((1, 4), 0.525)), 570.0,
                               rtol=2e-3)


def test_a_combination_needs_every_part_identified_and_plausible(cf):
    """Two effects cancelling at their bounds (every rotor -50 % and the vehicle 50 %
    lighter) are not a combination; a plausible pair with both parts identified is."""
    from quadsim.gap.judge import every_part_stands

    rotors = {f"thrust_mismatch.rotor_{i}": -0.5 for i in range(1, 5)}
    bad = {"name": "thrust_mismatch+mass_offset",
           "params": {**rotors, "mass_offset.mass": -0.5 * cf.mass},
           "identifiable": {**dict.fromkeys(rotors, False), "mass_offset.mass": True},
           "significant": {**dict.fromkeys(rotors, True), "mass_offset.mass": True}}
    assert not every_part_stands(bad, cf)
    good = {"name": "com_offset+mass_offset",
            "params": {"com_offset.x": 0.002, "com_offset.y": 0.0, "com_offset.z": 0.0,
                       "mass_offset.mass": 0.004},
            "identifiable": {"com_offset.x": True, "com_offset.y": True, "com_offset.z": False,
                             "mass_offset.mass": True},
            "significant": {"com_offset.x": True, "com_offset.y": False,
                            "com_offset.z": False, "mass_offset.mass": True}}
    assert every_part_stands(good, cf)
    implausible = {**good, "params": {**good["params"], "mass_offset.mass": 0.9 * cf.mass}}
    assert not every_part_stands(implausible, cf)


def test_inertia_fit_not_shrunk_by_gyro_noise():
    """Errors in variables: the differentiated gyro carries noise, and a torque residual in
    N m of the candidate's own inertia scales that noise by I_v, so least squares shrinks I_v
    (this 8 s testbed flight, gyro noise 0.1 rad/s, no inertia error: xx -18 %, zz -80 %).
    The residual in angular acceleration times the nominal inertia is not biased (measured
    +2.1 % and +1.0 %): |xx|, |yy| within 5 %, |zz| within 15 %."""
    from benchmarks.synthetic import SensorNoise
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import (
        candidates_for,
        fit_candidate,
        fit_motor_map,
        noise_floor,
        noise_scale,
        residuals,
    )

    params = load_params("physical")
    log = synthetic_flight(params, [], duration=8.0, seed=0, noise=SensorNoise(gyro=0.1))
    states = [prepare([log], params)[0].fit]
    params = fit_motor_map(states, params)
    sigma = noise_scale(residuals(states[0], params, [], rotor_channel=True),
                        float(states[0].t[1] - states[0].t[0]), floor=noise_floor(params, True))
    cand = next(c for c in candidates_for(params, True) if c.name == "inertia_error")
    fit = fit_candidate(cand, states, params, sigma, rotor_channel=True)
    values, ci = fit.params(), fit.ci()
    assert abs(values["inertia_error.xx"]) < 0.05 and abs(values["inertia_error.yy"]) < 0.05
    assert abs(values["inertia_error.zz"]) < 0.15, ci


@pytest.mark.parametrize("hidden", [("canted_rotor", {"rotor": 2, "angle": 0.05, "azimuth": 0.7}),
                                    ("battery_sag", {"rate": 0.01})])
def test_exact_flight_is_explained_by_its_own_effect(cf, hidden):
    """A noiseless generated flight with one effect: the residual with that effect is far
    below the nominal residual on every channel (a canted rotor pushes sideways, so the
    attitude carries its force; a battery scales the speed a command gives, statically).
    Measured: Fx 2.8e-3 -> 2.5e-8 N (was unchanged: the generator ignored the tilted rotor's
    sideways push); rotor channel 19 -> 8e-5 rad/s (3.0 while the generator gave the battery
    the engines' 5 ms response)."""
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import residuals

    params = cf.replace(motor_map=None)   # the generator's commands: speed / max_speed
    effects = [make_effect(hidden[0], **hidden[1])]
    log = synthetic_flight(params, effects, duration=4.0, seed=1, noise=None)
    states = prepare([log], params)[0].fit
    before = np.sqrt(np.mean(residuals(states, params, [], rotor_channel=True) ** 2, axis=0))
    after = np.sqrt(np.mean(residuals(states, params, effects, rotor_channel=True) ** 2, axis=0))
    scale = np.r_[[params.weight] * 3, [params.weight * 0.05] * 3, [100.0] * 4]
    moved = before > 1e-3 * scale          # channels the effect moves (N, N m, rad/s)
    print(hidden[0], before, after)
    assert moved.any()
    assert np.all(after[moved] <= 0.01 * before[moved])


def test_result_types_give_the_schema_json_and_read_as_it():
    """quadsim.gap.result: a per-flight Diagnosis of two refused flights is the
    quadsim.gap/3 JSON (validates; the batch answer counts them), reads as that JSON
    (mapping access), keeps no private key, and takes no item assignment."""
    from quadsim.gap.diagnose import refused_entry
    from quadsim.gap.result import Diagnosis
    from quadsim.gap.words import batch_answer

    flights = (refused_entry("a.csv", "t: too short"), refused_entry("b.csv", "t: gap"))
    result = Diagnosis("quadsim.gap/3", "crazyflie21", "per-flight", flights=flights,
                       answer=batch_answer(flights), reference=("r1.csv", "r2.csv"),
                       reference_model={}, reference_refit={})
    doc = result.to_json()
    validate(doc)
    assert dict(result) == doc and result["flights"][1]["reason"] == "t: gap"
    assert doc["verdict"]["answer"] == ("No flight judged against the reference flights: "
                                        "2 refused (see each flight's reason)")
    assert doc["flights"][0] == {"file": "a.csv", "outcome": "refused", "verdict": "refused",
                                 "answer": "Not judged: t: too short", "reason": "t: too short",
                                 "probability": None, "readings": [], "posterior": [],
                                 "notes": []}

    def keys(x):
        if isinstance(x, dict):
            return set(x) | {k for v in x.values() for k in keys(v)}
        return {k for v in x for k in keys(v)} if isinstance(x, list) else set()

    assert not any(k.startswith("_") for k in keys(doc))
    with pytest.raises(TypeError):
        result["checks"] = {}
