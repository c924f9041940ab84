"""The per-flight text output (quadsim.gap.report, the CLI's notes) and the page of a result
read back from its JSON (no series: tables without figures; the page itself:
tests/test_report_html.py)."""

from __future__ import annotations

import pytest

from quadsim.gap.__main__ import gather_notes
from quadsim.gap.report import flights_summary, write_html


def _reading(name, p, magnitude, undetermined=()):
    return {"name": name, "probability": p, "magnitude": magnitude, "log_evidence": 0.0,
            "params": {}, "ci": {}, "undetermined": list(undetermined), "fixed": {},
            "variant": ""}


def _flight(name, verdict, p, lead, others=(), symptom=None, delays=None, notes=(),
            lack=None):
    outcome = verdict if verdict in ("no_significant_gap", "unexplained") else "effect"
    return {"file": f"/data/{name}", "outcome": outcome, "verdict": verdict,
            "probability": p, "answer": f"{verdict} ({100 * p:.0f} %): {lead}.",
            "posterior": [_reading("no_difference" if outcome == "no_significant_gap"
                                   else verdict, p, lead)] + list(others),
            "lack_of_fit": lack or {}, "symptom": symptom or {},
            "signal_delays_ms": delays or {}, "notes": list(notes), "readings": [verdict],
            "differ_on": [], "separate_by": {}}


def _deficit(value):
    return {"channel": "Fz", "sign": "-", "value": value, "sigmas": 9.0,
            "text": f"Fz {100 * value / 0.363:+.1f} % of the weight"}


@pytest.fixture
def result():
    mass = "+6.1 ± 0.3 g heavier (+16.5 % of the model's 37 g)"
    flights = [
        _flight("a.csv", "mass_offset", 0.93, mass,
                [_reading("thrust_factor", 0.07, "-14 ± 1 % thrust per Ω² on all 4 rotors")],
                symptom=_deficit(-0.062), delays={"rotor": 3.1, "gyro": 0.4},
                notes=[("/data/a.csv: signal delays vs motion capture: rotor +3.1 ms, gyro "
                       "+0.4 ms (estimated; a gyro delay of 1.5 samples or more is shifted "
                       "out before fitting, the others are reported only)")]),
        _flight("b.csv", "thrust_curve", 0.6, "-17 ± 1 % thrust at the hover speed",
                [_reading("mass_offset", 0.4, "+6.3 ± 0.3 g heavier")],
                symptom=_deficit(-0.060), delays={"rotor": 2.8},
                notes=["/data/b.csv: gyro delay not resolvable (flat correlation)"]),
        _flight("c.csv", "no_significant_gap", 0.97, "no difference from the reference "
                "flights", symptom={"channel": "Mz", "sign": "+", "value": 1e-6,
                                   "sigmas": 0.4, "text": "Mz +0.001 mN m"},
                delays={"rotor": 3.0}),
        {"file": "/data/bad.csv", "outcome": "refused", "verdict": "refused",
         "answer": "Not judged: /data/bad.csv: accel: looks like g", "probability": None,
         "reason": "/data/bad.csv: accel: looks like g", "readings": [], "posterior": [],
         "notes": []},
    ]
    return {"schema": "quadsim.gap/3", "model": "crazyflie21", "mode": "per-flight",
            "reference": ["r1", "r2"],
            "reference_model": {
                "params": {"nominal_refit.thrust": 0.012, "wind.vx": -30.0},
                "se": {"nominal_refit.thrust": 0.001, "wind.vx": 1e3},
                "scatter": {"nominal_refit.thrust": 0.002, "wind.vx": 0.0},
                "identified": {"nominal_refit.thrust": True, "wind.vx": False},
                "sigma": {}, "correlation_samples": {},
                "delays_ms": {"rotor": {"mean": 3.0, "sd": 0.2, "count": 2}}},
            "flights": flights, "notes": ["only 2 reference flights: give 10 or more"],
            "verdict": {"answer": "3 flights judged against the reference flights: 1 "
                                  "mass_offset, 1 no_significant_gap, 1 thrust_curve; 1 "
                                  "refused (see each flight's reason)"}}


def test_span_notes_of_many_logs_are_one_warning():
    lines = [f"/data/f{k}.csv: airborne span t 1.{k}0-4{k}.50 s kept (4{k}.40 of 50.00 s); "
             f"cut: ground 0.00-1.{k}0 s; landing 4{k}.50-50.00 s" for k in range(3)]
    lines += ["/data/f0.csv: vbat: constant", "/data/f1.csv: vbat: constant"]
    out = gather_notes(lines)
    assert out == ["/data/f0.csv: vbat: constant (and 1 more file alike)",
                   ("airborne span kept (ground, idle and landing spans cut) on 3 logs: "
                   "f0.csv 1.00-40.50 s, f1.csv 1.10-41.50 s, f2.csv 1.20-42.50 s")]


def test_summary_states_each_answer_once_and_gathers_delay_notes(result):
    result["notes"] += [
        f"/data/r{k}.csv: gyro: delay not resolvable from this log (the two halves give "
        f"+{k}8.6 and -9{k}.6 ms, more than 10 ms apart: filtered or delayed beyond what its "
        "partner signal can time)" for k in range(2)]
    result["notes"] += [
        f"/data/r{k}.csv: signal delays vs motion capture: rotor +3.{k} ms (estimated; a gyro "
        "delay of 1.5 samples or more is shifted out before fitting, the others are reported "
        "only)" for k in range(2)]
    lines = flights_summary(result).splitlines()
    assert lines[2] == "  a.csv: mass_offset (93 %): +6.1 ± 0.3 g heavier (+16.5 % of the " \
                       "model's 37 g)."
    assert lines[5] == "  bad.csv: Not judged: /data/bad.csv: accel: looks like g"
    notes = [line for line in lines if line.startswith("note: ")]
    assert notes == [
        "note: only 2 reference flights: give 10 or more",
        ("note: gyro: delay not resolvable on 2 flights, the two halves of each log disagree "
        "(more than 10 ms apart: filtered or delayed beyond what its partner signal can time): "
        "r0.csv (+08.6 / -90.6 ms), r1.csv (+18.6 / -91.6 ms)"),
        ("note: signal delays vs motion capture (estimated; a gyro delay of 1.5 samples or more "
        "is shifted out before fitting, the others are reported only): r0.csv rotor +3.0 ms; "
        "r1.csv rotor +3.1 ms")]


def test_the_summary_says_the_residual_in_the_reports_words(result):
    text = ("Residual up to 4x the references' RMS (Fz) before the answer, 1.5x (Fz) after "
            "it: it removes 96 % of the excess.")
    result["flights"][0]["residual"] = {"rms_before": {}, "rms_after": {}, "removed": 0.96,
                                        "text": text}
    lines = flights_summary(result).splitlines()
    assert lines[2].startswith("  a.csv: mass_offset (93 %)") and lines[3] == f"    {text}"


def test_the_page_of_a_result_read_back_from_json(result, tmp_path):
    page = write_html(tmp_path / "r.html", result).read_text(encoding="utf-8")
    assert "<svg" not in page                      # no series in a JSON: no figures
    assert '<td class="name">a.csv</td>' in page and "mass_offset 93 %" in page
    assert "refused" in page and "looks like g" in page
    shown = page[:page.index("<details>")]         # the JSON appendix has every number
    assert "not determined by the reference flights" in shown and "-30" not in shown


def test_the_old_page_function_is_refused_with_what_to_change():
    with pytest.raises(ImportError, match=r"quadsim\.gap\.page\.page\(result\)"):
        from quadsim.gap.report import flights_html  # noqa: F401


def test_a_reference_model_at_a_bound_is_said_in_the_notes():
    """``words.bound_words``: every shared value at a bound of the references' fit, grouped
    by effect, in words with its value and why the bound is there; none at a bound: "".
    The per-flight notes carry it (``diagnose._stage_notes``), so the text output says it."""
    from types import SimpleNamespace

    from quadsim.gap.diagnose import _stage_notes
    from quadsim.gap.words import bound_words
    from quadsim.vehicle.params import load_params

    params = load_params("crazyflie21")
    values = {"inertia_error.xx": 2.0, "rate_damping.z": 0.0,
              "motor_lag.time_constant": 0.0025, "wind.vx": 0.3}
    reference = SimpleNamespace(
        params=params, values=lambda: values,
        at_bound={"inertia_error.xx": "upper", "rate_damping.z": "lower",
                  "motor_lag.time_constant": "lower"})
    text = bound_words(reference)
    ixx = params.inertia[0][0]                   # kg m^2; +200 % reads 3x it
    assert text.startswith("the reference model's fit stops at a bound: I_xx +200 % "
                           f"({3 * ixx:.3g} kg m² instead of the model's {ixx:.3g} kg m²), "
                           "at the upper end of its range; yaw rate damping +0 N m per rad/s")
    assert "+2.5 ms (time constant), at its bound: a quarter of a fit sample" in text
    assert "wind" not in text                    # not at a bound: not named
    assert bound_words(SimpleNamespace(at_bound={}, params=params, values=dict)) == ""
    kept = SimpleNamespace(count=20, reference=reference, notes=("delay note",))
    assert _stage_notes(kept) == [text, "delay note"]
    kept = SimpleNamespace(count=20, reference=SimpleNamespace(at_bound={}, values=dict),
                           notes=())
    assert _stage_notes(kept) == []


def test_a_thrust_the_sets_mass_and_b_do_not_give_is_said():
    """``words.refit_words``: the references' b refit beyond another session's air (2.8 %)
    is said with its factor and what it means for a mass reading (the balance fixes b / m
    only); within it, nothing."""
    from types import SimpleNamespace

    from quadsim.effects.thrust_factor import SESSION_SPREAD
    from quadsim.gap.words import refit_words
    from quadsim.vehicle.params import load_params

    params = load_params("crazyflie21")

    def ref(x):
        return SimpleNamespace(params=params, values=lambda: {"nominal_refit.thrust": x})

    assert refit_words(ref(0.99 * SESSION_SPREAD.relative)) == ""
    assert refit_words(SimpleNamespace(params=params, values=dict)) == ""
    text = refit_words(ref(0.21))
    assert text.startswith("the reference flights' weight balance needs 1.21x the parameter "
                           "set's thrust per Omega^2 (b) at its mass of 37 g, beyond the 2.8 %")
    assert "off by the same factor (+21 %)" in text
    assert refit_words(ref(-0.1)).startswith("the reference flights' weight balance needs "
                                             "0.9x")
