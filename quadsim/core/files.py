"""Atomic output: a file is either written whole or not at all.

Writers put the bytes into a temporary file in the destination folder and rename it over
the destination (``os.replace`` is atomic on POSIX and Windows), so an interrupted run never
leaves half a file and never destroys the previous one. Folders are not created unless the
caller asks (``make_parents``): a typo in an output path is an error, not a new tree.
"""

from __future__ import annotations

import os
import tempfile
import tomllib
from pathlib import Path

from .errors import InputError


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *,
                       make_parents: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically. The folder must exist: no folder is created
    unless ``make_parents`` (for a command whose output *is* a folder). Returns the path."""
    path = Path(path)
    if not make_parents and not path.parent.is_dir():
        raise InputError(f"{path}: cannot write: folder {path.parent} does not exist "
                         "(create it first)")
    try:
        if make_parents:
            path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        # mkstemp creates 0600; give the file the permissions a plain open() would have.
        os.chmod(tmp, 0o666 & ~_current_umask())
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | os.PathLike, text: str, *,
                      make_parents: bool = False) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`)."""
    return atomic_write_bytes(path, text.encode("utf-8"), make_parents=make_parents)


def read_toml(path: str | os.PathLike) -> dict:
    """Parse a TOML file; an unreadable or malformed file raises a one-line InputError."""
    path = Path(path)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: invalid TOML: {exc}") from None
