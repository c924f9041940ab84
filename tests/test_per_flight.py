"""Per-flight rule (quadsim.gap.per_flight), combination readings and benchmark scoring:
numbers checked against hand-built fit entries (the rule is pure over the fit results)."""

from __future__ import annotations

import numpy as np
import pytest

from quadsim.bench.score import read_verdict, score_case
from quadsim.gap.combine import _combination_alternatives, parts_identified
from quadsim.gap.per_flight import differs_from_reference, judge_flight, reference_band
from quadsim.vehicle.params import load_params

CHANNELS = ["Fx", "Fy", "Fz", "Mx", "My", "Mz"]


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def _lag(tau, ci, *, identified=True, reduction=0.5, after=None):
    return {"name": "motor_lag", "params": {"motor_lag.time_constant": tau},
            "ci": {"motor_lag.time_constant": ci},
            "identifiable": {"motor_lag.time_constant": identified},
            "significant": {"motor_lag.time_constant": True},
            "reduction": reduction, "t_statistic": 8.0,
            "heldout_rms_after": after or dict.fromkeys(CHANNELS, 1.0)}


def test_reference_band_uses_only_identified_reference_fits():
    refs = [_lag(0.0070, 0.0005), _lag(0.0073, 0.0004), _lag(0.5, 0.4, identified=False)]
    lo, hi = reference_band("motor_lag.time_constant", refs)
    assert lo == pytest.approx(0.0065) and hi == pytest.approx(0.0077)
    assert reference_band("motor_lag.time_constant", refs[2:]) is None


def test_an_effect_at_the_references_magnitude_does_not_differ():
    """RotorPy's nominal 5 ms motors fit as 7.2 ms on every flight: a faster flight shows
    the lag more (bigger reduction) but its magnitude is the references' (7.0-7.3 ms)."""
    refs = [_lag(0.0070, 0.0005), _lag(0.0073, 0.0004)]
    assert not differs_from_reference(_lag(0.0072, 0.0003), refs)
    # 24 ms against 7 ms: differs; 7.9 +- 0.1 ms lies 0.1 ms beyond the band: differs
    assert differs_from_reference(_lag(0.024, 0.0002), refs)
    assert differs_from_reference(_lag(0.0079, 0.0001), refs)
    # its CI reaches into the band: does not differ
    assert not differs_from_reference(_lag(0.0079, 0.0003), refs)
    # references that identified nothing: compared with "off" only (significance)
    assert differs_from_reference(_lag(0.0072, 0.0003), [_lag(0.5, 0.4, identified=False)])


def _one(effects, before):
    return {"effects": effects,
            "where": {"heldout_rms_before": dict(zip(CHANNELS, before))}}


def test_shared_effect_that_reaches_the_floor_is_no_significant_gap(cf):
    """A flight above the reference floor only by an effect every reference shares at the
    same magnitude: no_significant_gap, with the shared effect named in a note."""
    refs = {"motor_lag": [{**_lag(0.0070, 0.0005), "reduction": 0.69},
                          {**_lag(0.0073, 0.0004), "reduction": 0.60}]}
    floors = {k: [1.0, 0.9] for k in CHANNELS}
    flight = _lag(0.0072, 0.0003, reduction=0.79, after=dict.fromkeys(CHANNELS, 1.1))
    judged = judge_flight(_one([flight], [2.0] * 6), refs, "f", floors, cf)
    assert judged["outcome"] == "no_significant_gap" and judged["verdict"] == "no_significant_gap"
    assert "motor_lag" in judged["notes"][-1] and "shared" in judged["notes"][-1]
    assert "motor_lag.time_constant 6.5 to 7.7 ms" in judged["answer"]   # the references' band
    # the same flight with a 24 ms lag differs: named
    lagging = _lag(0.024, 0.0003, reduction=0.98, after=dict.fromkeys(CHANNELS, 1.0))
    judged = judge_flight(_one([lagging], [2.0] * 6), refs, "f", floors, cf)
    assert judged["outcome"] == "effect" and judged["verdict"] == "motor_lag"
    # a shared effect that leaves a channel above 1.25x the floor: unexplained
    partial = _lag(0.0072, 0.0003, reduction=0.79,
                   after={**dict.fromkeys(CHANNELS, 1.0), "Mz": 1.5})
    judged = judge_flight(_one([partial], [2.0] * 6), refs, "f", floors, cf)
    assert judged["outcome"] == "unexplained"


def _wind(vx, ci):
    keys = ("wind.vx", "wind.vy", "rotor_drag.coefficient")
    return {"name": "wind", "params": dict(zip(keys, (vx, 0.0, 1e-4))),
            "ci": dict(zip(keys, (ci, ci, 1e-5))), "identifiable": dict.fromkeys(keys, True),
            "significant": {"wind.vx": abs(vx) > ci, "wind.vy": False,
                            "rotor_drag.coefficient": True}}


def test_every_part_of_a_reading_must_be_identified():
    """wind fitted as 0.002 +- 0.1 m/s with rotor drag is rotor drag alone: not a reading."""
    assert not parts_identified(_wind(0.002, 0.1))
    assert parts_identified(_wind(1.0, 0.1))


def test_a_combination_answer_describes_every_part(cf):
    best = {"name": "mass_offset", "params": {"mass_offset.mass": 0.004},
            "ci": {"mass_offset.mass": 0.0002}, "reduction": 0.8}
    combined = {"name": "mass_offset+inertia_error",
                "params": {"mass_offset.mass": 0.004, "inertia_error.xx": 0.3,
                           "inertia_error.yy": 0.3, "inertia_error.zz": 0.0},
                "ci": {"mass_offset.mass": 0.0002, "inertia_error.xx": 0.05,
                       "inertia_error.yy": 0.05, "inertia_error.zz": 0.2}, "reduction": 0.95}
    factor = {"name": "thrust_factor", "magnitude": "-9.8 ± 0.5 % thrust per Ω² on all 4 rotors",
              "plausible": True, "params": {"thrust_factor.change": -0.098}}
    alts = [{"name": "mass_offset", "magnitude": "+4 g", "plausible": True}, factor]
    out = _combination_alternatives(combined, best, alts, cf)
    assert out[0]["name"] == "mass_offset+inertia_error"
    assert "g heavier" in out[0]["magnitude"] and "I_xx +30" in out[0]["magnitude"]
    assert out[1]["name"] == "thrust_factor+inertia_error"
    assert out[1]["magnitude"].startswith("-9.8") and "I_xx +30" in out[1]["magnitude"]


def test_scoring_counts_plausible_collinear_readings_only():
    entry = {"outcome": "effect", "effect": "mass_offset",
             "alternatives": [{"name": "mass_offset", "plausible": True},
                              {"name": "thrust_factor", "plausible": True},
                              {"name": "thrust_curve", "plausible": False}],
             "confusable_with": ["thrust_factor", "thrust_curve"]}
    verdict = read_verdict(entry)
    assert verdict["lead"] == ["mass_offset"] and verdict["readings"] == 2
    assert verdict["named"] == ["mass_offset", "thrust_factor"]
    assert verdict["alternatives"] == ["thrust_curve"]
    factor = score_case("thrust_factor", "library", verdict)
    assert factor["named"] and not factor["lead"] and not factor["confident_wrong"]
    curve = score_case("thrust_curve", "library", verdict)
    assert not curve["named"] and curve["named_or_alternative"] and curve["confident_wrong"]
    # out-of-library: every confident reading is wrong
    assert score_case("translational_lift", "outside", verdict)["confident_wrong"]
    assert np.isclose(score_case("none", "none", read_verdict(
        {"outcome": "no_significant_gap", "effect": "no_significant_gap"}))["no_gap"], 1)


def test_stated_readings_say_each_explanation_once():
    """The b refit and an all-rotors-alike thrust_mismatch repeat thrust_factor's reading;
    an implausible alternative is never a reading; a real per-rotor pattern is."""
    from quadsim.gap.verdict import stated_readings

    rotors = {f"thrust_mismatch.rotor_{i}": -0.065 + 0.0001 * i for i in range(1, 5)}
    ci = dict.fromkeys(rotors, 0.0025)
    alts = [{"name": "mass_offset", "plausible": True},
            {"name": "thrust_factor", "plausible": True},
            {"name": "thrust_mismatch", "plausible": True, "params": rotors, "ci": ci},
            {"name": "nominal_refit", "plausible": True},
            {"name": "thrust_curve", "plausible": False}]
    assert [a["name"] for a in stated_readings(alts)] == ["mass_offset", "thrust_factor"]
    uneven = {**rotors, "thrust_mismatch.rotor_2": -0.02}
    alts[2] = {**alts[2], "params": uneven}
    assert [a["name"] for a in stated_readings(alts)] == ["mass_offset", "thrust_factor",
                                                          "thrust_mismatch"]
    # without thrust_factor among them, the b refit is a reading of its own
    assert [a["name"] for a in stated_readings([alts[0], alts[3]])] == ["mass_offset",
                                                                         "nominal_refit"]


def test_summary_says_when_a_refit_parameter_is_not_identified():
    """Item 8(c) in the per-flight summary line: the reference refit's d at its -90 % bound
    (10 real Crazyflie references) is printed with that flag, never as a plain number."""
    from quadsim.gap.report import _fmt_params

    text = _fmt_params({"nominal_refit.thrust": -0.0042, "nominal_refit.drag": -0.9},
                       {"nominal_refit.thrust": 0.006, "nominal_refit.drag": 0.018},
                       {"nominal_refit.thrust": True, "nominal_refit.drag": False})
    thrust, drag = text.split(", ")
    assert "not identified" in drag and "not identified" not in thrust
    assert drag.startswith("nominal_refit.drag = -0.9 ± 0.018 (relative)")


def test_a_canted_rotor_is_compared_with_reference_fits_of_the_same_rotor():
    """Reference flights that picked rotor 1 say nothing about rotor 3's tilt."""
    def tilt(rotor, value, ci):
        return {"name": "canted_rotor", "fixed": {"canted_rotor.rotor": float(rotor)},
                "params": {"canted_rotor.tilt_x": value}, "ci": {"canted_rotor.tilt_x": ci},
                "identifiable": {"canted_rotor.tilt_x": True},
                "significant": {"canted_rotor.tilt_x": abs(value) > ci}}

    refs = [tilt(1, 0.04, 0.01), tilt(1, 0.05, 0.01)]
    assert not differs_from_reference(tilt(1, 0.045, 0.005), refs)
    assert differs_from_reference(tilt(3, 0.045, 0.005), refs)
