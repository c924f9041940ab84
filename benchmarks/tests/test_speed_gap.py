"""benchmarks/speed_gap.py's helpers on a small written log (numbers, not timing)."""

import gzip
import os

import numpy as np

from benchmarks import speed_gap


def _log(path, n=101, dt=0.01):
    rows = [f"{k * dt + 2.0!r},{np.sin(k):.6f}" for k in range(n)]
    with gzip.open(path, "wt") as handle:
        handle.write("\n".join(["t,x", *rows]) + "\n")
    return path


def test_duration_and_cut(tmp_path):
    log = _log(tmp_path / "f.csv.gz")
    assert abs(speed_gap.log_duration(log) - 1.0) < 1e-12          # 100 steps of 10 ms
    cut = speed_gap.cut_log(log, 0.5, tmp_path / "half.csv.gz")
    assert abs(speed_gap.log_duration(cut) - 0.5) < 1e-12
    with gzip.open(cut, "rt") as handle:
        assert len(handle.read().split()) == 1 + 51                  # header, t <= 2.5 s


def test_line_fit_recovers_a_line():
    runs = [speed_gap.Run(f"{m}", 1, m, 20.0 + 3.0 * m, 1.0, "") for m in (0.5, 1.0, 2.0)]
    fixed, per_minute = speed_gap.line_fit(runs)
    assert abs(fixed - 20.0) < 1e-9 and abs(per_minute - 3.0) < 1e-9
    assert runs[1].cpu_per_minute == 23.0


def test_against_needs_a_checkout(tmp_path, capsys):
    assert speed_gap.main(["--against", str(tmp_path)]) == 2
    assert "not a checkout of this repository" in capsys.readouterr().err
    assert speed_gap.main(["--against", str(speed_gap.ROOT), "--rounds", "0"]) == 2


def test_each_run_its_own_cache(tmp_path, capsys):
    """Every timed command gets the cache folder it is handed (cold: a fresh one), with the
    checkout first on the path; --warm is refused with --parts."""
    env = speed_gap._env(tmp_path / "co", tmp_path / "cache")
    assert env["QUADSIM_CACHE_DIR"] == str(tmp_path / "cache")
    assert env["PYTHONPATH"].split(os.pathsep)[0] == str(tmp_path / "co")
    assert speed_gap.main(["--warm", "--parts"]) == 2
    assert "--warm: not used with --parts" in capsys.readouterr().err


def test_long_skips_without_the_nano_drone_runs(tmp_path, capsys):
    """--long on a data folder without the nano-drone benchmark: one skipped line, exit 0;
    its runs are the validation runs (run4), never a test run, shortest first."""
    assert speed_gap.main(["--long", "--data", str(tmp_path)]) == 0
    assert capsys.readouterr().out.startswith("skipped:")
    assert all(name.endswith("_run4") for name in speed_gap.NANO_RUNS)
    assert speed_gap.NANO_RUNS[0].startswith("square") and speed_gap.NANO_MODEL.is_file()


def test_weighing_parts_count_the_nested_parts_inside_the_weighing_only(monkeypatch):
    """--parts: a part outside the evidence and the diagnosis (the rotor speeds read at a
    delay, the effects' loads, the rotor channel) counts only inside another part (the
    calibration reads them too); "EffectBase+" stands for every effect class's own loads;
    the weighings' own time is "the rest of the weighing"."""
    import importlib

    from quadsim.effects.base import EffectBase
    from quadsim.gap import reference

    diagnose = importlib.import_module("quadsim.gap.diagnose")
    cli = importlib.import_module("quadsim.gap.__main__")
    importlib.import_module("quadsim.gap.fitting")

    def subclasses(cls):
        for sub in cls.__subclasses__():
            yield sub
            yield from subclasses(sub)

    # every attribute the timer wraps is put back after the test
    for module, cls, name, _ in speed_gap.PARTS:
        owner = importlib.import_module(module)
        owners = (list(subclasses(getattr(owner, cls[:-1]))) if cls and cls.endswith("+")
                  else [getattr(owner, cls) if cls else owner])
        for each in owners:
            kept = each.__dict__.get(name) if isinstance(each, type) else getattr(
                each, name, None)
            if kept is not None:
                monkeypatch.setattr(each, name, kept)
    t = np.arange(64) * 0.01
    x = np.sin(t)[:, None]

    def weigh(*args, **kwargs):             # one flight's weighing: one read at a delay
        return reference.read_later(t, x, 0.003)

    def main(argv):
        reference.read_later(t, x, 0.002)   # outside the weighing: not counted
        diagnose.weigh_flight()

    monkeypatch.setattr(diagnose, "weigh_flight", weigh)
    monkeypatch.setattr(cli, "main", main)
    spent = speed_gap.weighing_parts([])
    assert spent["rotor speeds read at a delay"][1] == 1
    assert spent["the rest of the weighing"][1] == 1
    wrapped = [cls for cls in subclasses(EffectBase) if "loads" in cls.__dict__
               and hasattr(cls.__dict__["loads"], "__wrapped__")]
    assert any(cls.__name__ == "RotorDrag" for cls in wrapped)
