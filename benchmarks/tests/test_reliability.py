"""The reliability table's arithmetic (benchmarks.reliability): Wilson interval in closed
form, binning at the edges, scoring of labelled per-flight results."""

from __future__ import annotations

import math

import pytest

from benchmarks.reliability import (
    PAYLOAD_TOTAL,
    Answer,
    bin_label,
    format_table,
    mixed_answers,
    reliability_table,
    wilson_interval,
)


def test_wilson_interval_closed_form():
    # 8 of 10, z = 1.96: centre (0.8 + 0.19208) / 1.38416, half 1.96 sqrt(0.016 + 0.0009604)
    # / 1.38416 (Wilson 1927; Agresti & Coull 1998, Table 1 style numbers)
    z = 1.96
    lo, hi = wilson_interval(8, 10, z=z)
    denom = 1 + z * z / 10
    centre = (0.8 + z * z / 20) / denom
    half = z * math.sqrt(0.8 * 0.2 / 10 + z * z / 400) / denom
    assert (lo, hi) == pytest.approx((centre - half, centre + half), rel=1e-12)
    assert (lo, hi) == pytest.approx((0.4902, 0.9433), abs=1e-4)
    # all right: the upper end is 1, the lower n / (n + z^2)
    lo, hi = wilson_interval(14, 14, z=z)
    assert hi == 1.0 and lo == pytest.approx(14 / (14 + z * z), rel=1e-12)
    assert wilson_interval(0, 5, z=z)[0] == 0.0
    assert all(math.isnan(v) for v in wilson_interval(0, 0))


def _answer(p, right, outcome="effect"):
    return Answer("t", "f", "x", outcome, "v", p, right)


def test_binning_puts_each_edge_in_the_upper_bin():
    answers = [_answer(0.2, True), _answer(0.7, False), _answer(0.89, True),
               _answer(0.9, True), _answer(0.99, True), _answer(1.0, False)]
    rows = reliability_table(answers)
    assert [r.label for r in rows] == ["<0.7", "0.7-0.9", "0.9-0.99", ">=0.99"]
    assert [r.answers for r in rows] == [1, 2, 1, 2]
    assert rows[1].mean_stated == pytest.approx(0.795)
    assert rows[1].fraction_right == 0.5 and rows[3].fraction_right == 0.5
    assert rows[1].low == pytest.approx(wilson_interval(1, 2)[0])
    assert bin_label(0) == "<0.7" and bin_label(3) == ">=0.99"
    empty = reliability_table([_answer(0.95, True)])
    assert empty[0].answers == 0 and math.isnan(empty[0].fraction_right)


def test_unexplained_answers_are_counted_apart():
    text = format_table("t", [_answer(0.99, True), _answer(0.99, False, "unexplained")])
    assert "t: 1 answers" in text and "not binned: 1 unexplained or refused, 0 of them" in text


def test_mixed_scoring_needs_the_name_and_the_total():
    labels = {"flights": {"a.csv.gz": {"label": "payload"}, "b.csv.gz": {"label": "payload"},
                          "c.csv.gz": {"label": "none"}, "d.csv.gz": {"label": "payload"}}}
    near = PAYLOAD_TOTAL - 0.0015        # within 2 g
    result = {"flights": [
        {"file": "x/a.csv.gz", "outcome": "effect", "verdict": "cable_payload+mass_offset",
         "probability": 0.99, "params": {"cable_payload.mass": near - 0.003,
                                         "mass_offset.mass": 0.003}},
        {"file": "b.csv.gz", "outcome": "effect", "verdict": "mass_offset",
         "probability": 0.95, "params": {"mass_offset.mass": PAYLOAD_TOTAL - 0.0025}},
        {"file": "c.csv.gz", "outcome": "no_significant_gap", "verdict": "no_significant_gap",
         "probability": 0.8, "params": {}},
        {"file": "d.csv.gz", "outcome": "effect", "verdict": "wind", "probability": 0.9,
         "params": {"wind.vx": 0.1}}]}
    got = {a.flight: (a.right, a.stated) for a in mixed_answers(result, labels)}
    assert got == {"a.csv.gz": (True, 0.99), "b.csv.gz": (False, 0.95),
                   "c.csv.gz": (True, 0.8), "d.csv.gz": (False, 0.9)}
    with pytest.raises(KeyError):
        mixed_answers({"flights": [{"file": "e.csv.gz"}]}, labels)


def test_a_result_without_per_flight_verdicts_is_refused_in_one_line(tmp_path, capsys):
    """A held-out result (or any JSON without ``flights``) is not scored as an empty table:
    exit 2, one line naming the file and the field, nothing written."""
    from benchmarks.reliability import main

    bad = tmp_path / "held_out.json"
    bad.write_text('{"schema": "quadsim.gap/3", "verdict": {}}')
    labels = tmp_path / "labels.json"
    labels.write_text('{"flights": {}}')
    out = tmp_path / "out.json"
    assert main(["--mixed", str(bad), "--labels", str(labels), "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {bad}: flights:")
    assert not out.exists()


def test_generated_set_scores_flapping_in_the_library_and_adds_an_outside_wake():
    """Blade flapping joined the library: its flight is scored as ``blade_flapping``; the
    out-of-library flight is a rotor-rotor wake drawn from a generator of its own, so the
    earlier flights' draws (and the log speeds drawn after the list) are unchanged."""
    import numpy as np

    from benchmarks.draws import draw
    from benchmarks.outside import BladeFlapping
    from benchmarks.reliability import FLAPPING, LIBRARY, NO_EFFECT, OUTSIDE, _generated_cases
    from benchmarks.unmodelled import RotorWake
    from quadsim.vehicle.params import load_params

    params = load_params("crazyflie21")
    rng = np.random.default_rng(47)
    cases = _generated_cases(params, rng)
    truths = [t for t, _ in cases]
    assert truths == (["none"] * NO_EFFECT + list(LIBRARY) + ["blade_flapping"] * FLAPPING
                      + ["outside:rotor_wake"] * OUTSIDE)
    flap, wake = cases[-2][1][0], cases[-1][1][0]
    assert isinstance(flap, BladeFlapping) and isinstance(wake, RotorWake)
    assert 0.02 <= wake.k_wake <= 0.04          # draw_unmodelled's realistic range
    # the generator the log speeds are drawn from continues as if the wake were not there
    again = np.random.default_rng(47)
    for name in LIBRARY:
        draw(name, params, again)
    again.uniform(0.02, 0.04)
    assert rng.uniform() == again.uniform()


def test_simulator_source_rows_are_scored_by_kind_and_read_both_probabilities():
    """A gap_benchmark per-case JSON: an observable library case is right when the lead
    names it, an unobservable one is not scored, no effect right as no_significant_gap, an
    outside case right only unexplained; ``within`` is the library-only probability (the
    stated one where a result predates the field)."""
    from benchmarks.reliability import benchmark_answers

    def row(name, kind, outcome, lead, p, within=None, observable=True, named=False):
        v = {"outcome": outcome, "lead": lead, "probability": p,
             "score": {"named": named, "lead": named}}
        if within is not None:
            v["probability_within_library"] = within
        return {"name": name, "truth": name, "kind": kind, "observable": observable,
                "per_flight": v}

    rows = [row("mass", "library", "named", ["mass_offset"], 0.99, named=True),
            row("wind", "library", "named", ["wind"], 0.9, observable=False, named=True),
            row("none_0", "none", "no_significant_gap", [], 0.95, within=0.95),
            row("wake", "outside", "named", ["blade_flapping"], 0.51, within=1.0),
            row("lift", "outside", "unexplained", [], 0.99, within=0.99)]
    got = {a.flight: (a.outcome, a.right, a.stated, a.within)
           for a in benchmark_answers(rows, "src")}
    assert got == {"mass": ("effect", True, 0.99, 0.99),
                   "none_0": ("no_significant_gap", True, 0.95, 0.95),
                   "wake": ("effect", False, 0.51, 1.0),
                   "lift": ("unexplained", True, 0.99, 0.99)}
    with pytest.raises(ValueError, match="per_flight"):
        benchmark_answers([{"name": "x"}])


def test_a_missing_labels_file_is_named_not_the_result(tmp_path, capsys):
    """Outside the repository's layout the default labels path does not exist; the error
    named the --mixed result ("error: RESULT.json: [Errno 2] ... mixed_labels.json")."""
    from benchmarks.reliability import main

    result = tmp_path / "mixed.json"
    result.write_text('{"mode": "per-flight", "flights": []}')
    missing = tmp_path / "no" / "mixed_labels.json"
    assert main(["--mixed", str(result), "--labels", str(missing)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {missing}: --labels: No such file or directory"]
