"""The benchmark harness's tests: ``python -m pytest benchmarks/tests`` from the repository
root (each simulator source's tests skip where that simulator is not installed)."""
