"""Speed of the gap diagnosis as a user gets it: the command a user types, timed from outside.

Runs ``python -m quadsim.gap --model crazyflie21 --per-flight MIXED... --reference NOMINAL...
--workers 1`` as a subprocess (imports, log loading and checks, the references' calibration,
the per-flight judgment and the summary all included) on the real Crazyflie 2.1 Brushless
flights of ``../shared/data/crazyflie21_brushless`` and reports, per run:

* flight-minutes: the judged (``--per-flight``) flights' log durations summed (t_last - t_0);
* CPU s: user + system time of the command and its children (``resource.getrusage``
  ``RUSAGE_CHILDREN`` before and after), the number to compare on a shared machine;
* wall s, and CPU s per flight-minute (issue 43's goal: <= 2 for the 26 mixed flights
  against the 20 nominal references, one worker).

Two series: the first N mixed flights (N = 1, 2, 4, 8, 16, 26) whole, and 8 mixed flights
cut to 50 and 75 % of their length (the first part of each log; a quarter, ~1.4 s, is below
the diagnosis' 2 s minimum and is refused; the real flights cannot be made longer without
inventing data). A least-squares line CPU = fixed + per-minute x
flight-minutes over the count series splits the cost that does not grow with the judged
flights (imports, the 20 references' calibration) from the cost that does.

``--long`` instead times minute-long real logs: the nano-drone benchmark's validation runs
(``train/*_run4``: square 19 s, then chirp and random 60 s each, 100 Hz) judged per flight
against its training runs 1-3 (9 flights, 6.95 min) with ``--model
models/nanodrone_cf21bl.toml``, the first 1, 2 and 3 of them (never the benchmark's test
runs). The judgment's cost is mostly per flight (a few hundred residual evaluations whatever
its length), so the mixed flights (~6 s each) are the per-minute worst case and these the
typical one.

``--stages`` instead times the 26-flight command once by stage, in a fresh process of its
own (``time.process_time`` around the CLI's calls: the imports, loading and checking the
logs, preparing the references, their calibration, their self-check, judging the flights):
where the CPU goes, not a second measurement of the total.

``--parts`` instead times the weighing's parts (the references' self-check and the judged
flights' weighing) inside one fresh process of the 26-flight command: the residual
evaluations (``quadsim.gap.evidence.flight_residual``, each one the model evaluated; the
residuals kept as a fit's last point are not counted) with their own parts apart (the rotor
speeds read at a delay not read before, the effects' loads, the rotor channel), the linear
algebra after them (the marginal's profile and one-pass cost, the linear steps, the Laplace
evidence, the marginals' factorisations) and the rest of the weighing (each flight's
``weigh_flight`` and evaluate calls' own), each part's CPU (``time.process_time``) with what
it calls among the others apart, and how many calls: the parts add up to the weighing's
CPU. With ``--against`` the same for both checkouts, one after the other. Steadier than the
whole command's CPU on a loaded machine: the evaluation count does not move with the load
at all.

Cold and warm: the command keeps the references' loading, calibration and self-check in a
cache folder (``quadsim.gap.cache``, on by default). Every timed run here gets its own fresh
cache folder (``QUADSIM_CACHE_DIR``), so by default each run is **cold** (it computes the
references' stage and writes its entry, as a user's first run does: the numbers mean what
they meant before the cache). ``--warm`` first runs the same command once, untimed, to fill
that run's fresh folder, then times the second run, which reads the entry (a user's next run
against the same references); with ``--stages`` the stages of that second run, with
``--against`` both checkouts so (a checkout without the cache runs cold both times).

``--against CHECKOUT`` times the 26-flight command alternately with another checkout of the
repository (say the commit before a change; ``git worktree add ../before HEAD~3``) and this
one, ``--rounds`` times each (default 2): on a shared machine whose speed drifts, only runs
side by side compare. Each row states the load average before and after it.

Compiled bytecode: a user's installed package has its modules compiled once (pip writes
``__pycache__``); a machine whose environment sets ``PYTHONDONTWRITEBYTECODE`` would
recompile the package's ~65 modules in every timed run (~0.15 s on the 2-core VM, counted as
imports). Every timed command here runs without that variable, the checkout's package
compiled once beforehand (``compileall``, untimed, into its ``__pycache__`` folders, which
git ignores), so the imports stage is what a user pays.

Usage (from the repository root; the machine and its load matter, so say them)::

    nice -n 5 python benchmarks/speed_gap.py [--data ../shared/data] [--counts 1 2 4] [--warm]
    nice -n 5 python benchmarks/speed_gap.py --stages [--warm]
    nice -n 5 python benchmarks/speed_gap.py --against ../before [--rounds 2]
    nice -n 5 python benchmarks/speed_gap.py --parts [--against ../before]

Exit 0 with one ``skipped:`` line when the data folder is absent. Not a test: it measures.
"""

from __future__ import annotations

import argparse
import gzip
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data"
CAMPAIGN = "crazyflie21_brushless"
#: ``--long``: the nano-drone benchmark's folder, its validation runs in the order judged
#: (shortest first) and the parameter set they are judged with
NANO = "nanodrone_cf21bl"
NANO_RUNS = ("square_20251017_run4", "chirp_20251017_run4", "random_20251017_run4")
NANO_MODEL = ROOT / "models" / "nanodrone_cf21bl.toml"
COUNTS = (1, 2, 4, 8, 16, 26)
#: the share of each flight kept in the length series, and how many flights it judges
FRACTIONS = (0.5, 0.75)
LENGTH_FLIGHTS = 8


@dataclass(frozen=True)
class Run:
    """One timed command: what it judged and what it cost."""

    label: str
    flights: int
    flight_minutes: float
    cpu_s: float
    wall_s: float
    verdicts: str

    @property
    def cpu_per_minute(self) -> float:
        return self.cpu_s / self.flight_minutes


def log_duration(path: Path) -> float:
    """t_last - t_0 (s) of a flight-log CSV (``t`` the first column)."""
    with gzip.open(path, "rt") as handle:
        lines = handle.read().split("\n")
    rows = [line for line in lines[1:] if line]
    return float(rows[-1].split(",", 1)[0]) - float(rows[0].split(",", 1)[0])


def cut_log(path: Path, fraction: float, out: Path) -> Path:
    """The first ``fraction`` of a flight-log CSV (by time), written to ``out`` (gzip)."""
    with gzip.open(path, "rt") as handle:
        lines = [line for line in handle.read().split("\n") if line]
    t = np.array([float(line.split(",", 1)[0]) for line in lines[1:]])
    keep = t <= t[0] + fraction * (t[-1] - t[0])
    kept = [lines[0]] + [line for line, k in zip(lines[1:], keep) if k]
    with gzip.open(out, "wt") as handle:
        handle.write("\n".join(kept) + "\n")
    return out


#: the checkouts whose package was compiled (module doc, "Compiled bytecode")
_COMPILED: set = set()


def _env(root: Path, cache: str | os.PathLike) -> dict:
    """The command's environment: checkout ``root`` first on the path, the references'
    cache in ``cache`` (module doc, "Cold and warm"), bytecode read and kept (module doc,
    "Compiled bytecode"): ``root``'s package compiled once, untimed."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.update({"QUADSIM_CACHE_DIR": str(cache),
                "PYTHONPATH": os.pathsep.join(
                    p for p in (str(root), os.environ.get("PYTHONPATH")) if p)})
    if str(root) not in _COMPILED:
        subprocess.run([sys.executable, "-m", "compileall", "-q", str(Path(root) / "quadsim")],
                       capture_output=True, check=False, env=env)
        _COMPILED.add(str(root))
    return env


def time_gap(label: str, flights: list[Path], references: list[Path], root: Path = ROOT, *,
             warm: bool = False, model: str = "crazyflie21") -> Run:
    """Run the user's command once with the package of checkout ``root`` first on the path,
    in a fresh cache folder (cold); ``warm``: once untimed before, in the same folder, and
    the second run timed. ``model``: ``--model``'s value. CPU from the children's rusage,
    wall from a clock."""
    with tempfile.TemporaryDirectory(prefix="speed_gap_cache_") as cache:
        if warm:
            _run_gap(label, flights, references, root, cache, model)
        return _run_gap(label, flights, references, root, cache, model)


def _run_gap(label: str, flights: list[Path], references: list[Path], root: Path,
             cache: str, model: str = "crazyflie21") -> Run:
    """:func:`time_gap`'s one run, with the references' cache in ``cache``."""
    command = [sys.executable, "-m", "quadsim.gap", "--model", model, "--per-flight",
               *map(str, flights), "--reference", *map(str, references), "--workers", "1"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    run = subprocess.run(command, capture_output=True, text=True, check=False, cwd=root,
                         env=_env(root, cache))
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if run.returncode != 0:
        raise SystemExit(f"error: {label}: quadsim.gap exit {run.returncode}: "
                         f"{run.stderr.strip().splitlines()[-1] if run.stderr.strip() else ''}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    answer = next((line for line in run.stdout.splitlines() if line.startswith("answer:")), "")
    minutes = sum(log_duration(p) for p in flights) / 60.0
    return Run(label, len(flights), minutes, cpu, wall, answer.split(":", 1)[-1].strip())


#: the stage of the references' preparation (:func:`staged` counts ``prepare`` there only for
#: the references: a judged flight's is inside judging)
PREPARING = "preparing the references"
#: (module, function, stage) the stage timer wraps (:func:`staged`); two functions may share
#: a stage: the CLI reads every log first to pick the band a slow log needs (``_band``, the
#: logs kept for ``_load``), then checks them (``_load``), both "loading and checking"
STAGES = (("quadsim.gap.__main__", "_band", "loading and checking the logs"),
          ("quadsim.gap.__main__", "_load", "loading and checking the logs"),
          ("quadsim.gap.diagnose", "prepare", PREPARING),
          ("quadsim.gap.diagnose", "calibrate", "the references' calibration"),
          ("quadsim.gap.diagnose", "reference_self_check", "their self-check"),
          ("quadsim.gap.diagnose", "judge_one", "judging the flights (prepare, weigh, verdict)"))


def staged(argv: list[str]) -> dict:
    """CPU s (``time.process_time``) per stage of ``python -m quadsim.gap ARGV`` run in this
    process: "imports" (the CLI's, with the interpreter's start), each of :data:`STAGES`
    (``prepare`` counted for the references only: a judged flight's is inside judging) and
    "total"."""
    import functools
    import importlib

    modules = {name: importlib.import_module(name) for name, _, _ in STAGES}
    spent = {"imports (interpreter start included)": time.process_time()}
    spent.update((label, 0.0) for _, _, label in STAGES)   # in the table's order
    for module, name, label in STAGES:
        original = getattr(modules[module], name)

        def timed(*args, _original=original, _label=label, **kwargs):
            begin = time.process_time()
            try:
                return _original(*args, **kwargs)
            finally:
                if _label != PREPARING or len(args[0]) > 1:
                    spent[_label] = spent.get(_label, 0.0) + time.process_time() - begin

        setattr(modules[module], name, functools.wraps(original)(timed))
    _as_the_command(modules["quadsim.gap.__main__"])
    try:
        modules["quadsim.gap.__main__"].main(argv)
    except SystemExit:
        pass
    spent["total"] = time.process_time()
    return spent


def _as_the_command(main_module) -> None:
    """What ``python -m quadsim.gap`` does before its ``main`` (the garbage collector's
    setting, ``collector_for_a_command``, where the checkout has it), so that a run timed in
    this process is the user's command."""
    setup = getattr(main_module, "collector_for_a_command", None)
    if setup is not None:
        setup()


def time_stages(flights: list[Path], references: list[Path], *, warm: bool = False) -> dict:
    """:func:`staged` of the user's command on ``flights``, in a fresh process and a fresh
    cache folder (``warm``: filled by one untimed run first)."""
    code = ("import json, sys; from benchmarks.speed_gap import staged; "
            "print('STAGES ' + json.dumps(staged(sys.argv[1:])))")
    with tempfile.TemporaryDirectory(prefix="speed_gap_cache_") as cache:
        if warm:
            _run_gap("filling the cache", flights, references, ROOT, cache)
        return _timed_in_fresh_process(code, "STAGES", flights, references, ROOT, cache=cache)


def _timed_in_fresh_process(code: str, tag: str, flights: list[Path], references: list[Path],
                            root: Path, *, cache: str | None = None) -> dict:
    """Run ``code`` (Python source that prints one line ``TAG <json>``) with the user's
    command's arguments on ``flights`` against ``references`` in a fresh interpreter of
    checkout ``root``, the references' cache in ``cache`` (None: a fresh folder, cold);
    -> the decoded JSON. No such line: a one-line error naming ``tag``."""
    import json

    if cache is None:
        with tempfile.TemporaryDirectory(prefix="speed_gap_cache_") as fresh:
            return _timed_in_fresh_process(code, tag, flights, references, root, cache=fresh)
    argv = ["--model", "crazyflie21", "--per-flight", *map(str, flights), "--reference",
            *map(str, references), "--workers", "1"]
    run = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True,
                         check=False, cwd=root, env=_env(root, cache))
    line = next((x for x in run.stdout.splitlines() if x.startswith(tag + " ")), None)
    if line is None:
        raise SystemExit(f"error: {tag.lower()}: no timing came back: "
                         f"{run.stderr.strip()[-300:]}")
    return json.loads(line.split(" ", 1)[1])


#: (module, class or None, function, part) the weighing's part timer wraps
#: (:func:`weighing_parts`); a name a checkout lacks is left out. A class named with a
#: trailing ``+`` stands for each of its subclasses that defines the function itself (the
#: effects' own ``loads``). The residual evaluations' own parts come first: the rotor speeds
#: read at a delay (:func:`quadsim.gap.reference.read_later`, a Fourier shift per delay
#: not read before on the flight), the effects' loads and the rotor channel; "residual
#: evaluations" is the rest of an evaluation (the model wrench put together, the measured
#: wrench, the weighting, the memo)
PARTS = (("quadsim.gap.reference", None, "read_later", "rotor speeds read at a delay"),
         ("quadsim.effects.base", "EffectBase+", "loads", "effects' loads"),
         ("quadsim.gap.fitting", None, "rotor_residual", "the rotor channel"),
         ("quadsim.gap.evidence", None, "flight_residual", "residual evaluations"),
         ("quadsim.gap.evidence", "Marginal", "_profile", "profiles over the shared columns"),
         ("quadsim.gap.evidence", "Marginal", "cost", "one-pass profiled costs"),
         ("quadsim.gap.evidence", None, "linear_step", "linear steps"),
         ("quadsim.gap.evidence", None, "laplace", "Laplace evidence"),
         ("quadsim.gap.evidence", "Marginal", "__init__", "marginals factored"),
         ("quadsim.gap.evidence", None, "evaluate", "the rest of the weighing"),
         ("quadsim.gap.diagnose", None, "weigh_flight", "the rest of the weighing"),
         ("quadsim.gap.diagnose", None, "refined_rows", "the rest of the weighing"))


def weighing_parts(argv: list[str]) -> dict:
    """{part: [CPU s, calls]} of :data:`PARTS` while ``python -m quadsim.gap ARGV`` runs in
    this process: each part's ``time.process_time`` without the time of the other parts it
    calls (the residual evaluations inside a linear step count as evaluations), so the parts
    add up to the weighing's CPU; "the rest of the weighing" is the weighings' own (each
    flight's :func:`~quadsim.gap.diagnose.weigh_flight`, the evaluate calls in it and the
    self-check's refined rows: aligning, placing, the explanations, the screen's logic). A
    part outside :mod:`quadsim.gap.evidence` and :mod:`quadsim.gap.diagnose` (the rotor speeds
    read at a delay, the effects'
    loads, the rotor channel: the calibration and the log checks call them too) counts only
    inside another part."""
    import functools
    import importlib

    spent: dict = {}
    inner: list = []

    def wrap(owner, name, label, nested=False):
        original = owner.__dict__.get(name) if isinstance(owner, type) else getattr(owner, name)

        def timed(*args, _original=original, _label=label, **kwargs):
            if nested and not inner:        # outside the weighing (the calibration's)
                return _original(*args, **kwargs)
            begin = time.process_time()
            inner.append(0.0)
            try:
                return _original(*args, **kwargs)
            finally:
                took = time.process_time() - begin
                own = took - inner.pop()
                entry = spent.setdefault(_label, [0.0, 0])
                entry[0] += own
                entry[1] += 1
                if inner:
                    inner[-1] += took

        setattr(owner, name, functools.wraps(original)(timed))

    def subclasses(cls):
        for sub in cls.__subclasses__():
            yield sub
            yield from subclasses(sub)

    importlib.import_module("quadsim.gap.fitting")       # every effect class defined
    for module, cls, name, label in PARTS:
        owner = importlib.import_module(module)
        if cls and cls.endswith("+"):      # each subclass that defines it itself
            owners = list(dict.fromkeys(subclasses(getattr(owner, cls[:-1]))))
        else:
            owners = [getattr(owner, cls) if cls else owner]
        for owner in owners:
            if (owner.__dict__.get(name) if isinstance(owner, type)
                    else getattr(owner, name, None)) is not None:
                wrap(owner, name, label,
                     nested=module not in ("quadsim.gap.evidence", "quadsim.gap.diagnose"))
    main_module = importlib.import_module("quadsim.gap.__main__")
    _as_the_command(main_module)
    try:
        main_module.main(argv)
    except SystemExit:
        pass
    return spent


def time_parts(flights: list[Path], references: list[Path], root: Path = ROOT) -> dict:
    """:func:`weighing_parts` of the user's command on ``flights`` in a fresh process of
    checkout ``root`` (this file's functions, their source handed over: the other checkout
    needs no copy of them)."""
    import inspect

    code = ("import json, sys, time\n" + f"PARTS = {PARTS!r}\n"
            + inspect.getsource(_as_the_command) + inspect.getsource(weighing_parts)
            + "print('PARTS ' + json.dumps(weighing_parts(sys.argv[1:])))\n")
    return _timed_in_fresh_process(code, "PARTS", flights, references, root)


def alternate(flights: list[Path], references: list[Path], other: Path, rounds: int, *,
              warm: bool = False) -> list[tuple[str, Run, tuple[float, float]]]:
    """The command on ``flights`` run alternately with checkout ``other`` and this one,
    ``rounds`` times each (``warm``: each timed run after an untimed one, :func:`time_gap`):
    (which, run, (load average before, after)) per run."""
    out = []
    for k in range(rounds):
        for which, root in (("against", other), ("this", ROOT)):
            before = os.getloadavg()[0]
            run = time_gap(f"{which} {k + 1}", flights, references, root=root, warm=warm)
            out.append((which, run, (before, os.getloadavg()[0])))
            print(f"  {run.label}: {run.cpu_s:.1f} s CPU, {run.wall_s:.1f} s wall, load "
                  f"{before:.1f} -> {out[-1][2][1]:.1f}", flush=True)
    return out


def line_fit(runs: list[Run]) -> tuple[float, float]:
    """(fixed CPU s, CPU s per flight-minute) of the least-squares line through ``runs``."""
    x = np.array([r.flight_minutes for r in runs])
    y = np.array([r.cpu_s for r in runs])
    slope, intercept = np.polyfit(x, y, 1)
    return float(intercept), float(slope)


def table(runs: list[Run]) -> str:
    head = ("| run | flights | flight-min | CPU s | wall s | CPU s per flight-min |\n"
            "|---|---:|---:|---:|---:|---:|")
    rows = [f"| {r.label} | {r.flights} | {r.flight_minutes:.2f} | {r.cpu_s:.1f} | "
            f"{r.wall_s:.1f} | {r.cpu_per_minute:.1f} |" for r in runs]
    return "\n".join([head, *rows])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA,
                        help=f"the shared data folder (default {DEFAULT_DATA})")
    parser.add_argument("--counts", type=int, nargs="+", default=list(COUNTS),
                        help="numbers of mixed flights judged whole (default 1 2 4 8 16 26)")
    parser.add_argument("--fractions", type=float, nargs="*", default=list(FRACTIONS),
                        help="shares of each flight kept in the length series "
                             f"({LENGTH_FLIGHTS} flights; default 0.5 0.75; none: skip)")
    parser.add_argument("--stages", action="store_true",
                        help="time the 26-flight command once by stage instead")
    parser.add_argument("--against", type=Path, metavar="CHECKOUT",
                        help="time the 26-flight command alternately with this other "
                             "checkout of the repository instead")
    parser.add_argument("--parts", action="store_true",
                        help="time the weighing's parts of the 26-flight command instead "
                             "(with --against: for both checkouts)")
    parser.add_argument("--warm", action="store_true",
                        help="time each command's second run, its references' cache filled "
                             "by an untimed first one (default: cold, a fresh cache)")
    parser.add_argument("--long", action="store_true",
                        help="time minute-long real logs instead: the nano-drone benchmark's "
                             "validation runs against its training runs (module doc)")
    parser.add_argument("--rounds", type=int, default=2,
                        help="with --against: runs of each checkout (default 2)")
    args = parser.parse_args(argv)
    if args.against is not None and not (args.against / "quadsim" / "gap").is_dir():
        print(f"error: {args.against}: --against: not a checkout of this repository "
              "(no quadsim/gap)", file=sys.stderr)
        return 2
    if args.warm and args.parts:
        print("error: --warm: not used with --parts (the weighing's parts include the "
              "references' self-check, which a warm run reads)", file=sys.stderr)
        return 2
    if args.rounds < 1:
        print(f"error: --rounds: must be >= 1, got {args.rounds}", file=sys.stderr)
        return 2
    if args.long:
        return _long(args)
    folder = args.data / CAMPAIGN
    mixed = sorted((folder / "mixed").glob("flight_*.csv.gz"))
    nominal = sorted((folder / "nominal").glob("flight_*.csv.gz"))
    if not mixed or not nominal:
        print(f"skipped: {folder}: no mixed/ and nominal/ flights (the shared data folder)")
        return 0
    load = os.getloadavg()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"Python {platform.python_version()}; load average at start "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; QUADSIM_THREADS="
          f"{os.environ.get('QUADSIM_THREADS', '(unset: 1)')}; references' cache "
          f"{'warm (filled by an untimed run first)' if args.warm else 'cold (fresh)'}")
    if args.parts:
        roots = ([("against", args.against.resolve())] if args.against is not None else []
                 ) + [("this", ROOT)]
        found = {which: time_parts(mixed, nominal, root) for which, root in roots}
        labels = list(dict.fromkeys(label for *_, label in PARTS))
        print("\n| part | " + " | ".join(f"{root.name} CPU s (calls)" for _, root in roots)
              + " |\n|---|" + "---:|" * len(roots))
        for label in labels + ["total"]:
            cells = []
            for which, _ in roots:
                parts = found[which]
                if label == "total":
                    cells.append(f"{sum(v[0] for v in parts.values()):.1f}")
                elif label in parts:
                    cells.append(f"{parts[label][0]:.1f} ({parts[label][1]})")
                else:
                    cells.append("-")
            print(f"| {label} | " + " | ".join(cells) + " |")
        load = os.getloadavg()
        print(f"\nload average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
        return 0
    if args.against is not None:
        runs = alternate(mixed, nominal, args.against.resolve(), args.rounds, warm=args.warm)
        minutes = runs[0][1].flight_minutes
        print(f"\n{len(mixed)} mixed flights ({minutes:.2f} flight-min) against {len(nominal)} "
              "nominal, --workers 1\n\n| checkout | CPU s (each run) | mean CPU s | "
              "CPU s per flight-min |\n|---|---|---:|---:|")
        for which, root in (("against", args.against.resolve()), ("this", ROOT)):
            cpu = [r.cpu_s for w, r, _ in runs if w == which]
            print(f"| {root.name} | {', '.join(f'{c:.1f}' for c in cpu)} | "
                  f"{np.mean(cpu):.1f} | {np.mean(cpu) / minutes:.1f} |")
        same = len({r.verdicts for _, r, _ in runs}) == 1
        print(f"\nanswers {'the same' if same else 'DIFFER'} in every run")
        return 0
    if args.stages:
        spent = time_stages(mixed, nominal, warm=args.warm)
        print("\n| stage | CPU s |\n|---|---:|")
        for label, value in spent.items():
            print(f"| {label} | {value:.1f} |")
        return 0
    runs = []
    for n in args.counts:
        runs.append(time_gap(f"{n} mixed, whole", mixed[:n], nominal, warm=args.warm))
        _said(runs[-1])
    counted = list(runs)
    with tempfile.TemporaryDirectory() as tmp:
        for fraction in args.fractions:
            cut = [cut_log(p, fraction, Path(tmp) / f"{int(fraction * 100)}_{p.name}")
                   for p in mixed[:LENGTH_FLIGHTS]]
            runs.append(time_gap(f"{LENGTH_FLIGHTS} mixed, first {fraction:.0%}", cut, nominal,
                                 warm=args.warm))
            _said(runs[-1])
    _summary(runs, counted, f"{len(nominal)} nominal flights", nominal)
    return 0


def _said(run: Run) -> None:
    """One progress line of a timed run."""
    print(f"  {run.label}: {run.cpu_s:.1f} s CPU, {run.wall_s:.1f} s wall ({run.verdicts})",
          flush=True)


def _summary(runs: list[Run], counted: list[Run], what: str, references: list[Path]) -> None:
    """The load at the end, the references, the table of ``runs`` and the line through
    ``counted`` (two or more)."""
    load = os.getloadavg()
    print(f"load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"references: {what}, {sum(log_duration(p) for p in references) / 60:.2f} min; "
          "--workers 1\n")
    print(table(runs))
    if len(counted) >= 2:
        fixed, per_minute = line_fit(counted)
        print(f"\nCPU = {fixed:.1f} s + {per_minute:.1f} s per judged flight-minute "
              f"(least squares over the {'whole-flight ' if counted is not runs else ''}runs)")


def _long(args) -> int:
    """``--long`` (module doc): the first 1, 2 and 3 of :data:`NANO_RUNS` against the
    training runs 1-3, cold or ``--warm``, with the table and the line."""
    train = args.data / NANO / "train"
    flights = [train / f"{name}.csv.gz" for name in NANO_RUNS]
    references = sorted(train.glob("*_run[123].csv.gz"))
    if not all(p.is_file() for p in flights) or len(references) != 9:
        print(f"skipped: {train}: not the nano-drone benchmark's training runs")
        return 0
    load = os.getloadavg()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"Python {platform.python_version()}; load average at start {load[0]:.2f}; "
          f"references' cache {'warm' if args.warm else 'cold (fresh)'}")
    runs = []
    for n in range(1, len(flights) + 1):
        runs.append(time_gap(f"{n} validation run(s)", flights[:n], references,
                             warm=args.warm, model=str(NANO_MODEL)))
        _said(runs[-1])
    _summary(runs, runs, f"{len(references)} training runs", references)
    return 0


if __name__ == "__main__":
    sys.exit(main())
