"""``scripts/command_only_check.py`` as a newcomer types it (README, docs/logs.md): its
``--json OUT`` value was taken for the data folder (its own argument filter kept every word
not starting with ``--``), ``--help`` ran the check, and a folder without the flights ended
in a traceback from the command model's fit on zero logs."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "command_only_check.py"


def _script():
    spec = importlib.util.spec_from_file_location("command_only_check", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_folder_without_the_flights_is_one_line_and_exit_2(tmp_path, capsys):
    out = tmp_path / "out.json"
    assert _script().main([str(tmp_path), "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {tmp_path}: crazyflie21_brushless/nominal/*.csv.gz: no flights "
                   "found (give the shared data folder as DATA_DIR)"]
    assert not out.exists()


def test_the_json_value_is_not_the_data_folder(tmp_path, monkeypatch, capsys):
    module = _script()
    monkeypatch.setattr(module, "DEFAULT_DATA", tmp_path / "data")
    assert module.main(["--json", str(tmp_path / "out.json")]) == 2
    assert f"error: {tmp_path / 'data'}: crazyflie21_brushless/nominal" in capsys.readouterr().err


def test_help_describes_and_runs_nothing(capsys):
    with pytest.raises(SystemExit) as stop:
        _script().main(["--help"])
    assert stop.value.code == 0
    assert "DATA_DIR" in capsys.readouterr().out
