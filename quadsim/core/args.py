"""Command-line argument checks every CLI runs *before* any work starts.

argparse checks types; these check meaning: numeric ranges (``--window -0.1``), finite values, input
files that exist, the same file given twice or in two roles (training and ``--holdout``; also a
byte-identical copy), and output paths that can be written (suffix, not a directory, not an input,
folder exists and is writable), so that a long computation never fails at its last step. Each
failure is one :class:`~quadsim.core.errors.InputError` line naming the flag (or the file) and the
value. Nothing here writes anything.

Example::

    >>> from quadsim.core.args import check_number, check_output, distinct_files
    >>> check_number("--window", 0.1, low=0.0)            # passes
    >>> distinct_files({"LOG": ["a.csv"], "--holdout": ["a.csv"]})   # InputError
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path

from .errors import InputError

__all__ = ["ArgumentParser", "check_inputs", "check_number", "check_output", "distinct_files"]


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose usage errors (unknown flag, missing argument, bad type) are
    one line on stderr, ``<prog>: error: <message> (see --help)``, and exit status 2 --
    like every other input error of quadsim's CLIs, without the usage block."""

    def error(self, message: str):
        print(f"{self.prog}: error: {' '.join(message.split())} (see --help)", file=sys.stderr)
        sys.exit(2)


def check_number(flag: str, value: float | None, *, low: float | None = None,
                 high: float | None = None, low_inclusive: bool = False,
                 unit: str = "") -> None:
    """Refuse a non-finite ``value`` or one outside ``(low, high]`` (``[low, high]`` with
    ``low_inclusive``). ``None`` (flag not given) passes."""
    if value is None:
        return
    shown = f"{flag} {value:g}{' ' + unit if unit else ''}"
    if not math.isfinite(value):
        raise InputError(f"{shown}: must be a finite number")
    if low is not None and (value < low or (value == low and not low_inclusive)):
        raise InputError(f"{shown}: must be {'>=' if low_inclusive else '>'} {low:g}")
    if high is not None and value > high:
        raise InputError(f"{shown}: must be <= {high:g}")


def check_inputs(flag: str, paths: Iterable[str | os.PathLike] | None) -> None:
    """Every input file exists and is a file (not a folder)."""
    for path in paths or ():
        path = Path(path)
        if not path.exists():
            raise InputError(f"{path}: {flag}: file not found")
        if path.is_dir():
            raise InputError(f"{path}: {flag}: is a directory, not a file")


def _key(path: Path) -> tuple:
    try:
        stat = path.stat()
        return ("inode", stat.st_dev, stat.st_ino)
    except OSError:
        return ("path", str(path.resolve()))


def _content(path: Path) -> tuple | None:
    """(size, sha256) of a file's bytes; None when it cannot be read."""
    import hashlib

    try:
        digest = hashlib.sha256()
        with open(path, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
        return ("content", path.stat().st_size, digest.hexdigest())
    except OSError:
        return None


def distinct_files(roles: Mapping[str, Iterable[str | os.PathLike] | None]) -> None:
    """Refuse a file given twice in one role or in two roles (e.g. ``LOG`` and
    ``--holdout``), also as a byte-identical copy under another name: a flight in both
    training and held-out sets would score its own fit."""
    seen: dict[tuple, tuple[str, Path]] = {}
    for role, paths in roles.items():
        for path in paths or ():
            path = Path(path)
            key = _key(path)
            copy = _content(path)
            if key not in seen and copy is not None and copy in seen:
                first_role, first = seen[copy]
                raise InputError(f"{path}: {role}: the same bytes as {first} ({first_role}); "
                                 "each flight once (training and held-out must differ)")
            if copy is not None:
                seen.setdefault(copy, (role, path))
            if key in seen:
                first_role, first = seen[key]
                if first_role == role:
                    same = "" if str(first) == str(path) else f" (also as {first})"
                    raise InputError(f"{path}: {role}: given twice{same}; each flight once")
                raise InputError(f"{path}: given both as {first_role} and as {role}; a flight "
                                 "cannot be in both roles (training and held-out must differ)")
            seen[key] = (role, path)


def check_output(flag: str, path: str | os.PathLike | None,
                 suffixes: tuple[str, ...] | None = None,
                 inputs: Iterable[str | os.PathLike] = ()) -> None:
    """An output file can be written at ``path``: its name ends in one of ``suffixes``, it
    is not a directory, it is not one of the ``inputs``, and its folder exists and is
    writable. Writes nothing."""
    if path is None:
        return
    path = Path(path)
    if suffixes and not path.name.endswith(tuple(suffixes)):
        raise InputError(f"{path}: {flag}: output name must end in {' or '.join(suffixes)}")
    if path.is_dir():
        raise InputError(f"{path}: {flag}: is a directory; give a file name")
    for other in inputs:
        if Path(other).exists() and path.exists() and _key(Path(other)) == _key(path):
            raise InputError(f"{path}: {flag}: is also an input; it would be overwritten")
    parent = path.parent
    if not parent.exists():
        raise InputError(f"{path}: {flag}: folder {parent} does not exist (outputs never "
                         "create folders; create it first)")
    if not parent.is_dir():
        raise InputError(f"{path}: {flag}: cannot write: {parent} is not a directory")
    try:  # a real probe: os.access says yes to root even on read-only file systems
        fd, probe = tempfile.mkstemp(prefix=".quadsim-probe.", dir=parent)
    except OSError as exc:
        raise InputError(f"{path}: {flag}: cannot write in folder {parent}: "
                         f"{exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)
