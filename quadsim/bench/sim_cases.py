"""Frozen single-flight cases of an independent simulator: fly, cache, check, judge once.

Shared by the Crazyflow and PyFlyt sources (:mod:`.crazyflow_cases`, :mod:`.pyflyt_cases`);
each describes itself as a :class:`CaseSource` (its reference flights, its frozen case list,
how to fly a batch, how a case maps to quadsim's library) and this module does the rest the
same way for both:

* :func:`generate` flies the references and every case once (one child process of the
  simulator), writes each flight as ``NAME.csv.gz`` (flight-log schema) with its truth
  sidecar ``NAME.truth.json`` into ``CACHE/<source>-<code hash>/``, and the observability
  of every case (:func:`oracle_reductions`) to ``observability.json``; flights already
  there are kept (same code hash, same bytes);
* :func:`load_flights` reads them back (no verdict);
* :func:`judge` is THE BLIND RUN: per-flight verdicts of every case against the references,
  scored by :mod:`.score`. Run it once, after the verdict rules are frozen.

Observability (:func:`oracle_reductions`): the library effect with the *true difference*
(case minus references, in quadsim's terms) is applied in quadsim's residual model
(:mod:`quadsim.gap.fitting`) on top of the references' shared physics at its true value; a
case is observable when that cuts the flight's normalised residual by at least the source's
threshold. For a rotor-log delay the "true effect" is the log shifted back by the true
delay. The second number is the flight's mean squared normalised residual under the shared
physics relative to the references' own (about 1: nothing the references lack).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path

import numpy as np

from .observe import TrueModel, per_flight_observability

__all__ = ["CaseSource", "code_hash", "draw_cases", "flight_dir", "generate", "judge",
           "load_flights", "oracle_reductions"]


@dataclass(frozen=True)
class CaseSource:
    """One independent simulator's frozen cases.

    name: prefix of the cache folder and of ``truth["source"]``; package: the distribution
    whose version enters the code hash; modules: file names in ``quadsim/bench`` the flights
    depend on (hashed); references() -> reference specs; cases() -> case rows (``case``,
    ``truth``, ``kind``, ``seed``, ``speed``, ``effects``); case_spec(case) -> spec;
    fly(specs) -> [(log, truth)]; observe(logs, reference_logs, cases) -> [(reduction, gap
    ratio)]; scored_kind(case) -> the kind a case is scored as; params() -> quadsim's
    parameter set of the simulator's nominal vehicle; observable: the threshold."""

    name: str
    package: str
    modules: tuple[str, ...]
    references: Callable[[], list]
    cases: Callable[[], list[dict]]
    case_spec: Callable[[dict], object]
    fly: Callable[[list], list]
    observe: Callable[[list, list, list], list]
    scored_kind: Callable[[dict], str]
    params: Callable[[], object]
    observable: float


def draw_cases(table, draw: Callable, *, source: str, vehicle: str, seed0: int,
               speeds: tuple[float, float], scored_as: dict) -> list[dict]:
    """A source's frozen cases from its ``table`` of rows (truth, kind, count, speed range or
    None): ``count`` cases per row, each from its own seed ``seed0 + index``: the effects
    drawn by ``draw(truth, rng)`` (numbers as floats, tuples as tuples of floats; none for a
    no-effect case), then the path speed uniform in the row's range (``speeds`` when None).
    Each case: source, vehicle, truth (``scored_as`` maps a case's name to the library name
    it is scored against), case, kind, seed, speed, effects."""
    out = []
    for truth, kind, count, row_speeds in table:
        for _ in range(count):
            seed = seed0 + len(out)
            rng = np.random.default_rng(seed)
            effects = {} if kind == "none" else {
                k: (tuple(float(x) for x in v) if isinstance(v, tuple) else float(v))
                for k, v in draw(truth, rng).items()}
            low, high = row_speeds or speeds
            out.append({"source": source, "vehicle": vehicle,
                        "truth": scored_as.get(truth, truth), "case": truth, "kind": kind,
                        "seed": seed, "speed": float(rng.uniform(low, high)),
                        "effects": effects})
    return out


def code_hash(source: CaseSource) -> str:
    """Hash of everything the flights depend on: the source's modules, the simulator's
    version, the reference specs and the case list (a change never reads a stale flight)."""
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256(version(source.package).encode())
    for name in source.modules:
        digest.update((here / name).read_bytes())
    digest.update(repr([(s.seed, s.speed, s.duration) for s in source.references()]).encode())
    digest.update(repr(source.cases()).encode())
    return digest.hexdigest()[:12]


def flight_dir(source: CaseSource, cache) -> Path:
    return Path(cache) / f"{source.name}-{code_hash(source)}"


def _name(role: str, k: int, truth: str) -> str:
    return f"{role}_{k:02d}_{truth}" if role == "case" else f"{role}_{k:02d}"


def generate(source: CaseSource, cache, progress=print) -> Path:
    """Fly, write and check every flight of ``source`` (module docstring); the folder."""
    from ..core.files import atomic_write_text
    from ..logs.flightlog import load_log, write_log
    from .simlog import truth_json

    out = flight_dir(source, cache)
    out.mkdir(parents=True, exist_ok=True)
    cases = source.cases()
    jobs = ([(_name("ref", k, ""), s, None) for k, s in enumerate(source.references())]
            + [(_name("case", k, c["case"]), source.case_spec(c), c)
               for k, c in enumerate(cases)])
    todo = [j for j in jobs if not (out / f"{j[0]}.csv.gz").exists()]
    if todo:
        progress(f"{source.name}: flying {len(todo)} flights in one child process")
        for (name, _, case), (log, truth) in zip(todo, source.fly([j[1] for j in todo])):
            if case is not None:
                truth = {**truth, "truth": case["truth"], "kind": case["kind"],
                         "case": case["case"]}
            atomic_write_text(out / f"{name}.truth.json", truth_json(truth))
            write_log(out / f"{name}.csv.gz", log)
    if not todo and (out / "observability.json").exists():
        return out
    refs = [load_log(out / f"{name}.csv.gz", warn=False) for name, _, c in jobs if c is None]
    named = [(name, case) for name, _, case in jobs if case is not None]
    logs = [load_log(out / f"{name}.csv.gz", warn=False) for name, _ in named]
    observed = {n: {"reduction": r, "gap": g} for n, (r, g) in
                zip([n for n, _ in named], source.observe(logs, refs, [c for _, c in named]))}
    atomic_write_text(out / "observability.json",
                      json.dumps(observed, indent=1, sort_keys=True) + "\n")
    return out


def load_flights(source: CaseSource, cache) -> tuple[list, list[dict]]:
    """(reference logs, case rows with ``_log`` and ``oracle_reduction``) from
    :func:`generate`'s folder; raises FileNotFoundError when it is incomplete."""
    from ..logs.flightlog import load_log

    out = flight_dir(source, cache)
    observed = json.loads((out / "observability.json").read_text())
    refs = [load_log(out / f"{_name('ref', k, '')}.csv.gz", warn=False)
            for k in range(len(source.references()))]
    rows = []
    for k, case in enumerate(source.cases()):
        name = _name("case", k, case["case"])
        kind = source.scored_kind(case)
        rows.append({**case, "kind": kind, "flown_as": case["kind"], "name": name,
                     "_log": load_log(out / f"{name}.csv.gz", warn=False),
                     "oracle_reduction": observed[name]["reduction"],
                     "gap_vs_references": observed[name]["gap"],
                     "observable": (kind != "library"
                                    or observed[name]["reduction"] >= source.observable)})
    return refs, rows


def judge(source: CaseSource, cache) -> list[dict]:
    """THE BLIND RUN: per-flight verdicts of every case against the references, scored
    (:mod:`.score`). Run it once, after the verdict rules are frozen."""
    from ..core.errors import QuadsimWarning
    from ..gap import diagnose_per_flight
    from .score import read_verdict, score_case

    refs, rows = load_flights(source, cache)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        result = diagnose_per_flight([r["_log"] for r in rows], refs, source.params())
    seconds = time.perf_counter() - start
    out = []
    for row, flight in zip(rows, result["flights"]):
        verdict = read_verdict(flight)
        row = {k: v for k, v in row.items() if k != "_log"}
        out.append({**row, "effects": {k: np.asarray(v).tolist() for k, v in
                                       row["effects"].items()},
                    "per_flight": {**verdict, "reduction": flight.get("reduction"),
                                   "score": score_case(row["truth"], row["kind"], verdict)},
                    "seconds_all": seconds})
    return out


def oracle_reductions(logs: list, references: list, cases: list[dict], params,
                      shared: list, truth: Callable[[dict], list],
                      scored_kind: Callable[[dict], str]) -> list[tuple[float, float]]:
    """Per case (reduction, gap): :func:`quadsim.bench.observe.per_flight_observability` with
    the references' ``shared`` physics and each case's true model (``truth(case)``, the full
    effect list; a late rotor log: the shared physics on the log shifted back by the true
    delay): the cut of its flight's normalised residual (forces, torques, rotor channel) when
    the true difference is applied in quadsim's residual model, 0 for cases scored outside the
    library; and the flight's mean squared normalised residual under ``shared`` relative to
    the references' own."""
    truths = []
    for log, case in zip(logs, cases):
        if scored_kind(case) != "library":
            truths.append(None)
        elif "rotor_delay" in case["effects"]:
            delay = float(case["effects"]["rotor_delay"])
            truths.append(TrueModel(tuple(shared), dataclasses.replace(log, rotor_speed=np.stack(
                [np.interp(log.t + delay, log.t, c) for c in log.rotor_speed.T], axis=-1))))
        else:
            truths.append(TrueModel(tuple(truth(case))))
    return [tuple(o) for o in per_flight_observability(logs, references, params, shared,
                                                        truths)]
