"""One executor for many independent tasks: in-process, local processes, or a Ray cluster.

``run_tasks(fn, tasks)`` returns ``[fn(t) for t in tasks]`` - the same values, in task order,
whichever executor runs them (each task is computed by the same code on the same inputs, so
results are bit-identical and every file written from them is byte-identical):

* ``workers=1``: in this process, a plain loop (no pickling);
* ``workers=N`` (default: the CPU count): ``N`` local processes (``concurrent.futures``
  ``ProcessPoolExecutor``, ``spawn`` start method so that no thread state is forked);
* ``ray="local"``: starts a local Ray cluster with ``workers`` CPUs (default all);
  ``ray="HOST:PORT"`` (or ``ray://HOST:PORT``) connects to a running cluster. Ray is an
  optional extra: ``pip install -e '.[ray]'``.

``fn`` must be a module-level function (or a ``functools.partial`` of one) and the tasks
picklable. Exceptions raised by ``fn`` propagate unchanged (the first in task order).

A worker that *dies* mid-task (killed, out of memory, segfault) is different: that task is
retried once; if it dies again, it is reported as a :class:`TaskFailure` in its slot
(``keep_going=True``) or raises a one-line :class:`~quadsim.core.errors.InputError` naming it,
after every other task has finished (``keep_going=False``). With processes, a dead worker
breaks the whole pool: the unfinished tasks are rerun in a fresh pool, and if that breaks
again each is rerun alone, so that only the task that kills its worker is blamed. Ray does
this per task (``max_retries=1``).

Threads: a command's own process runs the numeric libraries (OpenBLAS, MKL, OpenMP) on
``QUADSIM_THREADS`` threads, default 1 (:func:`limit_numeric_threads`, applied by the
commands ``gap``, ``identify`` and ``sweep``); each spawned worker on one.

Example::

    >>> from quadsim.core.executor import run_tasks
    >>> run_tasks(abs, [-1, 2, -3], workers=1)
    [1, 2, 3]
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import socket
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from .errors import InputError

__all__ = [
    "DEFAULT_THREADS",
    "RAY_CONNECT_TIMEOUT_S",
    "THREADS_ENV",
    "TaskFailure",
    "connect_ray",
    "default_workers",
    "limit_numeric_threads",
    "numeric_threads",
    "run_tasks",
]

#: seconds to wait for a TCP connection to a Ray head before calling it unreachable
RAY_CONNECT_TIMEOUT_S = 5.0


@dataclass(frozen=True)
class TaskFailure:
    """A task whose worker died twice: its index in the task list, a label and why."""

    index: int
    label: str
    message: str


def default_workers() -> int:
    """The CPU count this process may use (``os.sched_getaffinity`` where available)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:                                    # macOS, Windows
        return max(1, os.cpu_count() or 1)


def _label(labels, i) -> str:
    return str(labels[i]) if labels is not None else f"task {i}"


def _finish(results, failures, labels, keep_going):
    if failures and not keep_going:
        names = ", ".join(_label(labels, f.index) for f in failures)
        raise InputError(f"worker died twice running {names}: {failures[0].message}")
    for f in failures:
        results[f.index] = f
    return results


#: the environment variable that sets the numeric libraries' threads of a command's own process
THREADS_ENV = "QUADSIM_THREADS"
#: their default: one: the linear algebra is on small matrices, where a second thread costs
#: more in spinning and handing over than it gains (README, "Speed": the CPU measured).
DEFAULT_THREADS = 1


def numeric_threads() -> int | None:
    """The thread count for BLAS/OpenMP in a command's own process: ``QUADSIM_THREADS`` (a
    positive integer; ``0``: the libraries' own choice, returned as None), else
    :data:`DEFAULT_THREADS`. Anything else raises a one-line InputError."""
    text = os.environ.get(THREADS_ENV, "").strip()
    if not text:
        return DEFAULT_THREADS
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise InputError(f"{THREADS_ENV}: {text!r} is not a thread count (a positive integer, "
                         "or 0 for the numeric libraries' own choice)")
    return value or None


def limit_numeric_threads(main: Callable) -> Callable:
    """Decorate a command's ``main``: while it runs, the numeric libraries' thread pools
    (OpenBLAS, MKL, OpenMP: threadpoolctl) in this process hold :func:`numeric_threads`
    threads; restored afterwards (so a test calling ``main`` in-process keeps its own).
    Spawned workers get one thread each (:data:`SINGLE_THREAD_ENV`) whatever this says."""

    @functools.wraps(main)
    def wrapper(*args, **kwargs):
        threads = numeric_threads()
        if threads is None:
            return main(*args, **kwargs)
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=threads):
            return main(*args, **kwargs)

    return wrapper


#: one thread per worker for the numeric libraries: the workers are the parallelism
SINGLE_THREAD_ENV = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                      "MKL_NUM_THREADS")}


@contextmanager
def _worker_env():
    """Spawned workers inherit the environment at start: set SINGLE_THREAD_ENV (where the
    user has not) while the pool runs, then restore it."""
    added = {k: v for k, v in SINGLE_THREAD_ENV.items() if k not in os.environ}
    os.environ.update(added)
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


def _run_pool(fn, tasks, indices, workers, results, progress):
    """Run ``indices`` in one pool; return the indices left unfinished by a broken pool."""
    ctx = multiprocessing.get_context("spawn")
    broken = []
    with _worker_env(), ProcessPoolExecutor(max_workers=min(workers, len(indices)),
                                            mp_context=ctx) as pool:
        futures = {pool.submit(fn, tasks[i]): i for i in indices}
        for future in as_completed(futures):
            i = futures[future]
            try:
                results[i] = future.result()
            except BrokenProcessPool:
                broken.append(i)
                continue
            if progress is not None:
                progress(i, results[i])
    return sorted(broken)


def _run_processes(fn, tasks, workers, progress, labels):
    results: list = [None] * len(tasks)
    left = _run_pool(fn, tasks, list(range(len(tasks))), workers, results, progress)
    if left:                                                  # retry once, together
        left = _run_pool(fn, tasks, left, workers, results, progress)
    failures = []
    for i in left:                                            # isolate the culprit(s)
        if _run_pool(fn, tasks, [i], 1, results, progress):
            failures.append(TaskFailure(i, _label(labels, i), "worker process died"))
    return results, failures


def _ray():
    try:
        import ray
    except ImportError:
        raise InputError("--ray: Ray is not installed; install the extra: "
                         "pip install -e '.[ray]'") from None
    return ray


def _reachable(address: str) -> None:
    hostport = address.split("://", 1)[-1].rstrip("/")
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise InputError(f"--ray: {address!r} is not 'local' or HOST:PORT")
    try:
        with socket.create_connection((host, int(port)), timeout=RAY_CONNECT_TIMEOUT_S):
            pass
    except OSError as exc:
        raise InputError(f"--ray: cannot reach a Ray cluster at {address} within "
                         f"{RAY_CONNECT_TIMEOUT_S:g} s: {exc.strerror or exc}") from None


def connect_ray(address: str, workers: int | None = None):
    """Start (``"local"``) or join (``HOST:PORT``) a Ray cluster once; return the module."""
    ray = _ray()
    if ray.is_initialized():
        return ray
    package_root = str(Path(__file__).resolve().parents[2])
    if address == "local":
        # Workers must import *this* quadsim (not another install): put it on their path.
        env = {"env_vars": {"PYTHONPATH": os.pathsep.join(
            p for p in (package_root, os.environ.get("PYTHONPATH")) if p),
            **{k: os.environ.get(k, v) for k, v in SINGLE_THREAD_ENV.items()}}}
        ray.init(num_cpus=workers or default_workers(), include_dashboard=False,
                 log_to_driver=False, logging_level="ERROR", runtime_env=env)
    else:
        _reachable(address)
        try:
            ray.init(address=address, logging_level="ERROR", log_to_driver=False)
        except Exception as exc:                              # noqa: BLE001 - any Ray failure
            raise InputError(f"--ray: cannot connect to {address}: "
                             f"{' '.join(str(exc).split())[:200]}") from None
    return ray


def _call(fn, task):
    return fn(task)


def _run_ray(fn, tasks, ray_address, workers, progress, labels):
    ray = connect_ray(ray_address, workers)
    remote = ray.remote(max_retries=1, retry_exceptions=False)(_call)
    fn_ref = ray.put(fn)
    refs = [remote.remote(fn_ref, t) for t in tasks]
    index = {r: i for i, r in enumerate(refs)}
    results: list = [None] * len(tasks)
    failures, error = [], None
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        i = index[done[0]]
        try:
            results[i] = ray.get(done[0])
        except (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError,
                ray.exceptions.OutOfMemoryError) as exc:
            failures.append(TaskFailure(i, _label(labels, i), type(exc).__name__))
            continue
        except ray.exceptions.RayTaskError as exc:            # fn raised: re-raise its error
            error = error or (i, exc.as_instanceof_cause())
            continue
        if progress is not None:
            progress(i, results[i])
    if error is not None:
        cause = error[1]
        raise (cause.cause if getattr(cause, "cause", None) is not None else cause)
    return results, sorted(failures, key=lambda f: f.index)


def run_tasks(fn: Callable, tasks: Sequence, *, workers: int | None = None,
              ray: str | None = None, progress: Callable[[int, object], None] | None = None,
              labels: Sequence[str] | None = None, keep_going: bool = False) -> list:
    """``[fn(t) for t in tasks]`` on the chosen executor (see the module docstring).

    ``progress(i, result)`` is called in this process as task ``i`` finishes (any order;
    e.g. to save each result at once);
    ``labels`` name the tasks in failure reports (default ``task <i>``)."""
    tasks = list(tasks)
    if workers is not None and workers < 1:
        raise InputError(f"--workers: must be >= 1, got {workers}")
    if not tasks:
        return []
    if ray is not None:
        results, failures = _run_ray(fn, tasks, ray, workers, progress, labels)
        return _finish(results, failures, labels, keep_going)
    workers = default_workers() if workers is None else workers
    if workers == 1 or len(tasks) == 1:
        out = []
        for i, task in enumerate(tasks):
            out.append(fn(task))
            if progress is not None:
                progress(i, out[-1])
        return out
    results, failures = _run_processes(fn, tasks, workers, progress, labels)
    return _finish(results, failures, labels, keep_going)
