"""Atomic output: a file is either written whole or not at all.

Writers put the bytes into a temporary file in the destination folder and rename it over
the destination (``os.replace`` is atomic on POSIX and Windows), so an interrupted run never
leaves half a file and never destroys the previous one. Folders are not created unless the
caller asks (``make_parents``): a typo in an output path is an error, not a new tree.

TOML in and out: :func:`read_toml` (one-line errors), :func:`check_schema` (a file of an
earlier schema name read with one warning, any other refused in one line) and
:func:`render_toml` (the writer of parameter sets, skeletons and effect files).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import tomllib
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .errors import InputError, QuadsimWarning, field_error


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
    """Parse a TOML file; an unreadable or malformed file raises a one-line InputError (a
    binary file, e.g. a flight log given where a TOML belongs, is named by its first bytes)."""
    path = Path(path)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        what = ("gzip-compressed (a .csv.gz flight log?)" if exc.object[:2] == b"\x1f\x8b"
                else f"byte 0x{exc.object[exc.start]:02x} at offset {exc.start} is not UTF-8 "
                "text (a binary file?)")
        raise InputError(f"{path}: header: not a TOML text file: {what}") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: invalid TOML: {exc}") from None


def check_schema(data: dict, path: object, schema: str,
                 earlier: Mapping[str, str] | None = None) -> dict:
    """``data`` (a file's parsed top level) checked against ``schema``, its ``schema`` key
    migrated in memory where it names an earlier schema; the file itself is never rewritten.

    ``earlier`` maps each earlier schema name whose content reads unchanged under ``schema``
    to what renamed it (a phrase for the warning). A file of an earlier name gives one
    :class:`~quadsim.core.errors.QuadsimWarning` naming the old schema and the line to change,
    and is returned as a copy whose ``schema`` is ``schema``; any other value raises the
    one-line ``<file>: schema: expected ...`` :class:`InputError`."""
    earlier = earlier or {}
    got = data.get("schema")
    if got == schema:
        return data
    if isinstance(got, str) and got in earlier:
        warnings.warn(f"{path}: schema: {got!r} is the earlier name of {schema!r} "
                      f"({earlier[got]}); read as {schema!r}: write schema = \"{schema}\" in "
                      "the file to silence this warning", QuadsimWarning, stacklevel=2)
        return {**data, "schema": schema}
    also = "".join(f" (or the earlier {name!r})" for name in earlier)
    raise field_error(path, "schema", f"expected {schema!r}{also}, got {got!r}")


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if not math.isfinite(f):
            raise ValueError(f"non-finite value {f} in a TOML file")
        return repr(f)
    if isinstance(v, np.ndarray):
        return _toml_value(v.tolist())
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def render_toml(data: dict, header: str = "") -> str:
    """TOML text of ``data`` (a parameter set, a skeleton or an effect file): ``header`` as
    ``#`` comment lines, then the top-level keys, then the tables, then the arrays of tables
    (``[[rotor]]``, ``[[effect]]``), each in ``data``'s order. Values: bool, str, int,
    finite float (``repr``: round-trips exactly), NumPy arrays and lists (inline arrays) and
    dicts (inline tables); a non-finite float raises ValueError, another type TypeError."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    tables = {k: v for k, v in data.items() if isinstance(v, dict)}
    arrays = {k: v for k, v in data.items()
              if isinstance(v, list) and v and all(isinstance(x, dict) for x in v)}
    for key, value in data.items():
        if key not in tables and key not in arrays:
            lines.append(f"{key} = {_toml_value(value)}")
    for name, table in tables.items():
        lines += ["", f"[{name}]"] + [f"{k} = {_toml_value(v)}" for k, v in table.items()]
    for name, entries in arrays.items():
        for entry in entries:
            lines += ["", f"[[{name}]]"] + [f"{k} = {_toml_value(v)}" for k, v in entry.items()]
    return "\n".join(lines) + "\n"
