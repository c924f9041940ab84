"""The fly/cache/check machinery shared by the simulator sources (benchmarks.sim_cases),
on a stand-in source whose "simulator" writes hovering logs: every flight is flown once and
reused from the cache, the cache key follows the case list, the rows carry the checked
observability with the source's threshold and its scored kind; no verdict is computed."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from benchmarks import sim_cases
from quadsim.logs.flightlog import FlightLog


@dataclass(frozen=True)
class _Spec:
    seed: int
    speed: float = 1.0
    duration: float = 0.2


def _hover_log(spec: _Spec) -> FlightLog:
    n = round(spec.duration * 100)
    t = np.arange(n) / 100.0
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    accel = np.tile([0.0, 0.0, 9.81 + 0.01 * spec.seed], (n, 1))
    return FlightLog(t, np.zeros((n, 3)), quat, np.zeros((n, 3)), np.zeros((n, 3)), accel,
                     np.full((n, 4), 1500.0), np.full((n, 4), 0.4), None, None)


def _source(cases: list[dict], flown: list) -> sim_cases.CaseSource:
    def fly(specs):
        flown.extend(s.seed for s in specs)
        return [(_hover_log(s), {"source": "stand-in", "seed": s.seed}) for s in specs]

    def observe(logs, refs, rows):
        assert len(refs) == 2 and len(logs) == len(rows)
        return [(0.01 * (k + 1), 1.0 + k) for k in range(len(rows))]

    return sim_cases.CaseSource(
        name="standin", package="numpy", modules=("simlog.py",),
        references=lambda: [_Spec(seed=1), _Spec(seed=2)], cases=lambda: cases,
        case_spec=lambda c: _Spec(seed=c["seed"]), fly=fly, observe=observe,
        scored_kind=lambda c: "library" if c["case"] == "joined" else c["kind"],
        params=lambda: None, observable=0.015)


def test_generate_once_reuse_and_rows(tmp_path):
    """Two references and three cases are flown once (one batch); a second generate flies
    nothing and keeps every byte; the rows carry reduction, gap ratio, the scored kind (a
    case joined to the library) and observable = reduction >= threshold for library cases
    only; a changed case list is a new cache folder."""
    cases = [{"case": "mass_offset", "truth": "mass_offset", "kind": "library", "seed": 10,
              "speed": 1.0, "effects": {"mass": 0.002}},
             {"case": "none", "truth": "none", "kind": "none", "seed": 11, "speed": 1.0,
              "effects": {}},
             {"case": "joined", "truth": "joined", "kind": "outside", "seed": 12,
              "speed": 1.0, "effects": {}}]
    flown: list = []
    source = _source(cases, flown)
    folder = sim_cases.generate(source, tmp_path, progress=lambda m: None)
    assert flown == [1, 2, 10, 11, 12]
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    assert sim_cases.generate(source, tmp_path, progress=lambda m: None) == folder
    assert flown == [1, 2, 10, 11, 12]
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    truth = json.loads((folder / "case_00_mass_offset.truth.json").read_text())
    assert truth["truth"] == "mass_offset" and truth["case"] == "mass_offset"
    refs, rows = sim_cases.load_flights(source, tmp_path)
    assert len(refs) == 2 and [r["name"] for r in rows] == ["case_00_mass_offset",
                                                            "case_01_none", "case_02_joined"]
    assert [r["oracle_reduction"] for r in rows] == [0.01, 0.02, 0.03]
    assert [r["gap_vs_references"] for r in rows] == [1.0, 2.0, 3.0]
    assert [r["kind"] for r in rows] == ["library", "none", "library"]
    assert [r["flown_as"] for r in rows] == ["library", "none", "outside"]
    assert [r["observable"] for r in rows] == [False, True, True]
    np.testing.assert_allclose(rows[0]["_log"].accel[:, 2], 9.81 + 0.1, atol=1e-9)
    other = _source(cases[:2], [])
    assert sim_cases.flight_dir(other, tmp_path) != folder


def _benchmark_script():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "gap_benchmark.py"
    spec = importlib.util.spec_from_file_location("gap_benchmark_script", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_simulator_summary_and_missing_cache(capsys):
    """benchmarks/gap_benchmark.py's simulator table: the observability-only table names the
    source and marks an unobservable library case; the blind-run table scores hand-made
    verdicts (a named case, a no-gap flight); every ``--source`` (pyflyt, the l2f vehicles,
    ...) without ``--cache`` is one error line and exit 2 (nothing flown)."""
    from benchmarks.score import score_case

    script = _benchmark_script()
    source = _source([], [])
    rows = [{"name": "case_00_mass_offset", "truth": "mass_offset", "kind": "library",
             "speed": 1.0, "effects": {"mass": 0.002}, "gap_vs_references": 3.0,
             "oracle_reduction": 0.5, "observable": True},
            {"name": "case_01_inertia_error", "truth": "inertia_error", "kind": "library",
             "speed": 1.1, "effects": {"inertia": (0.2, 0.2, 0.0)},
             "gap_vs_references": 1.1, "oracle_reduction": 0.01, "observable": False},
            {"name": "case_02_none", "truth": "none", "kind": "none", "speed": 0.5,
             "effects": {}, "gap_vs_references": 0.7, "oracle_reduction": 0.0,
             "observable": True}]
    text = script.summarise_simulator(rows, source)
    assert "standin change" in text and "1 of 2 in-library" in text
    assert "case_01_inertia_error" in text.splitlines()[0]
    assert "0.01 (not observable)" in text and "verdict" not in text
    named = {"outcome": "named", "lead": ["mass_offset"], "named": ["mass_offset"],
             "readings": 1, "alternatives": [], "confident": True}
    quiet = {"outcome": "no_significant_gap", "lead": [], "named": [], "readings": 0,
             "alternatives": [], "confident": False}
    for row, verdict in zip(rows, (named, {**quiet, "outcome": "unexplained"}, quiet)):
        row["per_flight"] = {**verdict, "score": score_case(row["truth"], row["kind"],
                                                            verdict)}
    text = script.summarise_simulator(rows, source, observability_only=False)
    assert "| standin | per-flight | 100% (1/1) |" in text.replace(" %", "%")
    assert "| 100% (1/1) | 0/0 |" in text.replace(" %", "%")
    for name in script.SIM_SOURCES:          # every source, the l2f vehicles included
        assert script.main(["--independent", "--source", name]) == 2, name
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"error: --source {name}:"), err


def test_a_source_that_cannot_be_judged_is_one_error_line(tmp_path, capsys, monkeypatch):
    """A flight lost while flying, or references the diagnosis refuses (l2f's arpl vehicle
    with b 2.7x low at hover), end ``--independent --source`` with one error line and exit 2,
    the output not written (a traceback before)."""
    import sys
    import types as _types

    from quadsim.core.errors import InputError, ModelError

    script = _benchmark_script()
    fake = _types.ModuleType("fake_cases")
    fake.SOURCE = _source([], [])
    fake.ok = lambda: True
    monkeypatch.setitem(sys.modules, "fake_cases", fake)
    monkeypatch.setitem(script.SIM_SOURCES, "fake", ("fake_cases", "fake_cases", "ok", ""))
    out = tmp_path / "x.json"
    for error in (ModelError("l2f flight (seed 85009) lost control at t = 8.05 s"),
                  InputError("model 'l2f-arpl' does not describe the logged vehicle")):
        def fail(*args, error=error, **kwargs):
            raise error
        monkeypatch.setattr(sim_cases, "generate", fail)
        assert script.run_simulator("fake", str(tmp_path), False, str(out)) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"error: --source fake: {error}"]
        assert not out.exists()


def test_self_check_line():
    """The runner's one line for the references' self-check (``sim_cases.judge``'s
    ``self_check``): the count of false alarms of n with each flight's verdict, clean or
    not, the channels; a result without one says so."""
    script = _benchmark_script()
    clean = {"flights": 8, "clean": True, "false_alarms": [], "channels": []}
    assert script.self_check_line(clean) == (
        "self-check of the references: 0 of 8 judged against the others not "
        "no_significant_gap (none); clean")
    bad = {"flights": 8, "clean": False, "channels": ["Fx", "Mz"],
           "false_alarms": [["ref_00", "body_drag"], ["ref_03", "unexplained"]]}
    assert script.self_check_line(bad) == (
        "self-check of the references: 2 of 8 judged against the others not "
        "no_significant_gap (ref_00 body_drag, ref_03 unexplained); NOT clean; channels "
        "Fx, Mz")
    assert script.self_check_line(None) == "self-check of the references: none in the result"
