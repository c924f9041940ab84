"""``--reference-cache``: the per-flight mode's reference stage kept between runs
(:class:`quadsim.gap.calibrate.Calibrated`, :func:`quadsim.gap.calibrate.reference_key`,
:class:`quadsim.gap.__main__.ReferenceCache`)."""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np
import pytest

from quadsim.effects.rotor_drag import RotorDrag
from quadsim.gap.__main__ import ReferenceCache, main
from quadsim.gap.calibrate import Calibrated, reference_key
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import load_params


def _log(shift=0.0, name="a.csv"):
    t = np.arange(50) * 0.01
    return FlightLog(t=t, position=np.zeros((50, 3)) + shift, quat=np.tile([1.0, 0, 0, 0], (50, 1)),
                     path=Path(name))


def test_key_follows_every_input():
    params = load_params("crazyflie21")
    key = reference_key([_log(), _log(name="b.csv")], params, window_s=0.1)
    assert len(key) == 64 and key == reference_key([_log(), _log(name="b.csv")], params,
                                                   window_s=0.1)
    others = [reference_key([_log(1e-12), _log(name="b.csv")], params, window_s=0.1),
              reference_key([_log(), _log(name="c.csv")], params, window_s=0.1),
              reference_key([_log(name="b.csv"), _log()], params, window_s=0.1),
              reference_key([_log(), _log(name="b.csv")], params, window_s=0.12),
              reference_key([_log(), _log(name="b.csv")], params, window_s=0.1,
                            effects=["mass_offset"]),
              reference_key([_log(), _log(name="b.csv")], load_params("nanodrone_cf21bl"),
                            window_s=0.1),
              reference_key([_log(), _log(name="b.csv")], params, window_s=0.1,
                            base=(RotorDrag(coefficient=1.9e-6),))]   # an --effects-file
    assert len({key, *others}) == 1 + len(others)


def test_store_round_trip_and_bad_files(tmp_path, capsys):
    store = ReferenceCache(tmp_path / "cache")
    kept = Calibrated("k" * 64, None, {"ok": True}, ("note",), 3)
    assert store.get(kept.key) is None                   # nothing kept yet: no warning
    store.put(kept)
    assert store.get(kept.key) == kept
    (tmp_path / "cache" / f"{'j' * 64}.pkl").write_bytes(b"not a pickle")
    assert store.get("j" * 64) is None
    assert "not a readable reference calibration: computed again" in capsys.readouterr().err
    (tmp_path / "cache" / f"{'m' * 64}.pkl").write_bytes(
        (tmp_path / "cache" / f"{kept.key}.pkl").read_bytes())     # another key's entry
    assert store.get("m" * 64) is None


def test_flag_needs_per_flight(tmp_path, capsys):
    data = tmp_path / "x.csv"
    data.write_text("t\n0\n")
    assert main(["--model", "crazyflie21", str(data), "--reference-cache", str(tmp_path)]) == 2
    assert "--reference-cache: only used with --per-flight" in capsys.readouterr().err


DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "crazyflie21_brushless"
if not DATA.exists():  # worktrees live one level deeper than the main checkout
    DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "crazyflie21_brushless"


@pytest.mark.skipif(not (DATA / "nominal").exists(), reason="shared real data absent")
def test_second_run_reads_the_calibration(tmp_path, monkeypatch):
    """Real flights: the second run with the same references reads the kept calibration
    (calibrating again would fail here) and writes the same JSON, byte for byte."""
    common = ["--model", "crazyflie21", "--per-flight", str(DATA / "mixed" / "flight_100.csv.gz"),
              "--reference", *(str(DATA / "nominal" / f"flight_0{k}.csv.gz") for k in range(3)),
              "--workers", "1", "--quiet", "--reference-cache", str(tmp_path / "cache")]
    assert main([*common, "--json", str(tmp_path / "first.json")]) == 0
    assert len(list((tmp_path / "cache").glob("*.pkl"))) == 1

    def refuse(*args, **kwargs):
        raise AssertionError("calibrated again")

    monkeypatch.setattr(importlib.import_module("quadsim.gap.diagnose"), "calibrate", refuse)
    assert main([*common, "--json", str(tmp_path / "second.json")]) == 0
    assert (tmp_path / "first.json").read_bytes() == (tmp_path / "second.json").read_bytes()
