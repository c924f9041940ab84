"""Per-flight posterior (quadsim.gap.judge), combination readings and benchmark scoring:
numbers checked against hand-built entries (the rules are pure over the fit results)."""

from __future__ import annotations

import numpy as np
import pytest

from quadsim.bench.score import read_verdict, score_case
from quadsim.gap.combine import _combination_alternatives, parts_identified
from quadsim.gap.evidence import Evidence, Explanation
from quadsim.gap.judge import posterior
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


def _ev(name, log_z, determined=True, variant=""):
    expl = Explanation(name, variant, (), (0.0,), (1.0,))
    return Evidence(expl, {f"{name}.p": 1.0}, {f"{name}.p": 0.1}, {f"{name}.p": 1.0},
                    {f"{name}.p": determined}, log_z, np.ones(6))


def test_posterior_sums_variants_and_gives_no_difference_the_effects_prior():
    """Two effects and no difference at equal evidence: no difference has the prior of both
    effects together (1/2), each effect 1/4; an effect's variants add up; an explanation
    whose parameter the data do not determine is counted as no difference."""
    null = Evidence(Explanation("no_difference", "", (), (), ()), {}, {}, {}, {}, 0.0,
                    np.ones(6))
    rows = [null, _ev("mass_offset", 0.0),
            _ev("thrust_mismatch", np.log(0.5), variant="rotor 1"),
            _ev("thrust_mismatch", np.log(0.5), variant="rotor 2")]
    post = {k: p for k, p, _ in posterior(rows)}
    assert post == pytest.approx({"no_difference": 0.5, "mass_offset": 0.25,
                                  "thrust_mismatch": 0.25})
    rows[1] = _ev("mass_offset", 0.0, determined=False)
    post = {k: p for k, p, _ in posterior(rows)}
    # mass_offset's weight joins no difference: (2 + 1) / (2 + 1 + 1)
    assert post == pytest.approx({"no_difference": 0.75, "thrust_mismatch": 0.25})
    # 3 nats more evidence for a mass: e^3 / (e^3 + 2 + 1)
    rows[1] = _ev("mass_offset", 3.0)
    post = {k: p for k, p, _ in posterior(rows)}
    assert post["mass_offset"] == pytest.approx(np.exp(3) / (np.exp(3) + 3), rel=1e-9)


def test_refused_flight_is_read_as_refused_and_never_confident():
    verdict = read_verdict({"file": "f", "outcome": "refused", "verdict": "refused",
                            "reason": "x", "probability": None})
    assert verdict["outcome"] == "refused" and not verdict["confident"]
    tentative = read_verdict({"outcome": "effect", "verdict": "mass_offset",
                              "probability": 0.6, "tentative": True,
                              "readings": ["mass_offset", "thrust_factor"]})
    assert tentative["probability"] == 0.6 and not tentative["confident"]
    assert tentative["named"] == ["mass_offset", "thrust_factor"]


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
