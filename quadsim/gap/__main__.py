"""``python -m quadsim.gap``: diagnose the sim-to-real gap of a parameter set on flight logs.

Examples::

    python -m quadsim.gap --model crazyflie21 flights/*.csv.gz --json gap.json
    python -m quadsim.gap --model crazyflie21 train/*.csv.gz --holdout test/*.csv.gz \\
        --report gap.html --rerun gap.rrd
    python -m quadsim.gap --model crazyflie21 --per-flight mixed/*.csv.gz \\
        --reference nominal/*.csv.gz --json mixed.json
"""

from __future__ import annotations

import argparse
import sys
import warnings

from ..errors import InputError, QuadsimWarning, run_cli
from ..flightlog import load_log
from ..params import load_params
from .diagnose import diagnose, diagnose_per_flight
from .report import summary, write_html, write_json, write_rerun


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m quadsim.gap",
        description="Where the gap between a parameter set and real flights lies, which "
                    "unmodelled effect (from quadsim.effects) causes it, and how far it "
                    "shrinks once that effect is added. Effects are fitted on training "
                    "flights and scored on held-out flights (split by flight, never by "
                    "sample).",
        epilog=__doc__.split("Examples::")[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("logs", nargs="+", metavar="LOG", help="flight logs (CSV, .gz allowed)")
    parser.add_argument("--model", required=True, help="parameter set: built-in name or TOML")
    parser.add_argument("--holdout", nargs="+", metavar="LOG",
                        help="held-out logs (default: every third of LOG)")
    parser.add_argument("--per-flight", action="store_true",
                        help="judge each LOG on its own against --reference nominal flights")
    parser.add_argument("--reference", nargs="+", metavar="LOG",
                        help="nominal reference flights for --per-flight")
    parser.add_argument("--effects", nargs="+", metavar="NAME",
                        help="candidate effects (default: the whole library)")
    parser.add_argument("--window", type=float, default=None, metavar="S",
                        help="Savitzky-Golay window (s) of the differentiator (default 0.1)")
    parser.add_argument("--json", metavar="OUT.json", help="write the quadsim.gap/2 result")
    parser.add_argument("--report", metavar="OUT.html", help="write a self-contained HTML report")
    parser.add_argument("--rerun", metavar="OUT.rrd", help="write a rerun recording of residuals")
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    return parser


def _load(paths):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", QuadsimWarning)
        logs = [load_log(p) for p in paths]
    for line in collapse_warnings([str(w.message) for w in caught
                                   if issubclass(w.category, QuadsimWarning)]):
        print(f"warning: {line}", file=sys.stderr)
    return logs


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


@run_cli
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    params = load_params(args.model)
    for out, suffix in ((args.json, ".json"), (args.report, ".html"), (args.rerun, ".rrd")):
        if out is not None and not out.endswith(suffix):
            raise InputError(f"{out}: output name must end in {suffix}")
    logs = _load(args.logs)
    progress = None
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        # disable=None: no bar when stderr is not a terminal (logs, CI)
        bar = tqdm(desc="fitting", unit="fit", file=sys.stderr, leave=False, disable=None)
        progress = lambda name: (bar.set_postfix_str(name), bar.update(1))  # noqa: E731
    extra = {} if args.window is None else {"window_s": args.window}
    try:
        if args.per_flight:
            if not args.reference:
                raise InputError("--per-flight needs --reference LOG... (nominal flights)")
            result = diagnose_per_flight(logs, _load(args.reference), params,
                                         effects=args.effects, progress=progress, **extra)
        else:
            holdout = _load(args.holdout) if args.holdout else None
            result = diagnose(logs, params, holdout=holdout, effects=args.effects,
                              progress=progress, **extra)
    finally:
        if bar is not None:
            bar.close()
    if args.json:
        write_json(args.json, result)
    if args.report:
        write_html(args.report, result)
    if args.rerun:
        write_rerun(args.rerun, result)
    if not args.quiet:
        print(summary(result), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
