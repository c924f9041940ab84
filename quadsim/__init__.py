"""quadsim: CAD parts of a small quadrotor -> MuJoCo model, analytic reference, rerun viewer,
and sim-to-real gap diagnosis.

Conventions: SI units inside; world z up; body x forward, y left, z up; quaternions
scalar-first (w, x, y, z), body to world. See :mod:`quadsim.vehicle.params` and
:mod:`quadsim.vehicle.state`.
"""


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
    signal handlers. ``run_cli`` puts the default handler back once ``main`` runs. The first
    statement of the package, with built-in modules only (``_signal``, not ``signal``, which
    imports ``enum``: ~10 ms in which Python's own traceback would still be printed);
    off the main thread ``_signal.signal`` raises ValueError and nothing is installed."""
    import _signal
    import sys

    if sys.argv[:1] == ["-m"] and _signal.getsignal(_signal.SIGINT) is \
            _signal.default_int_handler:
        try:
            _signal.signal(_signal.SIGINT, _interrupted_while_starting)
        except ValueError:      # not the main thread: signals are not ours to set there
            pass


_catch_early_interrupt()

__version__ = "0.1.0"
