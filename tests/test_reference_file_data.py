"""The crazyflie21 set's shipped references are current (quadsim.gap.reffile, "Staleness"):
judged against them (no ``--reference``), the 26 mixed Crazyflie flights get the verdicts,
probabilities (to 3 decimals) and leads a fresh calibration of the 20 nominal flights gives
(``--reference nominal/*.csv.gz``); the same with every log's rotor-speed columns cut,
against ``crazyflie21_commands.qref`` and against ``--reference cmd/*.csv.gz
--command-reference nominal/*.csv.gz``. Fails when the calibration's numbers changed and the
files were not written again: ``python scripts/write_crazyflie_reference.py``. Skipped
without the shared data (~90 s CPU)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from quadsim.gap.__main__ import main

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared/data/crazyflie21_brushless"


def _flights(tmp_path, name, judged, *extra):
    out = tmp_path / f"{name}.json"
    assert main(["--model", "crazyflie21", "--per-flight", *map(str, judged),
                 "--workers", "1", "--quiet", "--no-cache", "--json", str(out), *extra]) == 0
    result = json.loads(out.read_text())
    return result, [(Path(f["file"]).name, f["verdict"], f["outcome"],
                     None if f["probability"] is None else round(f["probability"], 3),
                     (f.get("posterior") or [{}])[0].get("name")) for f in result["flights"]]


@pytest.mark.skipif(not (DATA / "mixed").is_dir(), reason="shared data absent")
def test_shipped_reference_judges_mixed_as_a_fresh_calibration(tmp_path):
    mixed = sorted((DATA / "mixed").glob("flight_*.csv.gz"))
    shipped, by_file = _flights(tmp_path, "shipped", mixed)
    assert shipped["reference_file"]["shipped"] is True
    fresh, by_logs = _flights(tmp_path, "fresh", mixed, "--reference",
                              *map(str, sorted((DATA / "nominal").glob("flight_*.csv.gz"))))
    assert "reference_file" not in fresh
    assert len(by_file) == 26
    assert by_file == by_logs, ("the shipped reference is stale: python "
                                "scripts/write_crazyflie_reference.py")


def _cut_speeds():
    spec = importlib.util.spec_from_file_location(
        "write_crazyflie_reference", ROOT / "scripts" / "write_crazyflie_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.cut_speeds


@pytest.mark.skipif(not (DATA / "mixed").is_dir(), reason="shared data absent")
def test_shipped_commands_reference_judges_command_only_mixed_as_the_logs(tmp_path):
    """Command-only mixed flights: against the shipped commands file (chosen by default) as
    against the command-only nominal flights with the originals as --command-reference."""
    cut = _cut_speeds()
    (tmp_path / "cmd").mkdir()
    nominal = sorted((DATA / "nominal").glob("flight_*.csv.gz"))
    mixed = sorted((DATA / "mixed").glob("flight_*.csv.gz"))
    for f in [*nominal, *mixed]:
        cut(f, tmp_path / "cmd" / f.name)
    judged = [tmp_path / "cmd" / f.name for f in mixed]
    shipped, by_file = _flights(tmp_path, "shipped", judged)
    assert shipped["reference_file"]["file"] == "crazyflie21_commands.qref"
    fresh, by_logs = _flights(tmp_path, "fresh", judged, "--reference",
                              *[str(tmp_path / "cmd" / f.name) for f in nominal],
                              "--command-reference", *map(str, nominal))
    assert len(by_file) == 26 and "reference_file" not in fresh
    assert by_file == by_logs, ("the shipped commands reference is stale: python "
                                "scripts/write_crazyflie_reference.py")
