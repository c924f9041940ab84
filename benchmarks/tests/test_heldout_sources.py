"""benchmarks.heldout_sources without a simulator: the extra flights' seeds and speeds, their
cache (flown once, keyed by the source's code hash and the flights' recipe), the case list
parser, the scoring of hand-made held-out rows and the diagnosed set's rounds on a stand-in
diagnosis; no verdict is computed."""

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


def test_third_training_flight():
    """--train 3: the third flight is seed 10 s + 3 at the case's own speed; the first two are
    the default's; more than the speed factors give is refused."""
    assert ho.extra_seeds(60_000, 3) == (600_001, 600_002, 600_003)
    case = {"case": "none", "truth": "none", "kind": "none", "seed": 60_003, "speed": 0.8,
            "effects": {}}
    source = _source([case], [])
    specs = ho.extra_specs(source, 0, case, 3)
    assert [n for n, _ in specs] == ["case_00_none_x1", "case_00_none_x2", "case_00_none_x3"]
    assert [s.seed for _, s in specs] == [600_031, 600_032, 600_033]
    assert [s.speed for _, s in specs] == pytest.approx([0.88, 0.72, 0.8], rel=1e-12)
    assert specs[:2] == ho.extra_specs(source, 0, case)
    with pytest.raises(ValueError):
        ho.extra_specs(source, 0, case, 4)


def test_bad_train_count_refused(capsys):
    for bad in ("1", "4"):
        assert ho.main(["--source", "crazyflow", "--cache", "x", "--train", bad]) == 2
        assert capsys.readouterr().err == "error: --train: 2-3 training flights per case\n"


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
    # a third training flight joins the same folder; the first two are kept
    assert ho.fly_extra(source, tmp_path, [1], progress=lambda m: None, count=3) == folder
    assert flown == [111, 112, 101, 102, 113]


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


class _Result:
    def __init__(self, raw):
        self.raw = raw

    def to_json(self):
        return self.raw


def _fit(name, params, reduction=0.5):
    return {"name": name, "params": params, "ci": {k: 0.1 * abs(v) for k, v in params.items()},
            "reduction": reduction}


def _diagnosis(outcome, effect, effects, combination=None, best=None):
    verdict = {"outcome": outcome, "effect": effect, "probability": 0.99, "tentative": True}
    if best:
        verdict["best_candidate"] = best
    return {"verdict": verdict, "effects": effects, "combination": combination}


def test_diagnosed_set_rounds(monkeypatch):
    """Round 1 names motor_lag+rotor_drag: both added at the combination's values; round 2
    (on top of them) names gyroscopic+rotor_drag: rotor_drag is in the set, gyroscopic is
    added alone at its single fit (--add gyroscopic); round 3: no_significant_gap, stop.
    Every round is diagnosed on 6 training and 2 held-out flights with the set so far."""
    import quadsim.gap

    answers = [
        _diagnosis("effect", "motor_lag+rotor_drag", [_fit("motor_lag", {
            "motor_lag.time_constant": 0.05})], _fit("motor_lag+rotor_drag", {
                "motor_lag.time_constant": 0.058, "rotor_drag.coefficient": 2.0e-6})),
        _diagnosis("effect", "gyroscopic+rotor_drag", [_fit("gyroscopic", {
            "gyroscopic.rotor_inertia": 3.5e-8})], _fit("gyroscopic+rotor_drag", {
                "gyroscopic.rotor_inertia": 3.4e-8, "rotor_drag.coefficient": 7e-7})),
        _diagnosis("no_significant_gap", "no_significant_gap", [])]
    calls = []

    def fake(train, params, *, holdout, kstep, base_effects):
        calls.append((train, holdout, kstep, [(e.name, None) for e in base_effects]))
        return _Result(answers[len(calls) - 1])

    monkeypatch.setattr(quadsim.gap, "diagnose", fake)
    kept, rounds = ho.diagnosed_set(list(range(8)), None, label="standin",
                                    progress=lambda m: None)
    assert [(n, {k: v for k, (v, _) in p.items()}) for n, p in kept] == [
        ("motor_lag", {"time_constant": 0.058}), ("rotor_drag", {"coefficient": 2.0e-6}),
        ("gyroscopic", {"rotor_inertia": 3.5e-8})]
    assert [c[0] for c in calls] == [list(range(6))] * 3
    assert [c[1] for c in calls] == [[6, 7]] * 3 and not any(c[2] for c in calls)
    assert [[n for n, _ in c[3]] for c in calls] == [
        [], ["motor_lag", "rotor_drag"], ["motor_lag", "rotor_drag", "gyroscopic"]]
    assert [r.added for r in rounds] == [("motor_lag", "rotor_drag"), ("gyroscopic",), ()]
    assert [bool(r.stop) for r in rounds] == [False, False, True]
    assert "nominal flights 0-5 (held out: 6, 7)" in kept[0][1]["time_constant"][1]


def test_diagnosed_set_unexplained_adds_most_probable(monkeypatch):
    """An unexplained answer adds its most probable reading's library part (rotor_drag of
    rotor_drag+nominal_refit, whose refit is no library effect); an unexplained answer with
    no reading stops the set."""
    import quadsim.gap

    answers = [
        _diagnosis("unexplained", "unexplained", [
            _fit("rotor_drag+nominal_refit", {"rotor_drag.coefficient": 2.5e-6,
                                              "nominal_refit.thrust": 0.01}),
            _fit("rotor_drag", {"rotor_drag.coefficient": 2.4e-6})],
            best="rotor_drag+nominal_refit"),
        _diagnosis("unexplained", "unexplained", [])]
    def fake(*args, **kwargs):
        return _Result(answers.pop(0))

    monkeypatch.setattr(quadsim.gap, "diagnose", fake)
    kept, rounds = ho.diagnosed_set(list(range(8)), None, label="x", progress=lambda m: None)
    assert [(n, p["coefficient"][0]) for n, p in kept] == [("rotor_drag", 2.4e-6)]
    assert rounds[0].via.startswith("--add") and rounds[0].added == ("rotor_drag",)
    assert len(rounds) == 2 and rounds[1].added == () and "names nothing" in rounds[1].stop


def test_diagnosed_set_stops_where_the_set_is_no_base(monkeypatch):
    """A round whose base the residual cannot evaluate (ModelError) ends the set: the effects
    added so far are kept, the round says why."""
    import quadsim.gap
    from quadsim.core.errors import ModelError

    answers = [_diagnosis("effect", "motor_lag", [_fit("motor_lag", {
        "motor_lag.time_constant": 0.02})])]

    def fake(*args, base_effects, **kwargs):
        if base_effects:
            raise ModelError("cable_payload: needs its internal state")
        return _Result(answers.pop(0))

    monkeypatch.setattr(quadsim.gap, "diagnose", fake)
    kept, rounds = ho.diagnosed_set(list(range(8)), None, label="x", progress=lambda m: None)
    assert [(n, p["time_constant"][0]) for n, p in kept] == [("motor_lag", 0.02)]
    assert [r.outcome for r in rounds] == ["effect", "error"]
    assert rounds[1].base == ("motor_lag",) and "no base" in rounds[1].stop


def test_references_flag_passes_the_sources_references_and_one_store(monkeypatch):
    """--references: every case is diagnosed against the source's per-flight nominal
    flights with the process's one MemoryStore (a stage put once is read by the next case);
    without it, no reference reaches the diagnosis."""
    import quadsim.gap

    calls = []

    def fake(train, params, *, holdout, kstep, base_effects, **extra):
        calls.append(extra)
        store = extra.get("store")
        if store is not None and store.get("key") is None:
            store.put(type("Kept", (), {"key": "key"})())
        return {"verdict": {"outcome": "no_significant_gap", "effect": "no_significant_gap",
                            "probability": 0.9, "tentative": False, "posterior": []}}

    monkeypatch.setattr(quadsim.gap, "diagnose", fake)
    monkeypatch.setattr(ho, "_STORE", ho.MemoryStore())
    row = {"name": "case_00_none", "truth": "none", "kind": "none", "effects": {},
           "_log": "held"}
    for _ in range(2):
        out = ho.judge_case(dict(row), ["a", "b"], None, reference=["r1", "r2"],
                            store=ho._STORE)
        assert out["heldout"]["score"]["no_gap"] is True and "_log" not in out
    assert [c["reference"] for c in calls] == [["r1", "r2"]] * 2
    assert calls[0]["store"] is calls[1]["store"] is ho._STORE and ho._STORE.made == 1
    ho.judge_case(dict(row), ["a", "b"], None)
    assert calls[-1] == {}
