"""``python -m quadsim.gap``: diagnose the sim-to-real gap of a parameter set on flight logs.

Examples::

    python -m quadsim.gap --model crazyflie21 flights/*.csv.gz --json gap.json
    python -m quadsim.gap --model crazyflie21 train/*.csv.gz --holdout test/*.csv.gz \\
        --report gap.html --rerun gap.rrd
    python -m quadsim.gap --model crazyflie21 --per-flight mixed/*.csv.gz \\
        --reference nominal/*.csv.gz --json mixed.json
    python -m quadsim.gap --model crazyflie21 --per-flight new2/*.csv.gz \\
        --reference nominal/*.csv.gz    # again: the references' work read from the cache
    python -m quadsim.gap --model nanodrone_cf21bl.toml --effects-file diagnosed.toml \\
        train/*.csv.gz --holdout val/*.csv.gz        # diagnose a diagnosed model again
    python -m quadsim.gap --model crazyflie21 changed/*.csv.gz --holdout changed2.csv.gz \\
        --reference nominal/*.csv.gz    # what the changed flights share that nominal ones do not
    python -m quadsim.gap --model crazyflie21 --reference nominal/*.csv.gz \\
        --write-reference nominal.qref  # the references' calibrated stage, stored
    python -m quadsim.gap --model crazyflie21 --per-flight new/*.csv.gz \\
        --reference nominal.qref        # judged against it: the logs need not be at hand
    python -m quadsim.gap --model crazyflie21 --per-flight new/*.csv.gz
                                        # against the set's shipped reference (its own
                                        # nominal flights; quadsim.gap.reffile)
    python -m quadsim.gap --model crazyflie21 a.csv.gz b.csv.gz --holdout c.csv.gz --bare
                                        # against the parameter set alone
"""

from __future__ import annotations

import argparse
import re
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

from ..core.args import ArgumentParser
from ..core.cost import Estimate, check_cost
from ..core.errors import InputError, QuadsimWarning, run_cli
from ..core.executor import limit_numeric_threads
from ..logs import READABLE
from ..logs.flightlog import load_log
from ..vehicle.params import load_params
from .diagnose import diagnose, diagnose_per_flight
from .logcheck import check_length
from .report import summary, write_html, write_json, write_rerun


def _parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="python -m quadsim.gap",
        description="Where the gap between a parameter set and real flights lies, which "
                    "unmodelled effect (from quadsim.effects) causes it, and how far it "
                    "shrinks once that effect is added. Effects are fitted on training "
                    "flights and scored on held-out flights (split by flight, never by "
                    "sample).",
        epilog=__doc__.split("Examples::")[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("logs", nargs="*", metavar="LOG",
                        help=f"flight logs ({READABLE}); none only with --write-reference")
    parser.add_argument("--model", required=True, help="parameter set: built-in name or TOML")
    parser.add_argument("--holdout", nargs="+", metavar="LOG",
                        help="held-out logs (default: every third of LOG)")
    parser.add_argument("--per-flight", action="store_true",
                        help="judge each LOG on its own against --reference nominal flights")
    parser.add_argument("--reference", nargs="+", metavar="LOG",
                        help="nominal reference flights, or one stored reference FILE.qref "
                             "(their calibrated stage, --write-reference; quadsim.gap.reffile): "
                             "with --per-flight each LOG is "
                             "judged against them; held out (LOG... --holdout LOG...) they "
                             "are the reference model instead of the bare parameter set: "
                             "what the training LOGs share that they do not, checked on the "
                             "held-out logs. Default: the parameter set's shipped reference "
                             "where it has one that fits the run (models/references/NAME.qref: "
                             "its own nominal flights; NAME_commands.qref, the same with "
                             "commands only, where any LOG lacks rotor speeds), else none")
    parser.add_argument("--bare", action="store_true",
                        help="held out: judge against the parameter set alone, not its "
                             "shipped reference (the behaviour of sets without one)")
    parser.add_argument("--write-reference", metavar="OUT.qref",
                        help="write the --reference LOGs' calibrated stage (calibration, "
                             "noise model, discrepancy term, self-check) to a stored "
                             "reference file, read later with --reference OUT.qref "
                             "(quadsim.gap.reffile; command-only references: with the "
                             "command -> speed model that synthesised their speeds); with no "
                             "LOG only that is done")
    parser.add_argument("--reference-source", metavar="TEXT", default="",
                        help="with --write-reference: where the reference flights come "
                             "from (stored in the file's header)")
    parser.add_argument("--cache-dir", metavar="DIR",
                        help="with --reference: the folder where the references' loading, "
                             "calibration and self-check are kept between runs (default "
                             "$QUADSIM_CACHE_DIR, else ${XDG_CACHE_HOME:-~/.cache}/quadsim; "
                             "keyed by the reference files, the model, --effects-file, "
                             "--effects, --window and quadsim's code: a later run with the "
                             "same ones reads them, the same answers bit for bit; "
                             "quadsim.gap.cache). DIR must be yours: its files are Python "
                             "pickles")
    parser.add_argument("--no-cache", action="store_true",
                        help="neither read nor write the references' cache")
    parser.add_argument("--reference-cache", metavar="DIR",
                        help="the older name of --cache-dir (read as it, with a warning)")
    parser.add_argument("--command-reference", nargs="+", metavar="LOG",
                        help="flights with rotor speeds and commands: logs without rotor "
                             "speeds get speeds synthesised from their commands "
                             "(quadsim.gap.logcheck; default: --reference)")
    parser.add_argument("--effects-file", metavar="EFFECTS.toml",
                        help="effects already added to --model (an effect file, "
                             "quadsim.effects.effectfile): the diagnosis starts from the "
                             "diagnosed model, fits every candidate on top of it and never "
                             "refits these (--per-flight: the references' model and so every "
                             "flight's)")
    parser.add_argument("--write-effects", metavar="OUT.toml",
                        help="write an effect file: the --effects-file effects plus the "
                             "named effect (or --add NAME), fitted here with unit and "
                             "source (quadsim.gap.report)")
    parser.add_argument("--add", metavar="NAME",
                        help="with --write-effects: the ranked candidate to add instead of "
                             "the named one")
    parser.add_argument("--effects", nargs="+", metavar="NAME",
                        help="candidate effects (default: the whole library)")
    parser.add_argument("--window", type=float, default=None, metavar="S",
                        help="Savitzky-Golay window (s) of the differentiator (default 0.1)")
    parser.add_argument("--json", metavar="OUT.json", help="write the quadsim.gap/3 result")
    parser.add_argument("--report", metavar="OUT.html", help="write a self-contained HTML report")
    parser.add_argument("--rerun", metavar="OUT.rrd", help="write a rerun recording of residuals")
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="local processes (default: the CPU count; 1 = in this process); "
                             "parallel over flights (--per-flight) or candidate fits")
    parser.add_argument("--ray", metavar="ADDRESS", default=None,
                        help="run on Ray instead: 'local' starts a local cluster, HOST:PORT "
                             "joins one (needs the [ray] extra)")
    parser.add_argument("--allow-large", action="store_true",
                        help="run past the cost caps (quadsim.core.cost: 4 h, 8 GiB)")
    return parser


def _check_args(args) -> None:
    """Every argument checked before any work (see :mod:`quadsim.core.args`)."""
    from ..core.args import check_inputs, check_number, check_output, distinct_files

    check_number("--window", args.window, low=0.0, high=60.0, unit="s")
    _check_stored_args(args)
    if args.effects_file is not None:
        check_inputs("--effects-file", [args.effects_file])
    for flag, paths in (("LOG", args.logs), ("--holdout", args.holdout),
                        ("--reference", args.reference),
                        ("--command-reference", args.command_reference)):
        check_inputs(flag, paths)
    distinct_files({"LOG": args.logs, "--holdout": args.holdout,
                    "--reference": args.reference})
    if args.per_flight and args.holdout:
        raise InputError("--holdout: not used with --per-flight (each LOG is judged against "
                         "--reference)")
    if args.reference_cache is not None:
        if args.cache_dir is not None:
            raise InputError("--reference-cache: the older name of --cache-dir: give one")
        print("warning: --reference-cache: now --cache-dir (the cache is on by default; "
              "--no-cache turns it off): read as --cache-dir", file=sys.stderr)
        args.cache_dir, flag = args.reference_cache, "--reference-cache"
    else:
        flag = "--cache-dir"
    if args.cache_dir is not None:
        if args.no_cache:
            raise InputError(f"{flag}: not used with --no-cache")
        if not args.per_flight and not args.reference:
            raise InputError(f"{flag}: only used with --per-flight or --reference "
                             "(the references' calibration is what it keeps)")
        if Path(args.cache_dir).exists() and not Path(args.cache_dir).is_dir():
            raise InputError(f"{args.cache_dir}: {flag}: not a folder")
    inputs = [*args.logs, *(args.holdout or []), *(args.reference or []),
              *(args.command_reference or []),
              *([args.effects_file] if args.effects_file is not None else [])]
    outputs = [(f, o) for f, o in (("--json", args.json), ("--report", args.report),
                                   ("--rerun", args.rerun),
                                   ("--write-effects", args.write_effects),
                                   ("--write-reference", args.write_reference)) if o is not None]
    for flag, out in outputs:
        check_output(flag, out, {"--json": (".json",), "--report": (".html",),
                                 "--rerun": (".rrd",), "--write-effects": (".toml",),
                                 "--write-reference": (".qref",)}[flag],
                     inputs=inputs)
    if len({str(o) for _, o in outputs}) < len(outputs):
        raise InputError("--json/--report/--rerun/--write-effects/--write-reference: the same "
                         "output file given twice")
    if args.add is not None and args.write_effects is None:
        raise InputError("--add: only used with --write-effects")
    if args.write_effects is not None and args.per_flight:
        raise InputError("--write-effects: not used with --per-flight")
    if args.write_effects is not None and args.reference:
        raise InputError("--write-effects: not used with --reference (a reading is then a "
                         "difference from the references' model, not an effect to add to "
                         "--model)")


def _check_stored_args(args) -> None:
    """The stored-reference flags (:mod:`quadsim.gap.reffile`) against each other."""
    from .reffile import SUFFIX, is_reference_file

    stored = [p for p in args.reference or [] if is_reference_file(p)]
    if stored and len(args.reference) > 1:
        raise InputError(f"{stored[0]}: --reference: a stored reference ({SUFFIX}) is given "
                         "alone, not with reference logs or another one")
    args.reference_file = stored[0] if stored else None
    if not args.logs and args.write_reference is None:
        lists = [flag for flag, given in (("--reference", args.reference),
                                          ("--holdout", args.holdout),
                                          ("--command-reference", args.command_reference))
                 if given]     # a list flag takes every file after it: LOG... went there
        hint = ("" if not lists else f"; {lists[0]} takes every file after it: give the "
                "flight logs before it" if len(lists) == 1 else f"; {' and '.join(lists)} "
                "take every file after them: give the flight logs before them")
        raise InputError("LOG: give the flight logs to judge (or only --reference LOG... "
                         f"--write-reference OUT{SUFFIX} to write a stored reference){hint}")
    if args.write_reference is not None and (not args.reference or stored):
        raise InputError(f"{args.write_reference}: --write-reference: needs --reference "
                         "LOG... (the reference logs, not a stored reference)")
    if args.reference_source and args.write_reference is None:
        raise InputError("--reference-source: only used with --write-reference")
    if args.bare and args.reference:
        raise InputError("--bare: not used with --reference (the parameter set alone is the "
                         "reference model)")
    if args.bare and args.per_flight:
        raise InputError("--bare: not used with --per-flight (each LOG is judged against "
                         "reference flights: --reference LOG..., or the set's shipped one)")
    if not args.logs and (args.per_flight or args.holdout):
        raise InputError("LOG: --per-flight and --holdout judge LOGs: give them")


def _map_fn(args, bar):
    """The executor as a ``map(fn, items)``: built-in ``map`` for one in-process worker."""
    from ..core.executor import default_workers, run_tasks

    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers: must be >= 1, got {args.workers}")
    if args.ray is None and (args.workers or default_workers()) == 1:
        return map

    def map_fn(fn, items):
        items = list(items)
        labels = [str(getattr(x, "path", None) or getattr(x, "name", None) or f"task {i}")
                  for i, x in enumerate(items)]
        tick = (lambda i, result: bar.update(1)) if bar is not None else None
        return run_tasks(fn, items, workers=args.workers, ray=args.ray, progress=tick,
                         labels=labels)

    return map_fn


def _load(paths, params, args, lines: list | None = None, orders: list | None = None,
          said: list | None = None):
    """Load, check and count ``paths``: refused when too short, too finely windowed, or
    when all logs so far cost past the caps (``args.samples_loaded`` counts them). The
    warnings are printed, or appended to ``lines`` when given (printed later, gathered).
    ``orders``: a list that receives each accepted log's rotor-order status as the checks
    read it (:func:`quadsim.logs.checks.check_logs`). ``said``: a list that receives
    (the loader's warnings, the checks' notes), each a tuple of lines (the cache keeps
    them: :func:`_say`)."""
    kept = getattr(args, "preloaded", {})
    before: list = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", QuadsimWarning)
        logs = []
        for p in paths:
            log, said_before = kept.pop(str(p), (None, ()))
            logs.append(load_log(p) if log is None else log)
            before += said_before
    from ..logs.checks import check_logs  # channels against each other; NaN runs cut or refused
    from .logcheck import in_band, slow_rotors  # a rotor channel too slow (logcheck)

    band = getattr(args, "band", None)
    read: list | None = None if orders is None else []
    logs, notes = check_logs(logs, params, orders=read,
                             slow=(lambda log: slow_rotors(log, args.window)) if band is None
                             else (lambda log: in_band(log, band)))
    for log in logs:
        check_length(log, args.window, what=None if band is None else (
            f"t: the band's smoothing window {band.window_s:g} s ({band.source}, judged below "
            f"{band.cutoff_hz:.2g} Hz; give the log on finer rows: convert --rate 250)"))
    args.samples_loaded = getattr(args, "samples_loaded", 0) + sum(len(log) for log in logs)
    check_cost(gap_cost(args.samples_loaded), "LOG", allow=args.allow_large)
    if orders is not None:      # only once every log is accepted
        orders += read
    found = before + [str(w.message) for w in caught if issubclass(w.category, QuadsimWarning)]
    if said is not None:
        said.append((tuple(found), tuple(notes)))
    _say(found, notes, lines)
    return logs


def _band(args) -> None:
    """The band the run is judged in (:func:`quadsim.gap.logcheck.band_of`; docs/logs.md,
    "Slow channels"): every log of the run read first (kept in ``args.preloaded`` with its
    loader's warnings for :func:`_load`; one that fails is read again there, and refused
    there); where a log's rotors are carried only slowly, ``args.band`` is set and
    ``args.window`` becomes its window, which every stage, the cache's key and a stored
    reference's binding then follow. Nothing happens with ``--window`` given or where every
    rotor channel is fast."""
    args.band, args.preloaded = None, {}
    if args.window is not None:
        return
    from .logcheck import band_of

    paths = [*(args.logs or []), *(args.holdout or []), *(args.command_reference or []),
             *([] if args.reference_file is not None else args.reference or [])]
    for path in paths:
        if str(path) in args.preloaded:
            continue
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", QuadsimWarning)
            try:
                log = load_log(path)
            except InputError:
                continue
        args.preloaded[str(path)] = (log, [str(w.message) for w in caught
                                           if issubclass(w.category, QuadsimWarning)])
    args.band = band_of([log for log, _ in args.preloaded.values()])
    if args.band is not None:
        args.window = args.band.window_s


def _say(found, notes, lines: list | None) -> None:
    """:func:`_load`'s warnings: appended to ``lines`` when given, else printed (the
    loader's collapsed by kind, then the checks' notes)."""
    if lines is not None:
        lines += list(found) + list(notes)
        return
    for line in collapse_warnings(list(found)):
        print(f"warning: {line}", file=sys.stderr)  # only once every log is accepted
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)


_SPAN = re.compile(r"^(?P<file>.*): airborne span t (?P<a>\S+)-(?P<b>\S+) s kept "
                   r"\((?P<kept>\S+) of (?P<total>\S+) s\); cut: (?P<cut>.*)$")
_STRETCHES = re.compile(r"^(?P<file>.*): (?P<n>\d+) airborne stretches used, t (?P<spans>.*?) "
                        r"\((?P<kept>\S+) of (?P<total>\S+) s\); cut: (?P<cut>.*)$")


def gather_notes(lines: list[str]) -> list[str]:
    """The warnings of many logs as few lines: the airborne-span notes of every log
    (:func:`quadsim.logs.spans.cut_ground`) in one line, each file with the span it kept;
    the logs of several take-offs, every stretch of each used (:func:`quadsim.logs.spans.
    join_airborne`), in another; the other warnings collapsed by kind
    (:func:`collapse_warnings`)."""
    spans, several, rest = [], [], []
    for line in lines:
        m = _SPAN.match(line)
        k = _STRETCHES.match(line)
        if m:
            spans.append(f"{Path(m['file']).name} {m['a']}-{m['b']} s")
        elif k:
            several.append(f"{Path(k['file']).name} {k['n']} stretches ({k['spans']})")
        else:
            rest.append(line)
    out = collapse_warnings(rest)
    if spans:
        out.append(f"airborne span kept (ground, idle and landing spans cut) on "
                   f"{len(spans)} log{'s' if len(spans) > 1 else ''}: " + ", ".join(spans))
    if several:
        out.append(f"several take-offs or logging gaps: every airborne stretch used, each a "
                   f"segment of its flight (the ground spans and gaps between them cut, nothing "
                   f"fitted across them) on "
                   f"{len(several)} log{'s' if len(several) > 1 else ''}: " + "; ".join(several))
    return out


#: measured on the 2-core development machine (one 5 s and one 20 s log at 500 Hz, --workers
#: 1: 6.9 s and 9.6 s): about 6 s to start and 4e-4 s per logged sample; memory ~2 kB per
#: sample (states, residuals and candidate fits on the fit grid).
GAP_START_S = 6.0
GAP_S_PER_SAMPLE = 4e-4
GAP_BYTES_PER_SAMPLE = 2048
GAP_BASE_BYTES = 500 * 1024**2


def gap_cost(samples: int) -> Estimate:
    """Time and memory of diagnosing ``samples`` logged samples (:mod:`quadsim.core.cost`)."""
    return Estimate(seconds=GAP_START_S + GAP_S_PER_SAMPLE * samples,
                    bytes=GAP_BASE_BYTES + GAP_BYTES_PER_SAMPLE * samples,
                    what=f"{samples} logged samples")


def collapse_warnings(messages: list[str]) -> list[str]:
    """One line per kind of loader warning: messages that differ only in the file name
    (the text before the first ': ') and in numbers are one kind, printed once with the
    count of further files."""
    import re

    kinds: dict[str, list[str]] = {}
    for m in messages:
        _, sep, rest = m.partition(": ")
        key = re.sub(r"[-+]?\d[\d.eE+-]*", "#", rest if sep else m)
        kinds.setdefault(key, []).append(m)
    out = []
    for group in kinds.values():
        more = len(group) - 1
        out.append(group[0] + (f" (and {more} more file{'s' if more > 1 else ''} alike)"
                               if more else ""))
    return out


def _write_effects(args, params, base, result) -> None:
    """--write-effects: the starting model's effects, then the one this diagnosis adds."""
    from pathlib import Path

    from ..core.files import atomic_write_text
    from ..effects.effectfile import render_effect_file
    from .report import added_effects

    names = [Path(p).name for p in args.logs]
    held = [Path(p).name for p in args.holdout or []]
    logs = (f"{len(names)} training log(s) {', '.join(names)}"
            + (f" (held out: {', '.join(held)})" if held else "")
            + (f", on top of {Path(args.effects_file).name}" if base else ""))
    kept = []
    if base is not None:
        for effect in base.effects.effects:
            kept.append((effect.name, {p.name: (getattr(effect, p.name),
                                                base.sources[(effect.name, p.name)])
                                       for p in effect.parameters
                                       if (effect.name, p.name) in base.sources}))
    added = added_effects(result, args.add, logs=logs, base=tuple(n for n, _ in kept))
    text = render_effect_file(
        base.params if base is not None else params.name,
        f"{params.name} plus the effects python -m quadsim.gap named on its logs",
        kept + added,
        header=f"Written by python -m quadsim.gap --write-effects (rerun it instead of "
               f"editing by hand): {', '.join(n for n, _ in kept + added)} on {params.name}.")
    atomic_write_text(args.write_effects, text)
    from ..effects import make_effect

    stateful = [n for n, values in added
                if make_effect(n, **{k: v[0] for k, v in values.items()}).state_size() > 0]
    if stateful:
        print(f"note: {args.write_effects}: {', '.join(stateful)} has an internal state the "
              "engines integrate: the file serves the simulators; as --effects-file for "
              "quadsim.gap it is refused (a logged flight's residual cannot evaluate it)",
              file=sys.stderr)


def _with_effects_file(result, path, base_effects):
    """``result`` naming the --effects-file it was diagnosed on top of (JSON
    ``effects_file``, and a note the summary and the report show)."""
    import dataclasses

    names = ", ".join(e.name for e in base_effects)
    where = ("the references' model and every flight's" if result.mode == "per-flight"
             else "every fit")
    note = (f"model: {result.model} plus {Path(path).name} ({names}): in {where}, "
            "never refitted")
    return dataclasses.replace(result, effects_file=str(path),
                               notes=tuple(result.notes) + (note,))


@dataclass(frozen=True)
class _Writer:
    """The store :func:`quadsim.gap.diagnose.diagnose_per_flight` (and :func:`~quadsim.gap.
    diagnose.diagnose` with references) put a computed references' stage in: written to the
    cache as the entry of ``key`` with what loading them left (``said``, ``samples``)."""

    store: object
    key: str
    said: tuple
    samples: int
    quiet: bool

    def get(self, key):
        return None

    def put(self, stage) -> None:
        from .cache import Entry

        path = self.store.put(Entry(self.key, stage, self.said[0], self.said[1], self.samples))
        if path is not None and not self.quiet:
            print(f"note: the references' calibration and self-check kept in the cache: "
                  f"{path}", file=sys.stderr)


def _all_refused(reason: str, others: list) -> str:
    """The one line of a ``--per-flight`` run whose every flight is refused: the first
    flight's ``reason`` and the names of the ``others``."""
    more = (f" (and {len(others)} more flight(s) refused: {', '.join(map(str, others))})"
            if others else "")
    return f"{reason}{more}"


def _judged_as_commands(args, judged) -> bool:
    """Whether the references (``--reference LOG...``) are to be judged as command-only:
    every log ``judged`` has motor commands and no rotor speeds, and the references log both
    (their first is read to see). A flight without speeds has no rotor channel (measured
    against commanded speed), so against references with one every such flight would be
    refused; judged alike -- the references' speeds synthesised from their commands by the
    command model their own speeds (or ``--command-reference``'s) fit
    (:func:`quadsim.gap.logcheck.synthesise_all`), the stage keyed apart in the cache
    (:func:`quadsim.gap.cache.entry_key`'s ``as_commands``) -- flights and references are of
    one kind, as with the set's shipped commands reference (:mod:`quadsim.gap.reffile`). A
    batch that mixes logs with and without speeds keeps the references as they are (the
    command-only flights are refused, each saying so)."""
    if not args.reference or not judged:
        return False
    if not all(g.rotor_speed is None and g.rotor_command is not None for g in judged):
        return False
    from ..logs.flightlog import load_log

    try:
        first = load_log(args.reference[0], warn=False)
    except InputError:
        return False            # said where the references are loaded
    return first.rotor_speed is not None and first.rotor_command is not None


def _references(args, params, base_effects, logs, holdout, lines):
    """The references: (logs or None, stage or None, store or None, loaded: what loading
    them left, {"samples", "warnings", "notes"}). From the cache
    (:mod:`quadsim.gap.cache`) where it holds their entry: (None, the kept stage, None),
    their loader's warnings said again and their samples counted (where another log needs
    rotor speeds synthesised from them, :func:`quadsim.gap.logcheck.synthesise_all`: loaded
    too, the logs instead of None); else loaded here, and with the cache on a store that
    writes the stage the diagnosis computes."""
    if not args.reference:
        return None, None, None, {}
    from .cache import ReferenceStore, cache_dir, entry_key
    from .diagnose import DEFAULT_WINDOW_S

    store = key = None
    if not args.no_cache:
        store = ReferenceStore(cache_dir(args.cache_dir))
        key = entry_key(args.reference, params, effects=args.effects,
                        window_s=DEFAULT_WINDOW_S if args.window is None else args.window,
                        base=tuple(base_effects),
                        command_references=args.command_reference or (),
                        as_commands=getattr(args, "as_commands", False))
        entry = store.get(key)
        # written to a file: the references loaded (a command-only one's model is stored)
        synthesis = (args.write_reference is not None
                     or any(g.rotor_speed is None for g in [*logs, *(holdout or [])]))
        if entry is not None:
            reference = None
            if synthesis:
                reference = _load(args.reference, params, args, lines)
            else:
                _say(entry.found, entry.notes, lines)
                args.samples_loaded = getattr(args, "samples_loaded", 0) + entry.samples
                check_cost(gap_cost(args.samples_loaded), "LOG", allow=args.allow_large)
            if not args.quiet:
                print(f"note: the references' calibration and self-check read from the "
                      f"cache: {store.path(key)}", file=sys.stderr)
            return reference, entry.stage, None, {"samples": entry.samples,
                                                  "warnings": entry.found, "notes": entry.notes}
    said: list = []
    before = getattr(args, "samples_loaded", 0)
    reference = _load(args.reference, params, args, lines, said=said)
    samples = args.samples_loaded - before
    writer = (None if store is None else _Writer(store, key, said[0], samples, args.quiet))
    return reference, None, writer, {"samples": samples, "warnings": said[0][0],
                                     "notes": said[0][1]}


def _stored_reference(args, params, base_effects, judged, lines):
    """The stored reference of the run (:mod:`quadsim.gap.reffile`): (Stored or None, whether
    it is the set's shipped one, a note or None). ``--reference FILE.qref``: read and
    checked against the run (a refusal: one line); no ``--reference`` (nor ``--bare``,
    ``--write-effects``): the set's shipped reference where it fits the run
    (:func:`_shipped`; any judged log without rotor speeds: the set's commands file where it
    ships one). ``judged``: every log to judge (one needing rotor speeds synthesised needs
    the file's command model; against a "speeds" file whose references log commands, which
    judges a flight's rotor channel: refused, naming ``--reference LOG...``; against one
    whose references log none, ``--command-reference``: refused without;
    ``--command-reference`` with a "commands" file: refused)."""
    from .diagnose import DEFAULT_WINDOW_S
    from .reffile import binding_of, check_fits, read_reference, shipped_reference

    binding = binding_of(params, base=base_effects, effects_file=args.effects_file,
                         effects=args.effects,
                         window_s=DEFAULT_WINDOW_S if args.window is None else args.window)
    if args.reference_file is not None:
        stored, shipped = read_reference(args.reference_file), False
        check_fits(args.reference_file, stored.header, binding)
        _say(stored.found, stored.notes, lines)
    else:
        commands = any(g.rotor_speed is None for g in judged)
        path = (None if args.reference or args.bare or args.write_effects is not None
                else (commands and shipped_reference(params.name, commands=True))
                or shipped_reference(params.name))
        if path is None:
            return None, False, None
        stored, note = _shipped(path, binding, judged, args)
        if stored is None:
            return None, False, note
        shipped = True
    args.samples_loaded = getattr(args, "samples_loaded", 0) + stored.samples
    check_cost(gap_cost(args.samples_loaded), "LOG", allow=args.allow_large)
    needing = [g for g in judged if g.rotor_speed is None]
    if stored.judges == "commands" and args.command_reference:
        raise InputError(f"{stored.path}: command_model: this stored reference holds the "
                         "command -> speed model its command-only references were calibrated "
                         "with; --command-reference is not taken with it (drop it, or give "
                         "--reference LOG...)")
    if needing and stored.judges != "commands" and getattr(
            getattr(stored.stage, "reference", None), "rotor", False):
        raise InputError(f"{getattr(needing[0], 'path', None) or needing[0].name}: rotor_speed: "
                         f"not logged; {stored.path.name} was written from references with "
                         "rotor speeds and commands and judges a flight's rotor channel "
                         "(measured against commanded speed), which a log without speeds "
                         "lacks: give --reference LOG... (the references are then judged "
                         "alike, their speeds synthesised from their commands) or a stored "
                         "reference written from command-only logs")
    if needing and stored.judges != "commands" and not args.command_reference:
        raise InputError(f"{getattr(needing[0], 'path', None) or needing[0].name}: rotor_speed: "
                         f"not logged; against a stored reference ({stored.path.name}) its "
                         "speeds are synthesised from --command-reference LOG... (flights "
                         "with rotor speeds and commands, e.g. the references it was written "
                         "from): give them, or --reference LOG...")
    return stored, shipped, None


def _shipped(path, binding, judged, args):
    """The set's shipped reference ``path`` where it fits the run: (Stored, None); else
    (None, the note why: held out judged against the parameter set alone). It does not fit
    a run of another parameter-set content, effect file, ``--effects`` or ``--window``
    (:func:`quadsim.gap.reffile.mismatch`), one with logs lacking rotor speeds and no
    ``--command-reference``, nor a file this quadsim cannot read (another format, another
    numpy). ``--per-flight``: refused (one line) instead of a note."""
    from .reffile import judges_of, mismatch, read_header, read_reference

    stored = header = wrong = None
    try:
        header = read_header(path)
    except InputError as exc:
        wrong = str(exc)
    wrong = wrong or mismatch(header, binding)
    if (wrong is None and not args.command_reference and judges_of(header) != "commands"
            and any(g.rotor_speed is None for g in judged)):
        wrong = ("logs without rotor speeds: their speeds are synthesised from reference "
                 "flights with speeds, --command-reference LOG...")
    if wrong is None:
        try:
            stored = read_reference(path)
        except InputError as exc:
            wrong = str(exc)
    if wrong is not None and args.per_flight:
        raise InputError(f"--per-flight needs --reference LOG... (nominal flights): the set's "
                         f"shipped reference {path.name} does not fit this run: {wrong}")
    if wrong is not None:
        return None, (f"judged against the parameter set alone: its shipped reference "
                      f"{path.name} does not fit this run ({wrong}); --reference LOG... "
                      "calibrates nominal flights for it")
    return stored, None


def _write_reference(args, params, base_effects, refs, command_model=None) -> object:
    """--write-reference: the references' stage (``refs``: (logs, kept stage or None, store,
    loaded)) computed where the cache did not hold it, written (with ``command_model``, the
    model that synthesised command-only references' speeds, or None); -> the stage."""
    from .diagnose import DEFAULT_WINDOW_S, calibrated_stage
    from .reffile import Provenance, binding_of, write_reference

    reference, kept, store, loaded = refs
    window = DEFAULT_WINDOW_S if args.window is None else args.window
    if kept is None:
        kept = calibrated_stage(reference, params, effects=args.effects, window_s=window,
                                base=tuple(base_effects), store=store,
                                map_fn=_map_fn(args, None))
    binding = binding_of(params, base=base_effects, effects_file=args.effects_file,
                         effects=args.effects, window_s=window)
    provenance = Provenance(tuple(args.reference), tuple(args.command_reference or ()),
                            args.reference_source, ("python", "-m", "quadsim.gap",
                                                    *args.argv), loaded)
    path = write_reference(args.write_reference, binding, kept, provenance, command_model)
    if not args.quiet:
        kind = ("" if command_model is None else
                " (command-only, with their command -> speed model)")
        print(f"note: wrote {path}: the calibrated stage of {kept.count} reference "
              f"flights{kind} (read it with --reference {path})", file=sys.stderr)
    return kept


def _with_stored(result, stored, shipped: bool):
    """``result`` saying what it was judged against (:mod:`quadsim.gap.reffile`): JSON
    ``reference_file``, and a sentence after the answer."""
    import dataclasses

    from .reffile import describe, sentence

    said = sentence(stored, shipped)

    def told(answer: str) -> str:       # the sentence after the answer's last full stop
        answer = answer.rstrip()
        return f"{answer} {said}" if answer.endswith(".") else f"{answer}. {said}"

    if result.verdict is not None:
        verdict = dataclasses.replace(result.verdict, answer=told(result.verdict.answer))
        return dataclasses.replace(result, verdict=verdict,
                                   reference_file=describe(stored, shipped))
    return dataclasses.replace(result, answer=told(result.answer),
                               reference_file=describe(stored, shipped))


def _progress(args):
    """(bar, progress(name)) for the fits: a tqdm bar on a terminal, none with --quiet."""
    progress = None
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        # disable=None: no bar when stderr is not a terminal (logs, CI)
        from ..effects import EFFECTS

        # estimated fits: nominal refit + one per candidate (+ combinations, unknown ahead),
        # per split; the total grows if the diagnosis fits more, so "time left" stays honest
        per_split = 1 + len(args.effects or EFFECTS)
        splits = len(args.logs) + len(args.reference or []) if args.per_flight else 1
        bar = tqdm(desc="fitting", unit="fit", file=sys.stderr, leave=False, disable=None,
                   total=per_split * splits)

        def progress(name):
            bar.total = max(bar.total, bar.n + 1)
            bar.set_postfix_str(name)
            bar.update(1)
    return bar, progress


def _write_outputs(args, params, base, result) -> None:
    """--json, --report, --rerun, --write-effects, then the summary (unless --quiet)."""
    if args.json:
        write_json(args.json, result)
    if args.report:
        write_html(args.report, result)
    if args.rerun:
        write_rerun(args.rerun, result)
    if args.write_effects:
        _write_effects(args, params, base, result)
    if not args.quiet:
        print(summary(result), end="")


def synthesis_note(source: str) -> str:
    """The note naming what synthesised the command-only logs' rotor speeds, from a command
    model's ``source``: a fitted model's ("fitted on N reference log(s): ...", also as stored
    in a ``.qref``) or a parameter set's motor map ("the motor map of ...")."""
    what = f"the command -> speed model {source}" if source.startswith("fitted") else source
    return f"note: rotor speeds synthesised for the command-only logs from {what}"


@run_cli
@limit_numeric_threads
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)   # --write-reference records it
    _check_args(args)  # quadsim.core.args: ranges, duplicates, roles, writable outputs
    params = load_params(args.model)
    base_effects, base = (), None
    if args.effects_file is not None:
        from ..effects.effectfile import load_effect_file

        base = load_effect_file(args.effects_file)
        if base.params not in (params.name, str(args.model)):
            raise InputError(f"{args.effects_file}: params: the effects complete "
                             f"{base.params!r}, --model is {params.name!r}")
        base_effects = base.effects.effects
        stateful = [e.name for e in base_effects if e.state_size() > 0]
        if stateful:
            raise InputError(
                f"{args.effects_file}: effect {stateful[0]}: has an internal state (the engines "
                "integrate it along a simulation) that the residual of a logged flight cannot "
                "evaluate, so the diagnosis cannot start from it: remove it from the file for "
                "quadsim.gap (the file still serves the simulators)")
    for out, suffix in ((args.json, ".json"), (args.report, ".html"), (args.rerun, ".rrd")):
        if out is not None and not out.endswith(suffix):
            raise InputError(f"{out}: output name must end in {suffix}")
    if args.ray is not None:
        from ..core.executor import connect_ray

        connect_ray(args.ray, args.workers)   # fail fast: Ray missing, address unreachable
    _band(args)     # a log whose rotors are logged slowly: the run judged in its band
    refused, orders = [], None
    if args.per_flight:      # a flight the loader or the checks refuse is refused alone
        logs, lines, orders = [], [], []    # orders: the rotor-order statuses the checks read
        for k, path in enumerate(args.logs):
            try:
                logs += _load([path], params, args, lines, orders)
            except InputError as exc:
                refused.append((k, str(path), str(exc)))
        if not logs:         # nothing left to judge: bad input, one line and exit 2
            raise InputError(_all_refused(refused[0][2], [p for _, p, _ in refused[1:]]))
    else:
        logs, lines = _load(args.logs, params, args), None
    holdout = _load(args.holdout, params, args) if args.holdout else None
    stored, shipped, bare_note = _stored_reference(args, params, base_effects,
                                                   [*logs, *(holdout or [])], lines)
    # command-only logs against references with speeds: the references judged alike
    args.as_commands = stored is None and _judged_as_commands(args, [*logs, *(holdout or [])])
    as_commands = args.as_commands
    if stored is not None:
        from .reffile import with_paths

        refs = (None, with_paths(stored.stage, params.path, params.cad_dir), None, {})
    else:
        refs = _references(args, params, base_effects, logs, holdout, lines)
    reference, kept, store, _ = refs
    for line in gather_notes(lines or []):      # per flight: every log's notes, gathered
        print(f"warning: {line}", file=sys.stderr)
    # command-only logs in any role: speeds synthesised (quadsim.gap.logcheck.synthesise_all)
    from .logcheck import synthesise_all

    if as_commands:     # the model from the references' speeds (or --command-reference's)
        from .logcheck import without_speeds

        slow = [g for g in reference or [] if g.speeds_synthesised and g.rotor_command is None]
        if slow:    # their commands already carry their speeds (logcheck.slow_rotors)
            raise InputError(f"{slow[0].path}: rotor_1..rotor_N: the reference flights' rotor "
                             "speeds are logged too slowly for the moments and were "
                             "synthesised from their commands: the command-only flights "
                             "cannot be judged alike against them here; give references "
                             "with rotor speeds logged fast (or judge flights that log "
                             "their speeds as the references do)")
        command_ref = (_load(args.command_reference, params, args) if args.command_reference
                       else reference)
        reference = None if reference is None else [without_speeds(g) for g in reference]
        if not args.quiet:
            print("note: the logs judged have motor commands and no rotor speeds: the "
                  "references are judged alike, their speeds synthesised from their commands "
                  "by the command model fitted on logged speeds (the references', or "
                  "--command-reference's); no rotor channel on either side", file=sys.stderr)
    else:
        command_ref = (_load(args.command_reference, params, args) if args.command_reference
                       else reference)
    # references without rotor speeds: a file written from them keeps their command model
    command_only = reference is not None and any(g.rotor_speed is None for g in reference)
    roles, command_model = synthesise_all(
        {"logs": logs, "holdout": holdout, "reference": reference}, params, command_ref,
        model=None if stored is None else stored.command_model(params))
    if orders is not None:   # a log with synthesised speeds: its order read again when judged
        orders = [o if new is old else None for new, old, o in zip(roles["logs"], logs, orders)]
    logs, holdout, reference = roles["logs"], roles["holdout"], roles["reference"]
    if command_model is not None and not args.quiet:
        print(synthesis_note(command_model.source), file=sys.stderr)
    if args.write_reference is not None:
        kept, store = _write_reference(args, params, base_effects,
                                       (reference, kept, store, refs[3]),
                                       command_model if command_only else None), None
        if not args.logs:
            return 0
    against = reference if kept is None else kept
    bar, progress = _progress(args)
    extra = {} if args.window is None else {"window_s": args.window}
    extra["map_fn"] = _map_fn(args, bar)
    try:
        if args.per_flight:
            if against is None:
                raise InputError("--per-flight needs --reference LOG... (nominal flights)")
            result = diagnose_per_flight(logs, against, params,
                                         effects=args.effects, progress=progress,
                                         refused=refused, base_effects=base_effects,
                                         store=store, orders=orders, **extra)
        else:
            result = diagnose(logs, params, holdout=holdout, effects=args.effects,
                              progress=progress, base_effects=base_effects,
                              **({} if against is None else {
                                  "reference": against, "store": store}), **extra)
    finally:
        if bar is not None:
            bar.close()
    judged = [f for f in result["flights"] if f.get("outcome") != "refused"] \
        if args.per_flight else [None]
    if not judged:      # every flight refused while judged: bad input, one line, nothing written
        first = result["flights"][0]
        raise InputError(_all_refused(first.get("reason") or first["answer"],
                                      [Path(f["file"]).name for f in result["flights"][1:]]))
    if base is not None:
        result = _with_effects_file(result, args.effects_file, base_effects)
    if stored is not None:
        from .reffile import in_sample_note

        result = _with_stored(result, stored, shipped)
        own = in_sample_note(stored.header, [*args.logs, *(args.holdout or [])])
        if own is not None:
            import dataclasses

            result = dataclasses.replace(result, notes=tuple(result.notes) + (own,))
    elif bare_note is not None:
        import dataclasses

        result = dataclasses.replace(result, notes=tuple(result.notes) + (bare_note,))
    _write_outputs(args, params, base, result)
    return 0


#: allocations of container objects (tuples, lists, dicts) between two young collections of
#: the cyclic garbage collector in a command's run (Python's default: 700). A flight's
#: weighing makes a few dozen short-lived containers per residual evaluation, thousands of
#: evaluations per flight, and reference counting frees most of them; at the default a
#: young collection comes every 700 allocations, and the containers alive at that moment
#: (an evaluation's parts in flight) move to the older generations, whose collections scan
#: them again. A larger young generation lets more of them go before any collection sees
#: them. The collector still runs (cycles are freed, later); the numbers are the same.
YOUNG_COLLECTION = 10_000


def collector_for_a_command() -> None:
    """Set the cyclic garbage collector for one run of the command (not for a process that
    calls :func:`main` as a library): what the imports made is left out of its scans
    (``gc.freeze``: modules, classes and functions live as long as the process), and a
    young collection waits for :data:`YOUNG_COLLECTION` allocations (the older
    generations' thresholds as they were)."""
    import gc

    gc.freeze()
    _, older, oldest = gc.get_threshold()
    gc.set_threshold(YOUNG_COLLECTION, older, oldest)


if __name__ == "__main__":
    collector_for_a_command()
    sys.exit(main())
