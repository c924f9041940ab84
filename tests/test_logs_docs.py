"""docs/logs.md's worked example, run as written: every command of its bash block runs from
the repository root (outputs in a temporary $OUT) and exits 0, and the page's numbers are
what the commands wrote. Skipped without ``../shared/data``."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "logs.md"
DATA = ROOT.parent / "shared" / "data" / "px4_ulog" / "sample_px4_events.ulg"


def page_commands() -> list[str]:
    blocks = re.findall(r"```bash\n(.*?)```", PAGE.read_text(encoding="utf-8"), flags=re.DOTALL)
    return [line for block in blocks for line in block.splitlines() if line.strip()]


def test_page_commands_are_quadsim_commands_or_setup():
    commands = page_commands()
    assert sum(c.startswith("python -m quadsim.") for c in commands) == 5
    for c in commands:
        assert c.startswith(("python -m quadsim.", "D=", "OUT=", "mkdir ")), c


@pytest.mark.skipif(not DATA.exists(), reason="../shared/data is absent")
def test_worked_example_runs_as_written(tmp_path):
    env = {**os.environ, "OUT": str(tmp_path), "PYTHONPATH": str(ROOT)}
    *commands, gap = [c.replace("python -m", f"{sys.executable} -m", 1)
                      for c in page_commands()]
    run = subprocess.run(["bash", "-c", "set -e\n" + "\n".join(commands)], cwd=ROOT,
                         env=env, capture_output=True, text=True, timeout=900, check=False)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "wrote" in run.stdout and "620 samples, 30.90 s, 4 rotors" in run.stdout
    b = tomllib.loads((tmp_path / "px4.toml").read_text())["rotors"]["thrust_factor"]["value"]
    assert b == pytest.approx(2.135e-5, rel=0.005)
    # the page's gap is judged in the band of the 10 Hz commands (issue 47), as the page says
    judged = subprocess.run(["bash", "-c", gap], cwd=ROOT, env=env, capture_output=True,
                            text=True, timeout=600, check=False)
    assert judged.returncode == 0, judged.stderr[-2000:]
    result = json.loads((tmp_path / "px4_gap.json").read_text())
    assert result["verdict"]["outcome"] == "unexplained"
    assert "Fx 0.033 N (7.9x the noise's)" in result["verdict"]["answer"]
    assert any("judged below 2.5 Hz: motor commands logged at 10 Hz" in n
               for n in result["notes"])
    # the set the page says does not describe the vehicle: refused by the force balance
    said = "model 'px4_sitl_iris' does not describe the logged vehicle"
    refused = subprocess.run(
        [sys.executable, "-m", "quadsim.gap", "--model", "px4_sitl_iris",
         str(tmp_path / "px4_a.csv.gz"), "--holdout", str(tmp_path / "px4_b.csv.gz")],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert refused.returncode == 2 and said in refused.stderr and "2.05x" in refused.stderr
