"""Held-out mode, blind, on the simulator sources (issue 47): 2 flights train, 1 is held out.

The simulator sources (:mod:`.sim_cases`: Crazyflow, PyFlyt, multirotor, quadcopter-sim,
gym-pybullet-drones, drone-models, ...) fly ONE 8-s flight per case and judge it per flight
against 8 nominal flights. Here the same frozen cases are judged the way a user runs held-out mode
(``python -m quadsim.gap --model SET TRAIN... --holdout HELD...``): the parameter set itself
is the reference (the source's own ``source.params()``, not fitted), the effects are fitted
on two training flights that carry the change and scored on a third flight that carries it
too (:func:`quadsim.gap.diagnose` with ``holdout``, ``kstep=False``, as
:func:`benchmarks.cases.run_case` does for RotorPy).

Flights (:func:`extra_specs`): each case's frozen flight (seed ``s``, path speed ``v``) is the
held-out flight; two MORE flights with the same effect are flown by the source's own
``case_spec``/``fly``: seeds ``10 s + 1`` and ``10 s + 2`` (:func:`extra_seeds`; the path's
phase and the noise: a trajectory variant) at path speeds ``v x 1.1`` and ``v x 0.9``
(:data:`SPEED_FACTORS`: the held-out flight's speed lies between the training flights', as
a user who flies a little faster and a little slower than the flight held back). The
simulator sources' case seeds are 6e4-1.5e5 and their reference seeds 7e4-1.6e5, so no
derived seed (>= 6e5) is any flight's seed of its source. No-effect cases are the source's
``none`` cases with their 2 extra flights, judged the same way.

``--train N`` (default 2, the first run's setting) trains on N extra flights: flight k is
seed ``10 s + k`` at path speed ``v x SPEED_FACTORS[k - 1]`` (the third: ``10 s + 3`` at the
case's own speed ``v``, another path phase and noise); N >= 3 is held-out mode's minimum for
practical significance (docs/gap.md). ``--effects-file PATH`` (an effect file,
:mod:`quadsim.effects.effectfile`, completing the source's parameter set) is every case's base
model (``diagnose(..., base_effects=)``, what the CLI's ``--effects-file`` passes).
``--references`` judges each case held out against the source's own per-flight nominal
reference flights (the 8 in the per-flight folder, :func:`benchmarks.sim_cases.load_flights`):
``diagnose(train, params, holdout=[held], kstep=False, reference=refs, store=...)``, what
``python -m quadsim.gap ... --holdout HELD --reference NOMINAL...`` runs; the references are
calibrated once per source and process (:class:`MemoryStore`), not per case.
``--diagnose-set OUT.toml`` builds such a file the way a user would, from the source's 8
nominal reference flights only (never from the cases, :func:`diagnosed_set`): held-out mode
on 6 of them (2 held out), the named effect added (``--write-effects``), again from that file,
at most :data:`SET_ROUNDS` rounds, stopping at an answer that names nothing new.

Cache: ``CACHE/<source>-heldout-<hash>/`` beside the per-flight folder
(:func:`benchmarks.sim_cases.flight_dir`, whose flights and ``observability.json`` are read,
or flown first); ``hash`` is the per-flight code hash (:func:`benchmarks.sim_cases.code_hash`)
with the source text of what defines the extra flights (:func:`heldout_hash`: the seed,
speed and name rules and the flying function, not the judging code): a change of either
never reads a stale flight, and flight k is the same flight whatever ``--train``. (The first
run keyed the folder with this module's whole bytes; its flights are these flights, same
seeds and speeds: its folders can be renamed to the new key.) Each extra flight as
``NAME.csv.gz`` with its ``NAME.truth.json``.

Scoring (:mod:`.score`, as the RotorPy held-out rows): in-library cases count when they are
observable, here the source's per-flight observability of the held-out flight (its true
difference from the references cuts that flight's residual by the source's threshold,
``observability.json``); a reading of the verdict names the truth (``named``), the lead does
(``lead``); no effect -> ``no_significant_gap``; out of library -> a confident name is wrong.

Usage::

    python -m benchmarks.heldout_sources --source crazyflow --cache /tmp/cfcache \\
        --out cf_heldout.json [--jobs 1] [--cases 0-5,9] [--generate-only] [--train 3] \\
        [--effects-file cf_set.toml] [--references]
    python -m benchmarks.heldout_sources --source crazyflow --cache /tmp/cfcache \\
        --diagnose-set cf_set.toml          # the diagnosed set from the nominal flights
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import inspect
import json
import os
import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

__all__ = ["EXTRA", "MemoryStore", "SET_HELD", "SET_ROUNDS", "SPEED_FACTORS", "SetRound",
           "diagnosed_set",
           "extra_name", "extra_seeds", "extra_specs", "fly_extra", "heldout_dir",
           "heldout_hash", "judge_case", "main", "parse_cases", "summarise"]

#: extra flights per case by default (the training flights; the frozen case flight is held
#: out): the first run's setting
EXTRA = 2
#: path speed of extra flight k (1, 2, 3) as a factor of the case's speed
SPEED_FACTORS = (1.1, 0.9, 1.0)
#: :func:`diagnosed_set`: nominal flights held out (the last ones) and rounds at most
SET_HELD = 2
SET_ROUNDS = 3
#: extra flights flown per child process of the simulator (a lost batch loses few flights)
BATCH = 8


def extra_seeds(seed: int, count: int = EXTRA) -> tuple[int, ...]:
    """Seeds of a case's extra flights: ``10 seed + k``, k = 1..count (RotorPy's
    :func:`benchmarks.cases._case_flight` rule)."""
    return tuple(10 * int(seed) + k for k in range(1, count + 1))


def extra_name(index: int, case: dict, k: int) -> str:
    """File stem of extra flight ``k`` (1-based) of case number ``index``."""
    return f"case_{index:02d}_{case['case']}_x{k}"


def extra_specs(source, index: int, case: dict, count: int = EXTRA) -> list[tuple[str, object]]:
    """(name, spec) of a case's first ``count`` extra flights (at most
    ``len(SPEED_FACTORS)``): the source's own ``case_spec`` with the derived seed and speed
    (module doc)."""
    if not 1 <= count <= len(SPEED_FACTORS):
        raise ValueError(f"extra flights per case: 1-{len(SPEED_FACTORS)}, not {count}")
    spec = source.case_spec(case)
    return [(extra_name(index, case, k), dataclasses.replace(spec, seed=seed,
                                                             speed=case["speed"] * factor))
            for k, (seed, factor) in enumerate(zip(extra_seeds(case["seed"], count),
                                                   SPEED_FACTORS), start=1)]


def heldout_hash(source) -> str:
    """The per-flight code hash of ``source`` with the source text of the extra flights'
    recipe (:func:`extra_seeds`, :func:`extra_name`, :func:`extra_specs`, :func:`fly_extra`,
    :data:`SPEED_FACTORS`) (12 hex digits)."""
    from . import sim_cases

    digest = hashlib.sha256(sim_cases.code_hash(source).encode())
    for part in (extra_seeds, extra_name, extra_specs, fly_extra):
        digest.update(inspect.getsource(part).encode())
    digest.update(repr(SPEED_FACTORS).encode())
    return digest.hexdigest()[:12]


def heldout_dir(source, cache) -> Path:
    return Path(cache) / f"{source.name}-heldout-{heldout_hash(source)}"


def fly_extra(source, cache, indices: list[int], progress=print, count: int = EXTRA) -> Path:
    """Fly (or keep) the first ``count`` extra flights of the cases numbered ``indices``; the
    folder."""
    from quadsim.core.files import atomic_write_text
    from quadsim.logs.flightlog import write_log

    from .simlog import truth_json

    out = heldout_dir(source, cache)
    out.mkdir(parents=True, exist_ok=True)
    cases = source.cases()
    todo = [(name, spec, cases[i]) for i in indices for name, spec in extra_specs(
        source, i, cases[i], count) if not (out / f"{name}.csv.gz").exists()]
    for start in range(0, len(todo), BATCH):
        batch = todo[start:start + BATCH]
        progress(f"{source.name}: flying extra flights {start + 1}-{start + len(batch)} of "
                 f"{len(todo)} in one child process")
        for (name, _, case), (log, truth) in zip(batch, source.fly([b[1] for b in batch])):
            truth = {**truth, "truth": case["truth"], "kind": case["kind"],
                     "case": case["case"], "case_seed": case["seed"]}
            atomic_write_text(out / f"{name}.truth.json", truth_json(truth))
            write_log(out / f"{name}.csv.gz", log)
    return out


def _top(posterior, count: int = 6) -> list[dict]:
    return [{k: p.get(k) for k in ("name", "probability", "log_evidence", "magnitude",
                                   "params", "ci")} for p in list(posterior or [])[:count]]


@dataclasses.dataclass
class MemoryStore:
    """The references' stage kept in memory (``--references``): ``get(key)`` -> the kept
    :class:`quadsim.gap.calibrate.Calibrated` or None, ``put(calibrated)``, the ``store`` of
    :func:`quadsim.gap.diagnose` (so a source's references are calibrated once, not per
    case); ``made`` counts the stages put (calibrations done)."""

    kept: dict = dataclasses.field(default_factory=dict)
    made: int = 0

    def get(self, key):
        return self.kept.get(key)

    def put(self, calibrated) -> None:
        self.kept[calibrated.key] = calibrated
        self.made += 1


#: the store of this process (``--references``): one calibration per source
_STORE = MemoryStore()


def judge_case(row: dict, train: list, params, base_effects=(), *, reference=None,
               store=None) -> dict:
    """Held-out verdict of one case: ``train`` (its extra flights) fitted, ``row["_log"]``
    (its frozen flight) held out, ``base_effects`` (an effect file's effects) in the model,
    ``reference`` (nominal flights, or None: the parameter set is the reference) with the
    ``store`` their stage is kept in; the row (without the log) with ``heldout`` (the read
    verdict, its score and what it rests on) and ``cpu_s`` (this process's CPU seconds)."""
    from quadsim.core.errors import QuadsimWarning
    from quadsim.gap import diagnose

    from .score import read_verdict, score_case

    start = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        extra = {} if reference is None else {"reference": list(reference), "store": store}
        result = diagnose(train, params, holdout=[row["_log"]], kstep=False,
                          base_effects=tuple(base_effects), **extra)
    cpu = time.process_time() - start
    raw = json.loads(json.dumps(result["verdict"], default=_plain))
    verdict = read_verdict(raw)
    row = {k: v for k, v in row.items() if k != "_log"}
    return {**row, "effects": {k: np.asarray(v).tolist() for k, v in row["effects"].items()},
            "cpu_s": cpu,
            "heldout": {**verdict, "score": score_case(row["truth"], row["kind"], verdict),
                        "raw": {k: v for k, v in raw.items() if k != "posterior"},
                        "posterior": _top(raw.get("posterior"))}}


@dataclasses.dataclass(frozen=True)
class SetRound:
    """One round of :func:`diagnosed_set`: the held-out answer on the nominal flights with the
    effects added so far as base (``base``), its lead (``lead``, the verdict's effect name),
    ``probability``, ``tentative``, the effects this round added (``added``; empty: the
    set stops here), how they were chosen (``via``: "named", or the most probable reading of
    an ``unexplained`` answer) and why it stopped (``stop``; "" when it went on)."""

    base: tuple[str, ...]
    outcome: str
    lead: str
    probability: float | None
    tentative: bool
    added: tuple[str, ...]
    stop: str
    via: str
    verdict: dict


def diagnosed_set(refs: list, params, *, label: str, held: int = SET_HELD,
                  rounds: int = SET_ROUNDS, progress=print) -> tuple[list, list[SetRound]]:
    """The user's diagnosed set from nominal flights (module doc): held-out mode
    (``diagnose(refs[:-held], params, holdout=refs[-held:], kstep=False, base_effects=...)``)
    in up to ``rounds`` rounds; each round adds the named effect (or combination) with its
    fitted values, as ``--write-effects`` does (:func:`quadsim.gap.report.added_effects`), and
    the next round starts from the effects so far; a named combination with a part already in
    the set (an effect file holds each effect once: the CLI refuses it) adds its new parts
    alone (``--add PART``, their single fits); an ``unexplained`` answer adds its most
    probable reading (the CLI refuses ``--write-effects`` there and asks for ``--add NAME``
    of a ranked candidate), its parts outside the library (``nominal_refit``) left out.
    Stops at ``no_significant_gap``, when nothing new can be added, or where the set so far
    cannot be a base (:class:`~quadsim.core.errors.ModelError`: ``cable_payload`` needs
    its integrated state, which the residual of a logged flight lacks). Returns
    ([(effect, {parameter: (value, source)})] for
    :func:`quadsim.effects.effectfile.render_effect_file`, the rounds)."""
    from quadsim.core.errors import InputError, ModelError, QuadsimWarning
    from quadsim.effects import make_effect
    from quadsim.gap import diagnose
    from quadsim.gap.report import added_effects, named_candidate

    if not 1 <= held < len(refs) - 1:
        raise ValueError(f"held-out nominal flights: 1-{len(refs) - 2}, not {held}")
    train, holdout = refs[:-held], refs[-held:]
    words = (f"{label}: nominal flights 0-{len(train) - 1} (held out: "
             f"{', '.join(str(k) for k in range(len(train), len(refs)))})")
    kept: list = []
    done: list[SetRound] = []
    for _ in range(rounds):
        base = tuple(make_effect(name, **{k: v for k, (v, _) in values.items()})
                     for name, values in kept)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", QuadsimWarning)
                warnings.simplefilter("ignore", RuntimeWarning)
                result = diagnose(train, params, holdout=holdout, kstep=False,
                                  base_effects=base)
        except ModelError as exc:     # an effect the residual cannot evaluate as a base
            done.append(SetRound(base=tuple(n for n, _ in kept), outcome="error", lead="",
                                 probability=None, tentative=False, added=(),
                                 stop=f"the set so far is no base: {exc}", via="",
                                 verdict={}))
            progress(f"round {len(done)}: {done[-1].stop}")
            break
        raw = json.loads(json.dumps(result.to_json(), default=_plain))
        verdict = raw.get("verdict") or {}
        named, via = named_candidate(raw), "named"
        if named is None and verdict.get("outcome") == "unexplained" \
                and verdict.get("best_candidate"):
            # the CLI refuses --write-effects here and says "choose a ranked candidate with
            # --add NAME": a user adds the most probable reading
            named, via = str(verdict["best_candidate"]), "--add, unexplained: most probable"
        stop, added = "", []
        if named is None:
            stop = f"answer {verdict.get('outcome')}: names nothing"
        else:
            have = tuple(n for n, _ in kept)
            try:
                added = added_effects(raw, None, logs=words, base=have)
            except InputError as exc:
                # a combination with an effect already in the set: what the CLI's error
                # leaves a user, --add each new part alone (its own single fit)
                for part in [n for n in named.split("+") if n not in have]:
                    try:
                        added += added_effects(raw, part, logs=words, base=have)
                    except InputError:
                        pass
                if not added:
                    stop = f"nothing new it can add ({exc})"
        done.append(SetRound(base=tuple(n for n, _ in kept),
                             outcome=str(verdict.get("outcome")),
                             lead=str(verdict.get("effect")),
                             probability=verdict.get("probability"),
                             tentative=bool(verdict.get("tentative")),
                             added=tuple(n for n, _ in added), stop=stop, via=via,
                             verdict={k: v for k, v in verdict.items() if k != "posterior"}))
        progress(f"round {len(done)}: {done[-1].outcome} {done[-1].lead} [{via}] "
                 f"(p {done[-1].probability}); added {', '.join(done[-1].added) or '-'}"
                 f"{'; ' + stop if stop else ''}")
        if stop:
            break
        kept += added
    return kept, done


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if hasattr(value, "to_json"):
        return value.to_json()
    if isinstance(value, (tuple, set, frozenset)):
        return list(value)
    return str(value)


def parse_cases(text: str | None, count: int) -> list[int]:
    """Case numbers from ``"0-5,9"`` (None: all ``count``); ValueError on a bad item."""
    if not text:
        return list(range(count))
    out = []
    for item in text.split(","):
        low, dash, high = item.strip().partition("-")
        if not low.isdigit() or (dash and not high.isdigit()):
            raise ValueError(f"{item!r} is not a case number or a range a-b")
        out += range(int(low), int(high or low) + 1)
    if not out or max(out) >= count:
        raise ValueError(f"case numbers run 0-{count - 1}")
    return sorted(set(out))


def _ok(row: dict) -> bool | None:
    """The row's score: True/False, None for an in-library case not observable."""
    s = row["heldout"]["score"]
    if row["kind"] == "library":
        return s["named"] if row["observable"] else None
    return s["no_gap"] if row["kind"] == "none" else not s["confident_wrong"]


def summarise(rows: list[dict], observable: float, label: str) -> str:
    """The score line (:func:`benchmarks.score.summary_rows`) and one line per case."""
    from .gap_benchmark import _cell, _magnitude
    from .score import summary_rows

    group = [{**r, "score": r["heldout"]["score"]} for r in rows]
    lines = [("| source | in-library: a reading names it | the lead names it | named or "
             "listed | readings per named verdict | no effect -> no_significant_gap | "
             "out of library: confident wrong |"), "|---|---|---|---|---|---|---|"]
    lines += ["| " + " | ".join(r) + " |"
              for r in summary_rows([(f"{label} held out", group)], observable)]
    lines += ["", ("| case | truth | kind | speed | change | observable (held-out flight) | "
                   "held-out verdict | probability | tentative | score | lack of fit |"),
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        h = r["heldout"]
        ok = _ok(r)
        score = ("not observable" if ok is None else "ok" if ok else "MISS") + (
            " (confident wrong)" if h["score"]["confident_wrong"] else "")
        lack = ", ".join(f"{k} {v:.2g}x" for k, v in sorted(
            (h["raw"].get("lack_of_fit") or {}).items(), key=lambda kv: -kv[1]))
        prob = "-" if h.get("probability") is None else f"{h['probability']:.2f}"
        lines.append(f"| {r['name']} | {r['truth']} | {r['kind']} | {r['speed']:.2f} | "
                     f"{_magnitude(r['effects'])} | {r['oracle_reduction']:.2f} | {_cell(h)} | "
                     f"{prob} | {'yes' if h['raw'].get('tentative') else ''} | {score} | "
                     f"{lack} |")
    return "\n".join(lines) + "\n"


def _cpu_seconds() -> float:
    return sum(u.ru_utime + u.ru_stime for u in (resource.getrusage(resource.RUSAGE_SELF),
                                                 resource.getrusage(resource.RUSAGE_CHILDREN)))


def _judge_task(task: tuple) -> dict:
    """One case in a worker process: (source name, cache, case number, training flights,
    effect file or None, against the references)."""
    name, cache, index, count, effects_file, references = task
    source = _source(name)
    return _judge_index(source, cache, index, _frozen(source, cache)[1][index], count=count,
                        base=_base_effects(effects_file), references=references)


def _base_effects(path) -> tuple:
    """The effects of the effect file ``path`` (None: none)."""
    if path is None:
        return ()
    from quadsim.effects.effectfile import load_effect_file

    return tuple(load_effect_file(path).effects.effects)


def _source(name: str):
    import importlib

    from .gap_benchmark import SIM_SOURCES

    return importlib.import_module(SIM_SOURCES[name][0]).SOURCE


def _frozen(source, cache):
    from . import sim_cases

    return sim_cases.load_flights(source, cache)


def _judge_index(source, cache, index: int, row: dict, *, count: int = EXTRA,
                 base: tuple = (), references: bool = False) -> dict:
    from quadsim.logs.flightlog import load_log

    folder = heldout_dir(source, cache)
    train = [load_log(folder / f"{name}.csv.gz", warn=False)
             for name, _ in extra_specs(source, index, source.cases()[index], count)]
    refs = _frozen(source, cache)[0] if references else None
    return {**judge_case(row, train, source.params(), base, reference=refs, store=_STORE),
            "index": index}


def _write_set(source, cache, out: str, say) -> int:
    """``--diagnose-set``: the diagnosed set from the source's nominal flights, written as an
    effect file (``out``) with the rounds beside it (``out`` with ``.rounds.json``)."""
    from dataclasses import asdict

    from quadsim.core.files import atomic_write_text
    from quadsim.effects.effectfile import render_effect_file

    refs, _ = _frozen(source, cache)
    params = source.params()
    start, wall, load = _cpu_seconds(), time.time(), os.getloadavg()
    kept, rounds = diagnosed_set(refs, params, label=source.name, progress=say)
    names = ", ".join(n for n, _ in kept) or "no effect"
    atomic_write_text(out, render_effect_file(
        params.name, f"{params.name} plus the effects held-out mode named on its {len(refs)} "
        f"nominal flights ({source.name}; benchmarks.heldout_sources --diagnose-set)", kept,
        header=f"Written by python -m benchmarks.heldout_sources --diagnose-set: {names} on "
               f"{params.name}."))
    meta = {"source": source.name, "command": " ".join(sys.argv), "effects": names,
            "cpu_s": _cpu_seconds() - start, "wall_s": time.time() - wall,
            "load_start": load, "load_end": os.getloadavg()}
    atomic_write_text(str(Path(out).with_suffix(".rounds.json")), json.dumps(
        {"run": meta, "rounds": [asdict(r) for r in rounds]}, indent=1, sort_keys=True,
        default=_plain) + "\n")
    print(f"{out}: {names} ({len(rounds)} round(s)); CPU {meta['cpu_s']:.0f} s, wall "
          f"{meta['wall_s']:.0f} s; load {load[0]:.1f} -> {meta['load_end'][0]:.1f}")
    return 0


def run(args) -> int:
    """The command (module doc): fly what is missing, then (unless ``--generate-only``) judge
    each chosen case once and write the rows."""
    import importlib

    from . import sim_cases
    from .gap_benchmark import SIM_SOURCES

    _, source_module, available, hint = SIM_SOURCES[args.source]
    if not getattr(importlib.import_module(source_module), available)():
        print(f"error: --source {args.source}: not installed ({hint})", file=sys.stderr)
        return 2
    source = _source(args.source)
    try:
        indices = parse_cases(args.cases, len(source.cases()))
    except ValueError as exc:
        print(f"error: --cases: {exc}", file=sys.stderr)
        return 2
    base = ()
    if args.effects_file is not None:
        from quadsim.core.errors import InputError

        try:
            base = _base_effects(args.effects_file)
            from quadsim.effects.effectfile import load_effect_file

            made_for = load_effect_file(args.effects_file).params
        except (InputError, OSError) as exc:
            print(f"error: {args.effects_file}: {exc}", file=sys.stderr)
            return 2
        if made_for != source.params().name:
            print(f"error: {args.effects_file}: params: the effects complete {made_for!r}, "
                  f"the source's set is {source.params().name!r}", file=sys.stderr)
            return 2
    start, wall, load = _cpu_seconds(), time.time(), os.getloadavg()
    say = lambda m: print(m, file=sys.stderr)  # noqa: E731
    sim_cases.generate(source, args.cache, progress=say)       # the frozen flights (kept)
    if args.diagnose_set is not None:
        return _write_set(source, args.cache, args.diagnose_set, say)
    folder = fly_extra(source, args.cache, indices, progress=say, count=args.train)
    flown = _cpu_seconds() - start
    say(f"extra flights in {folder}; flying and checking: {flown:.0f} s CPU")
    if args.generate_only:
        return 0
    judged = _cpu_seconds()
    if args.jobs > 1:
        from multiprocessing import Pool

        with Pool(args.jobs) as pool:
            rows = pool.map(_judge_task, [(args.source, args.cache, i, args.train,
                                           args.effects_file, args.references)
                                          for i in indices])
    else:
        _, frozen = _frozen(source, args.cache)
        rows = []
        for i in indices:
            rows.append(_judge_index(source, args.cache, i, frozen[i], count=args.train,
                                     base=base, references=args.references))
            say(f"{i:2d} {rows[-1]['name']}: {rows[-1]['heldout']['outcome']} "
                f"{'+'.join(rows[-1]['heldout']['lead'])}")
    meta = {"source": args.source, "command": " ".join(sys.argv), "folder": str(folder),
            "heldout_hash": heldout_hash(source), "cases": indices, "train": args.train,
            "effects_file": args.effects_file,
            "base_effects": [e.name for e in base], "references": args.references,
            "calibrations": _STORE.made,
            "cpu_s_flying": flown, "cpu_s_judging": _cpu_seconds() - judged,
            "wall_s": time.time() - wall, "load_start": load, "load_end": os.getloadavg()}
    from quadsim.core.files import atomic_write_text

    atomic_write_text(args.out, json.dumps({"run": meta, "rows": rows}, indent=1,
                                           sort_keys=True, default=_plain) + "\n")
    print(summarise(rows, source.observable, args.source), end="")
    print(f"CPU: flying {flown:.0f} s, judging {meta['cpu_s_judging']:.0f} s; wall "
          f"{meta['wall_s']:.0f} s; load {load[0]:.1f} -> {meta['load_end'][0]:.1f}")
    return 0


def main(argv=None) -> int:
    from .gap_benchmark import SIM_SOURCES

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", required=True, choices=sorted(SIM_SOURCES))
    parser.add_argument("--cache", required=True, metavar="DIR",
                        help="the source's flight cache (its per-flight folder is read or "
                             "flown; the extra flights go beside it)")
    parser.add_argument("--out", default="heldout_sources.json", help="per-case rows (JSON)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes for judging")
    parser.add_argument("--cases", metavar="LIST",
                        help="case numbers, e.g. 0-5,9 (default: all)")
    parser.add_argument("--generate-only", action="store_true",
                        help="only fly and cache the extra flights (no verdict)")
    parser.add_argument("--train", type=int, default=EXTRA, metavar="N",
                        help=f"training flights per case, 2-{len(SPEED_FACTORS)} (default "
                             f"{EXTRA}, the first run's; 3 is held-out mode's minimum for "
                             "practical significance)")
    parser.add_argument("--effects-file", metavar="PATH",
                        help="an effect file completing the source's parameter set: every "
                             "case's base model (diagnose(..., base_effects=))")
    parser.add_argument("--references", action="store_true",
                        help="judge against the source's per-flight nominal reference "
                             "flights (diagnose(..., reference=)), calibrated once")
    parser.add_argument("--diagnose-set", metavar="OUT.toml",
                        help="instead of judging cases: build the diagnosed set from the "
                             "source's nominal flights (module doc) and write it")
    args = parser.parse_args(argv)
    if args.jobs < 1:
        print("error: --jobs: at least 1", file=sys.stderr)
        return 2
    if not 2 <= args.train <= len(SPEED_FACTORS):
        print(f"error: --train: 2-{len(SPEED_FACTORS)} training flights per case",
              file=sys.stderr)
        return 2
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
