"""Per-flight posterior (quadsim.gap.judge), combination readings and benchmark scoring:
numbers checked against hand-built entries (the rules are pure over the fit results)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.score import read_verdict, score_case
from quadsim.gap.evidence import Evidence, Explanation
from quadsim.gap.fitting import describe
from quadsim.gap.judge import every_part_stands, posterior
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


def test_every_part_of_a_reading_must_be_identified(cf):
    """wind fitted as 0.002 +- 0.1 m/s with rotor drag is rotor drag alone: not a reading."""
    assert not every_part_stands(_wind(0.002, 0.1), cf)
    assert every_part_stands(_wind(1.0, 0.1), cf)


def test_a_combination_reading_describes_every_part(cf):
    """A pair's magnitude in words (the live reading text, quadsim.gap.judge.reading_text)
    states each of its effects with units: +4 g on the model's mass, I_xx +30 %."""
    values = {"mass_offset.mass": 0.004, "inertia_error.xx": 0.3, "inertia_error.yy": 0.3}
    ci = {"mass_offset.mass": 0.0002, "inertia_error.xx": 0.05, "inertia_error.yy": 0.05}
    text = describe("mass_offset+inertia_error", values, ci, cf)
    assert "+4 ± 0.2 g heavier" in text
    assert f"{100 * 0.004 / cf.mass:+.1f} % of the model's" in text
    for axis, i in (("xx", 0), ("yy", 1)):
        assert f"I_{axis} +30 ± 5 % ({1.3 * cf.inertia[i, i]:.3g} kg m² instead of" in text


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
