"""Third-party parsers under a time and memory budget, their chatter captured.

A corrupt file can make a parser loop for ever (pyulog seeks back after a short read of a
damaged message header and re-reads the same bytes), allocate gigabytes (a length field
read from random bytes) or print thousands of lines (pymavlink's "bad header" reports).
:func:`run_bounded` runs ``fn(*args)`` in a child process (``fork`` where the platform has
it, else ``spawn``) whose address space is capped with ``RLIMIT_AS`` at its size when it
starts plus ``Budget.memory_bytes``, and which is killed after ``Budget.time_s`` seconds
of wall time. Inside the child, file descriptors 1 and 2 go to a temporary file and every
Python warning is recorded, so nothing the library prints reaches the terminal; the
parent gets the result and the captured lines.

Outcomes (each a one-line :class:`~quadsim.core.errors.InputError` naming ``label``):

* over the time budget -> ``<label>: parser: no result within T s (budget ...)``;
* out of memory (``MemoryError``, or the child killed) -> ``... over the memory budget``;
* a :class:`~quadsim.core.errors.QuadsimError` in the child is raised again as it was;
* any other exception (the library's reaction to bytes it did not expect) becomes
  ``<label>: <what>: cannot be parsed (<ExceptionType>: <message> at <file>:<line>)``, the
  message made printable (:func:`~quadsim.core.errors.printable`); raised in quadsim's own
  code it says ``internal error of quadsim's importer`` instead (a bug to report).

The captured output comes back as :class:`Chatter`: distinct lines with their counts, in
order of first appearance, made printable, for the caller to turn into its own warning.

Example::

    >>> from quadsim.core.bounded import Budget, run_bounded
    >>> result, chatter = run_bounded(parse, "flight.ulg", label="flight.ulg",
    ...                               what="ULog", budget=Budget(time_s=30.0))
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import tempfile
import traceback
import warnings
from collections.abc import Callable
from dataclasses import dataclass

from .errors import InputError, QuadsimError, printable

__all__ = ["Budget", "Chatter", "printable", "run_bounded"]

@dataclass(frozen=True)
class Budget:
    """Limits of one parse: ``time_s`` wall-clock seconds, ``memory_bytes`` of address space
    on top of what the child process has when it starts."""

    time_s: float = 60.0
    memory_bytes: int = 4 * 1024**3

    def __post_init__(self):
        if not self.time_s > 0 or not self.memory_bytes > 0:
            raise ValueError(f"Budget: time_s and memory_bytes must be > 0, got {self}")


@dataclass(frozen=True)
class Chatter:
    """What a library printed or warned: one example line per kind (``lines``, printable)
    and how many lines of that kind (``counts``)."""

    lines: tuple[str, ...] = ()
    counts: tuple[int, ...] = ()

    @property
    def total(self) -> int:
        return int(sum(self.counts))

    def summary(self, limit: int = 3) -> str:
        """``N line(s): "a" (x3 alike); "b"; ...`` -- at most ``limit`` kinds shown."""
        shown = [f'"{line}"' + (f" (x{n} alike)" if n > 1 else "")
                 for line, n in zip(self.lines[:limit], self.counts[:limit])]
        more = len(self.lines) - limit
        return (f"{self.total} line(s): " + "; ".join(shown)
                + (f"; {more} other kind(s)" if more > 0 else ""))


def _collect(raw: str, warned: list[str]) -> Chatter:
    """Lines that differ only in their numbers (offsets, byte values) are one kind; the
    first of each kind is kept as its example."""
    import re

    first: dict[str, str] = {}
    counts: dict[str, int] = {}
    for line in raw.splitlines() + warned:
        line = printable(line)
        if not line:
            continue
        kind = re.sub(r"0x[0-9a-fA-F]+|\d+(\.\d+)?", "#", line)
        first.setdefault(kind, line)
        counts[kind] = counts.get(kind, 0) + 1
    return Chatter(tuple(first[k] for k in counts), tuple(counts.values()))


def _address_space() -> int:
    try:
        with open("/proc/self/statm") as handle:
            return int(handle.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def _child(conn, fn, args, memory_bytes: int) -> None:
    """Runs in the worker: limits, captured output, result or error through ``conn``."""
    try:
        import resource

        limit = _address_space() + memory_bytes
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    except (ImportError, ValueError, OSError):  # no RLIMIT_AS here: time budget only
        pass
    sink = tempfile.TemporaryFile(mode="w+b")  # noqa: SIM115 (lives as long as the worker)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(sink.fileno(), 1)
    os.dup2(sink.fileno(), 2)
    # Python-level streams too (a test harness may have replaced sys.stdout by its own)
    sys.stdout = open(1, "w", closefd=False, errors="replace")  # noqa: SIM115
    sys.stderr = open(2, "w", closefd=False, errors="replace")  # noqa: SIM115
    warned: list[str] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = fn(*args)
        warned = [f"{w.category.__name__}: {w.message}" for w in caught]
        reply = ("ok", result)
    except QuadsimError as exc:
        reply = ("quadsim", exc)
    except MemoryError:
        reply = ("memory", None)
    except RecursionError:
        reply = ("other", ("RecursionError", "nesting too deep", "", False))
    except Exception as exc:  # noqa: BLE001 (whatever the library raises on bad bytes)
        where = traceback.extract_tb(exc.__traceback__)[-1]
        ours = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        internal = os.path.abspath(where.filename).startswith(ours + os.sep)
        reply = ("other", (type(exc).__name__, str(exc),
                           f"{os.path.basename(where.filename)}:{where.lineno}", internal))
    sys.stdout.flush()
    sys.stderr.flush()
    sink.seek(0)
    raw = sink.read(1 << 20).decode("utf-8", "replace")
    try:
        conn.send((reply, _collect(raw, warned)))
    except MemoryError:
        conn.send((("memory", None), Chatter()))
    conn.close()


def _context():
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("fork" if "fork" in methods else "spawn")


def run_bounded(fn: Callable, *args, label: str, what: str,
                budget: Budget = Budget()) -> tuple[object, Chatter]:
    """``(fn(*args), chatter)`` computed in a child process under ``budget`` (see the
    module docstring). ``label`` names the input (the file) and ``what`` the parser in
    error messages. ``fn`` and ``args`` must be picklable when ``spawn`` is used."""
    ctx = _context()
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args, budget.memory_bytes), daemon=True)
    proc.start()
    send.close()
    try:
        ready = receive.poll(budget.time_s)
        message = None
        if ready:
            try:
                message = receive.recv()
            except (EOFError, OSError):
                message = None
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join()
        receive.close()
    if not ready:
        raise InputError(f"{label}: {what}: no result within {budget.time_s:g} s (the time "
                         "budget of a parse): the file is corrupt or far larger than a flight")
    if message is None:
        raise InputError(f"{label}: {what}: the parser stopped (exit {proc.exitcode}) before "
                         f"a result; over the memory budget of {budget.memory_bytes / 2**30:g} "
                         "GiB or a crash on corrupt data")
    (kind, payload), chatter = message
    if kind == "ok":
        return payload, chatter
    if kind == "quadsim":
        raise payload
    if kind == "memory":
        raise InputError(f"{label}: {what}: over the memory budget of "
                         f"{budget.memory_bytes / 2**30:g} GiB (the file is corrupt or far "
                         "larger than a flight)")
    name, text, where, internal = payload
    kind = "internal error of quadsim's importer" if internal else "cannot be parsed"
    raise InputError(f"{label}: {what}: {kind} ({name}: {printable(text)}"
                     + (f" at {where}" if where else "") + ")")
