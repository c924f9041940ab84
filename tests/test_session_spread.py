"""A weighed mass's size on another session's air (issue 47): the between-session spread of
the thrust per Omega^2 from the ideal gas (quadsim.effects.thrust_factor.SESSION_SPREAD),
its arithmetic on the whole weighed mass (quadsim.gap.words.across_sessions), its words and
its JSON."""

from types import SimpleNamespace

import jsonschema
import numpy as np
import pytest

from quadsim.effects import EFFECTS
from quadsim.effects.thrust_factor import SESSION_SPREAD, SessionSpread, air_density_spread
from quadsim.gap.fitting import FIT_EFFECTS
from quadsim.gap.report import GAP_SCHEMA
from quadsim.gap.result import Reading, Verdict
from quadsim.gap.words import across_sessions, nominal_words, session_text, total_mass

R_AIR = 287.05          # J/(kg K), dry air's specific gas constant (ISA)


def _rho(p, t):
    return p / (R_AIR * t)


def test_the_air_density_spread_is_the_ideal_gas_ratio_of_two_sessions():
    """rho = p / (R T): two sessions at 20 and 26 C and the same pressure differ by
    ln(rho_20 / rho_26) = ln(299.15 / 293.15) = 2.03 % (0.34 %/K at 293 K); at one
    temperature and 1013.25 vs 993.25 hPa by ln(1013.25 / 993.25) ~ 20 / 1013.25 = 1.97 %;
    the declared spread is their quadrature sum, 2.83 %."""
    temperature = np.log(_rho(101325.0, 293.15) / _rho(101325.0, 299.15))
    assert temperature == pytest.approx(0.020261, abs=1e-6)
    per_kelvin = np.log(_rho(101325.0, 292.65) / _rho(101325.0, 293.65))
    assert per_kelvin == pytest.approx(0.0034, abs=0.0001)
    assert air_density_spread((293.15, 299.15), 0.0) == pytest.approx(temperature, rel=1e-12)
    assert air_density_spread((293.15, 293.15), 0.02) == pytest.approx(0.02, rel=1e-12)
    pressure = np.log(_rho(101325.0, 293.15) / _rho(99325.0, 293.15))
    assert pressure == pytest.approx(20.0 / 1013.25, rel=0.011)     # ln(1 + x) ~ x
    assert SESSION_SPREAD.relative == pytest.approx(
        np.sqrt(temperature ** 2 + (20.0 / 1013.25) ** 2), rel=1e-12)
    assert SESSION_SPREAD.relative == pytest.approx(0.0283, abs=5e-5)
    assert "ideal-gas" in SESSION_SPREAD.source and "propeller" in SESSION_SPREAD.source
    with pytest.raises(ValueError, match="temperature_k"):
        air_density_spread((300.0, 290.0), 0.01)
    with pytest.raises(ValueError, match="pressure_swing"):
        _ = SessionSpread((290.0, 300.0), -0.01, "x").relative


def test_the_gravity_balance_weighs_the_whole_mass_in_the_references_b():
    """Hover: M g = (1 + c) b sum Omega^2. Read at the references' b the mass is M / (1 + c);
    the added mass is off by M (1 / (1 + c) - 1) ~ -c M: the whole weighed mass (vehicle
    and payload), not the payload alone, to first order in c."""
    g, vehicle, payload, c = 9.81, 37e-3, 7.4e-3, SESSION_SPREAD.relative
    weighed = vehicle + payload
    thrust_per_speed = 1.0            # b sum Omega^2 / g at the references' b, per unit
    omega_sq = weighed * g / ((1 + c) * thrust_per_speed)
    read = thrust_per_speed * omega_sq / g - vehicle
    assert payload - read == pytest.approx(c * weighed, rel=1.1 * c)
    assert abs(payload - read) > 5 * c * payload


def _ev(values, sd, determined=None, cov=None):
    keys = list(values)
    return SimpleNamespace(values=dict(values), post_sd=dict(sd),
                           determined=determined or {k: True for k in keys},
                           post_cov=None if cov is None else np.asarray(cov, float))


def test_a_single_mass_widens_by_the_spread_times_the_weighed_mass_in_quadrature():
    """+6.6 g fixed, standard error 0.19 g (95 %: 0.37 g), on the model's 37 g at s = 2.83 %:
    sqrt(0.37^2 + (0.0283 x 43.6)^2) = 1.29 g; the position (not weighed) is not widened;
    an undetermined mass or no weighed mass: nothing; ``spread`` 0: the within-session one."""
    ev = _ev({"mass_offset.mass": 6.6e-3, "mass_offset.x": 0.004},
             {"mass_offset.mass": 0.19e-3, "mass_offset.x": 0.001})
    s = SESSION_SPREAD.relative
    out = across_sessions(ev, 37e-3)
    assert out["thrust_spread"] == s
    assert set(out["ci"]) == {"mass_offset.mass"} and "total_ci" not in out
    assert out["ci"]["mass_offset.mass"] == pytest.approx(
        np.hypot(1.96 * 0.19e-3, s * 43.6e-3), rel=1e-12)
    assert out["ci"]["mass_offset.mass"] == pytest.approx(1.29e-3, abs=0.01e-3)
    assert across_sessions(ev, 37e-3, 0.0)["ci"]["mass_offset.mass"] == pytest.approx(
        1.96 * 0.19e-3, rel=1e-12)
    assert across_sessions(ev, 37e-3, 0.05)["ci"]["mass_offset.mass"] == pytest.approx(
        np.hypot(1.96 * 0.19e-3, 0.05 * 43.6e-3), rel=1e-12)
    lighter = _ev({"mass_offset.mass": -2e-3}, {"mass_offset.mass": 0.1e-3})
    assert across_sessions(lighter, 37e-3, 0.02)["ci"]["mass_offset.mass"] == pytest.approx(
        np.hypot(0.196e-3, 0.02 * 35e-3), rel=1e-12)
    assert across_sessions(_ev({"mass_offset.mass": 1e-3}, {"mass_offset.mass": 1e-3},
                               {"mass_offset.mass": False}), 37e-3) == {}
    assert across_sessions(_ev({"thrust_factor.change": -0.02},
                               {"thrust_factor.change": 0.002}), 37e-3) == {}


def test_a_payloads_parts_and_total_each_carry_the_whole_weighed_mass():
    """+4 g on a cable and +2.7 g fixed (standard errors 0.1 and 0.2 g, correlated -0.5):
    the total's within-session half-interval (:func:`total_mass`) and each part's widen by
    s (37 + 6.7) g in quadrature; the cable's length is not weighed."""
    s1, s2, rho = 0.1e-3, 0.2e-3, -0.5
    cov = np.array([[s1 ** 2, rho * s1 * s2, 0.0], [rho * s1 * s2, s2 ** 2, 0.0],
                    [0.0, 0.0, 1e-4]])
    keys = ("cable_payload.mass", "mass_offset.mass", "cable_payload.length")
    ev = _ev(dict(zip(keys, (4e-3, 2.7e-3, 0.45))), dict(zip(keys, (s1, s2, 0.01))), cov=cov)
    s, part = 0.03, 0.03 * (37e-3 + 6.7e-3)
    out = across_sessions(ev, 37e-3, s)
    total = total_mass(ev)
    assert set(out["ci"]) == {"cable_payload.mass", "mass_offset.mass"}
    assert out["total_ci"] == pytest.approx(np.hypot(total["ci"], part), rel=1e-12)
    assert total["ci"] == pytest.approx(1.96 * np.sqrt(s1 ** 2 + s2 ** 2 + 2 * rho * s1 * s2),
                                        rel=1e-12)
    for k, sd in (("cable_payload.mass", s1), ("mass_offset.mass", s2)):
        assert out["ci"][k] == pytest.approx(np.hypot(1.96 * sd, part), rel=1e-12)


def test_the_weighed_parameters_are_declared_by_the_payload_effects_only():
    """mass_offset.mass and cable_payload.mass (and its fit form's) are weighed; no other
    library effect declares a weighed parameter."""
    weighed = {f"{n}.{p}" for n, cls in EFFECTS.items() for p in cls.facts.weighed}
    assert weighed == {"mass_offset.mass", "cable_payload.mass"}
    assert FIT_EFFECTS["cable_payload"].facts.weighed == ("mass",)


def test_the_words_state_both_widths_and_the_model_in_held_out_words():
    """1.29 g at s = 2.83 %: "± 1.3 g on another session's air (its thrust per Ω² ± 2.8 %:
    20-26 °C, pressure ± 2 %)"; the sum's where there is one; nothing without one; held out
    against the nominal model the references' b is the model's."""
    across = {"thrust_spread": 0.028286, "ci": {"mass_offset.mass": 1.29e-3}}
    assert session_text(across) == ("± 1.3 g on another session's air (its thrust per Ω² "
                                    "± 2.8 %: 20-26 °C, pressure ± 2 %)")
    both = {"thrust_spread": 0.028286, "ci": {"a.mass": 1.0e-3, "b.mass": 1.1e-3},
            "total_ci": 0.9e-3}
    assert session_text(both).startswith("± 0.9 g on another")
    assert session_text({}) == ""
    text = "+2.7 ± 0.39 g heavier at the reference flights' thrust per Ω²; ± 1.2 g"
    assert nominal_words(text, True) == ("+2.7 ± 0.39 g heavier at the model's thrust per "
                                         "Ω²; ± 1.2 g")
    assert nominal_words(text, True, references=True) == text


def test_the_json_key_is_additive_and_validated():
    """A Reading and a Verdict with ``across`` write ``across_sessions`` (absent without);
    GAP_SCHEMA accepts it on a flight and its posterior and rejects an unknown field in it."""
    across = {"thrust_spread": 0.0283, "ci": {"mass_offset.mass": 1.29e-3}}
    reading = Reading("mass_offset", 0.9, "+6.6 g", -10.0, {"mass_offset.mass": 6.6e-3},
                      {"mass_offset.mass": 0.37e-3}, across=across)
    assert reading.to_json()["across_sessions"] == across
    assert "across_sessions" not in Reading("mass_offset", 0.9, "x", -10.0).to_json()
    flight = Verdict("effect", "mass_offset", "words", 0.9, posterior=(reading,),
                     params=reading.params, ci=reading.ci, across=across, file="f.csv")
    doc = flight.to_json()
    assert doc["across_sessions"] == across and doc["ci"] == {"mass_offset.mass": 0.37e-3}
    result = {"schema": "quadsim.gap/3", "where": {}, "effects": [], "mode": "per-flight",
              "verdict": {"outcome": "effect", "effect": "see flights", "answer": "",
                          "reduction": None, "confusable_with": []},
              "flights": [doc]}
    jsonschema.validate(result, GAP_SCHEMA)
    result["flights"][0]["posterior"][0]["across_sessions"] = dict(across, spread=1.0)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(result, GAP_SCHEMA)
