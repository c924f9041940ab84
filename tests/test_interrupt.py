"""Ctrl-C while a ``python -m quadsim.X`` command starts (issue 44, item 7): one line, exit
130, from the package's first statement on; a library import leaves the handlers alone and
imports no module for it (``_signal`` is built in: ``signal`` would import ``enum``)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(code: str) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter started as from an interactive shell: SIGINT at its
    default disposition (a suite run as a background job, ``cmd &`` in a script, inherits
    SIGINT ignored, and Python then keeps it ignored, as the package does)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=120,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def test_interrupt_during_the_first_imports_is_one_line():
    """SIGINT delivered right after the package's first statement, while ``quadsim.gap``
    and its numpy/scipy imports are still to come (as ``python -m`` sees it: argv[0] "-m")."""
    done = _run("import sys; sys.argv[0] = '-m'; import quadsim, os, signal; "
                "os.kill(os.getpid(), signal.SIGINT); import quadsim.gap.__main__; "
                "print('not interrupted')")
    assert done.returncode == 130
    assert done.stderr == "error: interrupted\n" and done.stdout == ""


def test_a_library_import_sets_no_handler_and_imports_nothing_for_it():
    done = _run("import sys, _signal; before = set(sys.modules); import quadsim; "
                "print(_signal.getsignal(_signal.SIGINT) is _signal.default_int_handler, "
                "sorted({'signal', 'threading', 'enum'} & (set(sys.modules) - before)))")
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["True", "[]"]
