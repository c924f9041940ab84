"""The references' stage kept on disk between runs of ``python -m quadsim.gap``.

A run with ``--reference`` (per flight, or held out) spends most of its fixed cost on the
reference flights alone: loading and checking them, preparing them, their calibration and
their self-check (:func:`quadsim.gap.diagnose.diagnose_per_flight`, the
:class:`quadsim.gap.calibrate.Calibrated` stage). A user judges new flights against the
same references again and again; this module keeps that stage in a cache folder, so that a
later run whose inputs are the same reads it instead of computing it.

Where: ``--cache-dir DIR``, else ``$QUADSIM_CACHE_DIR``, else
``${XDG_CACHE_HOME:-~/.cache}/quadsim`` (:func:`cache_dir`); one file per entry,
``gap-reference-KEY.pkl``. ``--no-cache``: neither read nor written.

Key (:func:`entry_key`): SHA-256 over :data:`ENTRY_SCHEMA`, quadsim's version and
:func:`quadsim.gap.calibrate.code_version` (every ``quadsim/**/*.py`` source, numpy's and
scipy's versions: any code change misses), the Python version and machine, the numeric
libraries' thread settings (``QUADSIM_THREADS`` and the ``*_NUM_THREADS`` variables: a
thread count can move a BLAS result in its last bits), the parameter set's content and the
effects already in the model (``--effects-file``'s, both pickled), ``--effects`` (in the
given order), ``--window``, and each reference file and each ``--command-reference`` file
in the given order: its name as given (the result names the references by it) and its
bytes. The same key: the same entry, bit for bit, so a run that reads it writes the same
result JSON as one that computes it.

What an entry holds (:class:`Entry`): the stage itself, and what loading the references
left for the run (their warnings, their logged sample count for the cost caps), so that a
run that reads it need not load them at all (unless another log needs rotor speeds
synthesised from them: :mod:`quadsim.gap.logcheck`).

Entries are Python pickles: unpickling runs code named in the file, so the folder must be
the user's own (the default one is; pass ``--cache-dir`` only a folder you own). An entry
that does not read back as the entry of its key is ignored with one ``warning:`` line and
computed again (and written anew); a folder that cannot be written leaves the run as it is,
with one ``warning:`` line.

Bounded: after each write the entries beyond the newest :data:`MAX_ENTRIES` (by modification
time; a read refreshes its entry's time) or beyond :data:`MAX_BYTES` in all are deleted,
oldest first (an entry for the 20 Crazyflie references is ~85 kB). Clearing it by hand:
delete the ``gap-reference-*.pkl`` files (or the folder).
"""

from __future__ import annotations

import hashlib
import os
import pickle
import platform
import sys
from dataclasses import dataclass
from pathlib import Path

from ..core.errors import InputError

__all__ = ["ENTRY_SCHEMA", "MAX_BYTES", "MAX_ENTRIES", "PREFIX", "Entry", "ReferenceStore",
           "cache_dir", "entry_key"]

#: hashed first: a new version when :class:`Entry` changes
ENTRY_SCHEMA = "quadsim.gap.reference-cache/1"
#: file names of the entries: PREFIX + key + ".pkl" (only these are read or deleted)
PREFIX = "gap-reference-"
#: entries kept at most (the newest): a user's few reference sets, each model and option
MAX_ENTRIES = 16
#: bytes kept at most in all (the newest entries that fit; the newest one always kept)
MAX_BYTES = 512 * 1024**2
#: environment variables of the numeric libraries' threads (part of the key)
THREAD_VARS = ("QUADSIM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def cache_dir(given: str | os.PathLike | None = None) -> Path:
    """The cache folder: ``given`` (``--cache-dir``), else ``$QUADSIM_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/quadsim``, else ``~/.cache/quadsim`` (an empty variable counts as
    unset)."""
    if given is not None:
        return Path(given).expanduser()
    if os.environ.get("QUADSIM_CACHE_DIR"):
        return Path(os.environ["QUADSIM_CACHE_DIR"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path("~/.cache").expanduser())
    return Path(base) / "quadsim"


def entry_key(references, params, *, effects=None, window_s: float, base: tuple = (),
              command_references=(), as_commands: bool = False) -> str:
    """SHA-256 (hex) of everything the references' stage reads (module doc, "Key"):
    ``references`` and ``command_references`` are file paths (names as given, bytes read
    here), ``params`` the loaded parameter set, ``effects`` the ``--effects`` names (None:
    all), ``window_s`` the smoothing window (s), ``base`` the effects already in the model,
    ``as_commands`` the references judged as command-only (their speeds cut and synthesised:
    ``quadsim.gap.__main__._judged_as_commands``; another stage of the same files).
    Raises :class:`InputError` for a file that cannot be read."""
    from .. import __version__
    from .calibrate import CALIBRATED_SCHEMA, code_version

    digest = hashlib.sha256(f"{ENTRY_SCHEMA}\0{CALIBRATED_SCHEMA}\0quadsim {__version__}\0"
                            f"{code_version()}\0{sys.version}\0{platform.machine()}\0".encode())
    from ..core.executor import numeric_threads

    digest.update(repr((numeric_threads(), [os.environ.get(v) for v in THREAD_VARS])).encode())
    digest.update(pickle.dumps((params, None if effects is None else tuple(effects),
                                float(window_s), tuple(base)), protocol=4))
    if as_commands:
        digest.update(b"\0references judged as command-only\0")
    for role, paths in (("reference", references), ("command-reference", command_references)):
        digest.update(f"\0{role} {len(paths)}\0".encode())
        for path in paths:
            try:
                data = Path(path).read_bytes()
            except OSError as exc:
                raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
            digest.update(f"{path}\0{len(data)}\0".encode())
            digest.update(data)
    return digest.hexdigest()


@dataclass(frozen=True)
class Entry:
    """One cache entry: ``key`` (:func:`entry_key`), ``stage`` (the references'
    :class:`quadsim.gap.calibrate.Calibrated`), ``found`` and ``notes`` (the loader's
    warnings and the checks' notes on the references, as the CLI prints them), ``samples``
    (their logged samples, counted against the cost caps)."""

    key: str
    stage: object
    found: tuple
    notes: tuple
    samples: int


@dataclass(frozen=True)
class ReferenceStore:
    """The cache folder ``folder`` (module doc): :meth:`get` an entry by key,
    :meth:`put` one (then the oldest beyond the bounds deleted)."""

    folder: Path

    def path(self, key: str) -> Path:
        return self.folder / f"{PREFIX}{key}.pkl"

    def get(self, key: str) -> Entry | None:
        """The entry of ``key``, or None: none kept (silently), or one that does not read
        back as the entry of its key (one ``warning:`` line; computed again)."""
        path = self.path(key)
        try:
            data = path.read_bytes()
        except (FileNotFoundError, NotADirectoryError):    # none kept (or no folder)
            return None
        except OSError as exc:
            print(f"warning: {path}: cache entry not readable ({exc.strerror or exc}): the "
                  "references computed again", file=sys.stderr)
            return None
        try:
            value = pickle.loads(data)
        except Exception:       # any unpickling failure: computed again, written anew
            value = None
        if not (isinstance(value, Entry) and value.key == key):
            print(f"warning: {path}: not a readable cache entry: the references computed "
                  "again", file=sys.stderr)
            return None
        try:
            os.utime(path)      # the newest again: evicted last
        except OSError:
            pass
        return value

    def put(self, entry: Entry) -> Path | None:
        """Write ``entry`` atomically (a temporary file, then ``os.replace``) and delete the
        entries beyond the bounds; -> its path, or None when it cannot be written (one
        ``warning:`` line; the run goes on)."""
        from ..core.files import atomic_write_bytes

        try:
            path = atomic_write_bytes(self.path(entry.key), pickle.dumps(entry, protocol=4),
                                      make_parents=True)
        except InputError as exc:
            print(f"warning: {exc}: the references' cache not written", file=sys.stderr)
            return None
        self.prune(keep=path)
        return path

    def prune(self, keep: Path | None = None) -> list[Path]:
        """Delete the entries beyond the newest :data:`MAX_ENTRIES` or :data:`MAX_BYTES` in
        all (``keep`` never); -> the deleted paths. Files it cannot stat or delete are left."""
        entries = []
        for path in self.folder.glob(f"{PREFIX}*.pkl"):
            try:
                stat = path.stat()
            except OSError:
                continue
            entries.append((path != keep, -stat.st_mtime, stat.st_size, path))
        entries.sort(key=lambda e: e[:2])   # ``keep`` first, then newest first
        deleted, total = [], 0
        kept = 0
        for _, _, size, path in entries:
            if path != keep and (kept >= MAX_ENTRIES or total + size > MAX_BYTES):
                try:
                    path.unlink()
                    deleted.append(path)
                    continue
                except OSError:
                    pass
            kept, total = kept + 1, total + size
        return deleted
