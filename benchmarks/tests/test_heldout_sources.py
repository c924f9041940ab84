"""benchmarks.heldout_sources without a simulator: the extra flights' seeds and speeds, their
cache (flown once, keyed by the source's code hash and the module's bytes), the case list
parser, and the scoring of hand-made held-out rows; no verdict is computed."""

from __future__ import annotations

import json

import pytest

from benchmarks import heldout_sources as ho
from benchmarks import sim_cases
from benchmarks.score import score_case
from benchmarks.tests.test_sim_cases import _source


def test_extra_seeds_and_specs():
    """Seeds 10 s + 1, 10 s + 2; speeds x1.1 and x0.9; everything else of the case's spec."""
    assert ho.extra_seeds(60_000) == (600_001, 600_002)
    case = {"case": "mass_offset", "truth": "mass_offset", "kind": "library", "seed": 60_003,
            "speed": 0.8, "effects": {"mass": 0.002}}
    source = _source([case], [])
    specs = ho.extra_specs(source, 3, case)
    assert [n for n, _ in specs] == ["case_03_mass_offset_x1", "case_03_mass_offset_x2"]
    assert [s.seed for _, s in specs] == [600_031, 600_032]
    assert [s.speed for _, s in specs] == pytest.approx([0.88, 0.72], rel=1e-12)
    assert {s.duration for _, s in specs} == {0.2}


def test_derived_seeds_are_no_flight_of_the_source():
    """On the simulator sources' seed ranges (cases from 6e4, references 7e4-1.6e5) no
    derived seed is a case's or a reference's seed."""
    cases = set(range(60_000, 60_028)) | set(range(140_000, 140_028))
    refs = {70_000 + 31 * k for k in range(8)} | {150_000 + 31 * k for k in range(8)}
    derived = {s for c in cases for s in ho.extra_seeds(c)}
    assert len(derived) == 2 * len(cases) and not derived & (cases | refs)


def test_fly_extra_once_and_keyed(tmp_path):
    """The chosen cases' extra flights are flown once (seeds as derived), written with their
    truth, kept on a second call; the folder's key is not the per-flight folder's and
    follows the source's code hash."""
    cases = [{"case": "none", "truth": "none", "kind": "none", "seed": 10, "speed": 1.0,
              "effects": {}},
             {"case": "mass_offset", "truth": "mass_offset", "kind": "library", "seed": 11,
              "speed": 1.0, "effects": {"mass": 0.002}}]
    flown: list = []
    source = _source(cases, flown)
    folder = ho.fly_extra(source, tmp_path, [1], progress=lambda m: None)
    assert flown == [111, 112]
    assert folder.name == f"standin-heldout-{ho.heldout_hash(source)}"
    assert folder != sim_cases.flight_dir(source, tmp_path)
    truth = json.loads((folder / "case_01_mass_offset_x2.truth.json").read_text())
    assert truth["case_seed"] == 11 and truth["seed"] == 112 and truth["truth"] == "mass_offset"
    ho.fly_extra(source, tmp_path, [0, 1], progress=lambda m: None)
    assert flown == [111, 112, 101, 102]
    assert ho.heldout_dir(_source(cases[:1], []), tmp_path) != folder


def test_parse_cases():
    assert ho.parse_cases(None, 4) == [0, 1, 2, 3]
    assert ho.parse_cases("0-2,5,1", 6) == [0, 1, 2, 5]
    for bad in ("x", "3-", "7", "1-9"):
        with pytest.raises(ValueError):
            ho.parse_cases(bad, 6)


def _row(name, truth, kind, verdict, observable=True):
    return {"name": name, "truth": truth, "kind": kind, "speed": 1.0, "effects": {},
            "oracle_reduction": 0.5 if observable else 0.01, "observable": observable,
            "heldout": {**verdict, "score": score_case(truth, kind, verdict),
                        "raw": {"tentative": not verdict["confident"]}}}


def test_summary_scores_rows():
    """Named in-library 1 of 2 observable (an unobservable miss not counted), no effect 1 of
    2 clear, an out-of-library confident name counted wrong and a tentative one not."""
    def named(*names, confident=True):
        return {"outcome": "named", "lead": list(names[:1]), "named": list(names),
                "readings": 1, "alternatives": [], "probability": 0.99,
                "confident": confident}

    quiet = {"outcome": "no_significant_gap", "lead": [], "named": [], "readings": 0,
             "alternatives": [], "probability": 0.9, "confident": False}
    rows = [_row("a", "mass_offset", "library", named("mass_offset")),
            _row("b", "wind", "library", named("body_drag")),
            _row("c", "com_offset", "library", quiet, observable=False),
            _row("d", "none", "none", quiet),
            _row("e", "none", "none", named("motor_lag")),
            _row("f", "periodic_torque", "outside", named("inertia_error")),
            _row("g", "periodic_force", "outside", named("wind", confident=False))]
    text = ho.summarise(rows, 0.05, "standin")
    score = text.splitlines()[2]
    assert "| 50% (1/2) |" in score and "| 50% (1/2) | 1/2 |" in score
    assert [ho._ok(r) for r in rows] == [True, False, None, True, False, False, True]
    assert "| MISS (confident wrong) |" in text and "not observable" in text
