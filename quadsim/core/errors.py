"""One exception base class for the package, and the thin CLI wrapper that turns it into a
one-line message and a non-zero exit (no traceback).

Every error a user can cause (bad file, bad field, bad flag) raises a subclass of
:class:`QuadsimError` whose message names the file and the field. Programming errors are
left as ordinary exceptions so that they keep their traceback.
"""

from __future__ import annotations

import functools
import sys
import warnings
from collections.abc import Callable


class QuadsimError(Exception):
    """Base class of every error caused by the user's input."""


class InputError(QuadsimError):
    """A file, field or flag that is missing, malformed or physically implausible."""


class ModelError(QuadsimError):
    """A parameter set or model that an engine refuses (e.g. non-physical inertia)."""


class SimulationError(QuadsimError):
    """A simulation diverged (NaN, MuJoCo warning, state out of bounds).

    ``diverged``: indices of the simulations of a batch that diverged (when known);
    ``partial``: the batch's results, NaN for a diverged simulation from then on."""

    def __init__(self, message: str, *, partial: dict | None = None,
                 diverged: list[int] | None = None):
        super().__init__(message)
        self.partial, self.diverged = partial, diverged


class QuadsimWarning(UserWarning):
    """Something suspicious that does not stop the computation (said once, loudly)."""


#: longest message kept from a file or a library (characters), after making it printable.
MAX_MESSAGE = 160
#: longest error line a CLI prints (characters).
MAX_LINE = 2000


def printable(text: object, limit: int = MAX_MESSAGE) -> str:
    """``text`` as one printable line: whitespace runs collapsed to one space, characters that
    are not printable (control bytes, ...) as ``\\xNN``/``\\uNNNN`` escapes, cut at ``limit``
    characters."""
    out = []
    for ch in " ".join(str(text).split()):
        code = ord(ch)
        if ch.isprintable():
            out.append(ch)
        elif code < 256:
            out.append(f"\\x{code:02x}")
        else:
            out.append(f"\\u{code:04x}" if code < 65536 else f"\\U{code:08x}")
    line = "".join(out)
    return line if len(line) <= limit else line[:limit - 3] + "..."


def refuse_moved(module: str, gone: dict[str, str]) -> Callable[[str], object]:
    """A module-level ``__getattr__`` for ``module`` that refuses each name in ``gone`` (name ->
    what to write instead, one sentence) with ``ImportError("<module>.<name> ...: <what>")``
    and any other missing name with the usual AttributeError. Use: ``__getattr__ =
    refuse_moved(__name__, {...})`` (CHANGELOG.md lists each such name)."""

    def __getattr__(name: str):
        if name in gone:
            raise ImportError(f"{module}.{name} {gone[name]}")
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__


def field_error(path: object, field: str, message: str) -> InputError:
    """Build the package's standard one-line error: ``<file>: <field>: <message>``."""
    return InputError(f"{path}: {field}: {message}")


def warning_lines(messages: list[str]) -> list[str]:
    """``warning: ...`` lines for ``messages``: each made printable, equal ones said once
    with their count (``(x12)``), in order of first appearance."""
    counts: dict[str, int] = {}
    for message in messages:
        line = printable(message, limit=MAX_LINE)
        counts[line] = counts.get(line, 0) + 1
    return [f"warning: {line}" + (f" (x{n})" if n > 1 else "") for line, n in counts.items()]


def _said(caught) -> list[str]:
    out = []
    for w in caught:
        kind = "" if issubclass(w.category, QuadsimWarning) else f"{w.category.__name__}: "
        out.append(f"{kind}{w.message}")
    return out


def _default_interrupt() -> None:
    """Ctrl-C raises KeyboardInterrupt again (handled below) when the import-time handler of
    :mod:`quadsim` was installed; in the main thread only (signals live there)."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread() and \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        handler = signal.getsignal(signal.SIGINT)
        if getattr(handler, "__module__", None) == "quadsim":
            signal.signal(signal.SIGINT, signal.default_int_handler)


def run_cli(main: Callable[[list[str] | None], int | None]) -> Callable[[list[str] | None], int]:
    """Decorate a CLI ``main(argv)`` so that a :class:`QuadsimError` prints one line on
    stderr (``error: ...``) and exits with status 2 instead of a traceback.

    Python warnings raised while ``main`` runs (ours and those of numpy or a library) are
    recorded, never shown with their source lines: after a successful run each kind is one
    ``warning: ...`` line on stderr (:func:`warning_lines`); after a refusal only the
    ``error:`` line is printed."""

    @functools.wraps(main)
    def wrapper(argv: list[str] | None = None) -> int:
        _default_interrupt()      # the import-time handler of ``python -m quadsim.X`` ends here
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")  # once per message and place
            try:
                code = main(argv)
            except QuadsimError as exc:
                print(f"error: {printable(exc, limit=MAX_LINE)}", file=sys.stderr)
                return 2
            except KeyboardInterrupt:
                print("error: interrupted", file=sys.stderr)
                return 130
        for line in warning_lines(_said(caught)):
            print(line, file=sys.stderr)
        return int(code or 0)

    return wrapper
