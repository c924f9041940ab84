"""quadsim: CAD parts of a small quadrotor -> MuJoCo model, analytic reference, rerun viewer,
and sim-to-real gap diagnosis.

Conventions: SI units inside; world z up; body x forward, y left, z up; quaternions
scalar-first (w, x, y, z), body to world. See :mod:`quadsim.vehicle.params` and
:mod:`quadsim.vehicle.state`.
"""

__version__ = "0.1.0"


def _interrupted_while_starting(signum, frame):
    """SIGINT while a ``python -m quadsim.X`` command is still importing (before
    :func:`quadsim.core.errors.run_cli` takes over): one line, exit status 130, no traceback
    of the import machinery."""
    import sys

    print("error: interrupted", file=sys.stderr)
    raise SystemExit(130)


def _catch_early_interrupt() -> None:
    """Installed only when the package is imported by ``python -m`` (``sys.argv[0]`` is
    ``"-m"`` while runpy imports the parent packages): a library import never changes the
    signal handlers. ``run_cli`` puts the default handler back once ``main`` runs."""
    import signal
    import sys
    import threading

    if (sys.argv[:1] == ["-m"] and threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
        signal.signal(signal.SIGINT, _interrupted_while_starting)


_catch_early_interrupt()
