"""The crazyflie21 set's shipped reference is current (quadsim.gap.reffile, "Staleness"):
judged against it (no ``--reference``), the 26 mixed Crazyflie flights get the verdicts,
probabilities (to 3 decimals) and leads a fresh calibration of the 20 nominal flights gives
(``--reference nominal/*.csv.gz``). Fails when the calibration's numbers changed and the
file was not written again: ``python scripts/write_crazyflie_reference.py``. Skipped
without the shared data (~60 s CPU)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from quadsim.gap.__main__ import main

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared/data/crazyflie21_brushless"


def _flights(tmp_path, name, *extra):
    out = tmp_path / f"{name}.json"
    assert main(["--model", "crazyflie21", "--per-flight",
                 *map(str, sorted((DATA / "mixed").glob("flight_*.csv.gz"))),
                 "--workers", "1", "--quiet", "--no-cache", "--json", str(out), *extra]) == 0
    result = json.loads(out.read_text())
    return result, [(Path(f["file"]).name, f["verdict"], f["outcome"],
                     None if f["probability"] is None else round(f["probability"], 3),
                     (f.get("posterior") or [{}])[0].get("name")) for f in result["flights"]]


@pytest.mark.skipif(not (DATA / "mixed").is_dir(), reason="shared data absent")
def test_shipped_reference_judges_mixed_as_a_fresh_calibration(tmp_path):
    shipped, by_file = _flights(tmp_path, "shipped")
    assert shipped["reference_file"]["shipped"] is True
    fresh, by_logs = _flights(tmp_path, "fresh", "--reference",
                              *map(str, sorted((DATA / "nominal").glob("flight_*.csv.gz"))))
    assert "reference_file" not in fresh
    assert len(by_file) == 26
    assert by_file == by_logs, ("the shipped reference is stale: python "
                                "scripts/write_crazyflie_reference.py")
