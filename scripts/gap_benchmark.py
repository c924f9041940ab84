"""Moved to benchmarks/gap_benchmark.py: ``python -m benchmarks.gap_benchmark`` from the repository
root."""
import runpy
import sys
from pathlib import Path

print("warning: scripts/gap_benchmark.py moved to benchmarks/gap_benchmark.py: run "
      "python -m benchmarks.gap_benchmark from the repository root", file=sys.stderr)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
runpy.run_module("benchmarks.gap_benchmark", run_name="__main__", alter_sys=True)
