"""Parallel test runs by default, serial runs unchanged.

With pytest-xdist installed (the ``test`` extra), ``python -m pytest -q`` runs the suite on
``xdist_workers`` worker processes with ``--dist xdist_dist`` (both in ``[tool.pytest.ini_options]``
of pyproject.toml): the README's command and ``.ci/run`` stay the same command. The default is
applied here and not in ``addopts`` because ``-n`` in ``addopts`` breaks every run without the
plugin (``-p no:xdist``, or a developer without xdist: "unrecognized arguments: -n").
A command line that names ``-n`` / ``--numprocesses`` (``-n 0``: serial), ``--pdb`` or
``-p no:xdist`` keeps its own choice.

``--dist loadgroup``: tests marked ``pytest.mark.xdist_group(NAME)`` run on one worker, in one
go (a module whose module-scoped fixture flies flights marks itself so that the fixture is
built once, not once per worker); every other test goes to whichever worker is free.

The workers are the parallelism: like quadsim's own process pools
(``quadsim.core.executor.SINGLE_THREAD_ENV``), each worker gets one thread for the numeric
libraries where the user has not set their thread counts, so that 2 workers on 2 cores do not
run 4 OpenBLAS threads that spin against each other.

The references' cache of ``python -m quadsim.gap`` (:mod:`quadsim.gap.cache`, on by default)
never touches the user's own: ``QUADSIM_CACHE_DIR`` points at a temporary folder for the
whole run (subprocesses and pytest-xdist workers inherit it) and at a fresh one for every
test (no test reads an entry another test wrote).
"""

from __future__ import annotations

import os
import shutil
import tempfile

import pytest

_CACHE_ENV = "QUADSIM_CACHE_DIR"


def pytest_addoption(parser):
    parser.addini("xdist_workers", "worker processes of a run that does not name -n "
                  "(pytest-xdist installed; 0: serial)", default="0")
    parser.addini("xdist_dist", "--dist mode of such a run", default="load")


def pytest_configure(config):
    # the references' cache: never the user's (module doc); removed at the end
    config._quadsim_cache = tempfile.mkdtemp(prefix="quadsim-test-cache-")
    os.environ[_CACHE_ENV] = config._quadsim_cache
    # without pytest-xdist the marks would be unknown marks
    config.addinivalue_line("markers", "xdist_group(name): run these tests on one worker "
                            "(pytest-xdist --dist loadgroup)")
    worker = getattr(config, "workerinput", None)
    if worker and worker.get("quadsim_dist") == "loadgroup":
        config.option.loadgroup = True      # read by the worker's collection (see below)


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
    """Apply the ini file's worker count and --dist mode before pytest-xdist reads them (this
    hook runs first: conftest hooks run before the plugin's of the same priority)."""
    if not config.pluginmanager.hasplugin("xdist") or hasattr(config, "workerinput"):
        return                              # no plugin, or inside a worker: as given
    option = config.option
    if option.numprocesses is not None or option.usepdb or option.collectonly:
        return                              # the command line decides
    workers = int(config.getini("xdist_workers"))
    if workers <= 0:
        return
    option.numprocesses = workers
    if option.dist == "no":
        option.dist = config.getini("xdist_dist")
    from quadsim.core.executor import SINGLE_THREAD_ENV

    for key, value in SINGLE_THREAD_ENV.items():    # inherited by the workers at their start
        os.environ.setdefault(key, value)


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    """Tell each worker the --dist mode: a worker parses the original command line again, so
    a mode set above is unknown to it, and only a worker that knows of loadgroup puts the
    group into its tests' ids (which is how the scheduler sees the groups)."""
    node.workerinput["quadsim_dist"] = node.config.option.dist


def pytest_unconfigure(config):
    folder = getattr(config, "_quadsim_cache", None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(autouse=True)
def _own_cache_dir(tmp_path_factory, monkeypatch):
    """Each test its own empty references' cache folder (module doc)."""
    monkeypatch.setenv(_CACHE_ENV, str(tmp_path_factory.mktemp("quadsim-cache")))
