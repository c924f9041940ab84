"""The harness's tests run serially by default (``-n 2`` for two pytest-xdist workers);
the repository's ``[tool.pytest.ini_options]`` keys that ``tests/conftest.py`` reads are
declared here too, so that a run of ``benchmarks/tests`` alone does not warn about them."""

from __future__ import annotations


def pytest_addoption(parser):
    parser.addini("xdist_workers", "read by tests/conftest.py (the package's suite)", default="0")
    parser.addini("xdist_dist", "read by tests/conftest.py (the package's suite)", default="load")


def pytest_configure(config):
    config.addinivalue_line("markers", "xdist_group(name): run these tests on one worker "
                            "(pytest-xdist --dist loadgroup)")
