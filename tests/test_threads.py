"""A command's own process runs the numeric libraries on ``QUADSIM_THREADS`` threads (default
1), restored when its ``main`` returns; a bad value is a one-line error, exit 2."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy  # noqa: F401  (loads OpenBLAS, so that threadpoolctl sees it)
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from quadsim.core.errors import InputError
from quadsim.core.executor import DEFAULT_THREADS, limit_numeric_threads, numeric_threads


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_thread_count_from_the_environment(monkeypatch):
    monkeypatch.delenv("QUADSIM_THREADS", raising=False)
    assert numeric_threads() == DEFAULT_THREADS == 1
    monkeypatch.setenv("QUADSIM_THREADS", "3")
    assert numeric_threads() == 3
    monkeypatch.setenv("QUADSIM_THREADS", "0")
    assert numeric_threads() is None
    for bad in ("two", "-1", "1.5"):
        monkeypatch.setenv("QUADSIM_THREADS", bad)
        with pytest.raises(InputError, match=rf"^QUADSIM_THREADS: '{bad}' is not a thread count"):
            numeric_threads()


def test_main_runs_limited_and_the_limit_is_restored(monkeypatch):
    if not _blas_threads():
        pytest.skip("no BLAS library that threadpoolctl can see")
    monkeypatch.setenv("QUADSIM_THREADS", "1")

    @limit_numeric_threads
    def main(seen):
        seen.extend(_blas_threads())
        return 7

    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        seen: list[int] = []
        assert main(seen) == 7
        assert seen and set(seen) == {1}
        assert _blas_threads() == before
    monkeypatch.setenv("QUADSIM_THREADS", "0")         # the libraries' own choice: untouched
    with threadpool_limits(limits=2, user_api="blas"):
        seen = []
        main(seen)
        assert seen == _blas_threads()


def test_bad_thread_count_is_one_line_through_a_command():
    run = subprocess.run([sys.executable, "-m", "quadsim.sweep", "--help"], capture_output=True,
                         text=True, timeout=120, check=False,
                         env={**os.environ, "QUADSIM_THREADS": "many"})
    assert run.returncode == 2
    assert run.stderr.strip() == ("error: QUADSIM_THREADS: 'many' is not a thread count (a "
                                  "positive integer, or 0 for the numeric libraries' own choice)")
