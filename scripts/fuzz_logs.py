"""Moved to benchmarks/fuzz_logs.py: ``python -m benchmarks.fuzz_logs`` from the repository root."""
import runpy
import sys
from pathlib import Path

print("warning: scripts/fuzz_logs.py moved to benchmarks/fuzz_logs.py: run "
      "python -m benchmarks.fuzz_logs from the repository root", file=sys.stderr)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
runpy.run_module("benchmarks.fuzz_logs", run_name="__main__", alter_sys=True)
