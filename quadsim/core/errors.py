"""One exception base class for the package, and the thin CLI wrapper that turns it into a
one-line message and a non-zero exit (no traceback).

Every error a user can cause (bad file, bad field, bad flag) raises a subclass of
:class:`QuadsimError` whose message names the file and the field. Programming errors are
left as ordinary exceptions so that they keep their traceback.
"""

from __future__ import annotations

import functools
import sys
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


def field_error(path: object, field: str, message: str) -> InputError:
    """Build the package's standard one-line error: ``<file>: <field>: <message>``."""
    return InputError(f"{path}: {field}: {message}")


def run_cli(main: Callable[[list[str] | None], int | None]) -> Callable[[list[str] | None], int]:
    """Decorate a CLI ``main(argv)`` so that a :class:`QuadsimError` prints one line on
    stderr (``error: ...``) and exits with status 2 instead of a traceback."""

    @functools.wraps(main)
    def wrapper(argv: list[str] | None = None) -> int:
        try:
            code = main(argv)
        except QuadsimError as exc:
            message = " ".join(str(exc).split())
            print(f"error: {message}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("error: interrupted", file=sys.stderr)
            return 130
        return int(code or 0)

    return wrapper
