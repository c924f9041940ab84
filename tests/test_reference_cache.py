"""The references' cache of ``python -m quadsim.gap`` (:mod:`quadsim.gap.cache`): the
references' loading, calibration and self-check kept on disk between runs, keyed by their
files, the model, the options and quadsim's code; the same JSON whether read or computed."""

from __future__ import annotations

import gzip
import importlib
import json
import os
import pickle
from pathlib import Path

import pytest

from quadsim.effects.rotor_drag import RotorDrag
from quadsim.gap import cache as gap_cache
from quadsim.gap.__main__ import main
from quadsim.gap.cache import PREFIX, Entry, ReferenceStore, cache_dir, entry_key
from quadsim.logs.flightlog import write_log
from quadsim.vehicle.params import load_params

from _helpers import drag_flights


def _files(tmp_path, *texts):
    out = []
    for k, text in enumerate(texts):
        out.append(tmp_path / f"r{k}.csv")
        out[-1].write_bytes(text)
    return out


def test_key_follows_every_input(tmp_path, monkeypatch):
    params = load_params("crazyflie21")
    a, b, c = _files(tmp_path, b"t\n0\n", b"t\n1\n", b"t\n2\n")
    key = entry_key([a, b], params, window_s=0.1)
    assert len(key) == 64 and key == entry_key([a, b], params, window_s=0.1)
    others = [entry_key([a, c], params, window_s=0.1),
              entry_key([b, a], params, window_s=0.1),              # the order
              entry_key([a, b], params, window_s=0.12),
              entry_key([a, b], params, window_s=0.1, effects=["mass_offset"]),
              entry_key([a, b], load_params("nanodrone_cf21bl"), window_s=0.1),
              entry_key([a, b], params, window_s=0.1,
                        base=(RotorDrag(coefficient=1.9e-6),)),     # an --effects-file
              entry_key([a, b], params, window_s=0.1, command_references=[c])]
    monkeypatch.setenv("QUADSIM_THREADS", "2")
    others.append(entry_key([a, b], params, window_s=0.1))
    monkeypatch.delenv("QUADSIM_THREADS")
    b.write_bytes(b"t\n1.0\n")                                        # one byte more
    others.append(entry_key([a, b], params, window_s=0.1))
    b.write_bytes(b"t\n1\n")
    assert entry_key([a, b], params, window_s=0.1) == key
    moved = tmp_path / "sub"
    moved.mkdir()
    (moved / "r0.csv").write_bytes(a.read_bytes())                   # the same bytes, renamed
    others.append(entry_key([moved / "r0.csv", b], params, window_s=0.1))
    assert len({key, *others}) == 1 + len(others)


def test_key_follows_the_code(tmp_path, monkeypatch):
    """quadsim's sources are in the key: another code version, another key."""
    params = load_params("crazyflie21")
    (a,) = _files(tmp_path, b"t\n0\n")
    key = entry_key([a], params, window_s=0.1)
    monkeypatch.setattr(importlib.import_module("quadsim.gap.calibrate"), "code_version",
                        lambda: "0" * 64)
    assert entry_key([a], params, window_s=0.1) != key


def test_cache_dir_order(tmp_path, monkeypatch):
    monkeypatch.setenv("QUADSIM_CACHE_DIR", str(tmp_path / "env"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir(tmp_path / "flag") == tmp_path / "flag"
    assert cache_dir() == tmp_path / "env"
    monkeypatch.setenv("QUADSIM_CACHE_DIR", "")
    assert cache_dir() == tmp_path / "xdg" / "quadsim"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert cache_dir() == Path("~/.cache/quadsim").expanduser()


def test_store_round_trip_and_bad_files(tmp_path, capsys):
    store = ReferenceStore(tmp_path / "cache")
    kept = Entry("k" * 64, {"stage": 1}, ("found",), ("note",), 3)
    assert store.get(kept.key) is None                   # nothing kept yet: no warning
    assert capsys.readouterr().err == ""
    assert store.put(kept) == tmp_path / "cache" / f"{PREFIX}{'k' * 64}.pkl"
    assert store.get(kept.key) == kept
    assert [p.name for p in (tmp_path / "cache").iterdir()] == [f"{PREFIX}{'k' * 64}.pkl"]
    store.path("j" * 64).write_bytes(b"not a pickle")
    assert store.get("j" * 64) is None
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: ") and "not a readable" in err[0]
    store.path("m" * 64).write_bytes(store.path(kept.key).read_bytes())  # another key's entry
    assert store.get("m" * 64) is None
    store.path("p" * 64).write_bytes(pickle.dumps({"not": "an entry"}))
    assert store.get("p" * 64) is None


def test_unwritable_folder_warns_once(tmp_path, capsys):
    (tmp_path / "file").write_text("")
    store = ReferenceStore(tmp_path / "file" / "cache")   # below a file: cannot be made
    assert store.put(Entry("k" * 64, None, (), (), 0)) is None
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: ") and "not written" in err[0]


def test_entries_are_bounded(tmp_path, monkeypatch):
    """Beyond MAX_ENTRIES (or MAX_BYTES) the oldest entries go, the one just written never;
    files that are not entries are left alone."""
    monkeypatch.setattr(gap_cache, "MAX_ENTRIES", 3)
    store = ReferenceStore(tmp_path)
    (tmp_path / "other.pkl").write_bytes(b"x")
    for k in range(5):
        path = store.put(Entry(f"{k}" * 64, None, (), (), 0))
        os.utime(path, (1e9 + k, 1e9 + k))
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["other.pkl"] + [f"{PREFIX}{str(k) * 64}.pkl" for k in (2, 3, 4)])
    size = store.path("4" * 64).stat().st_size
    monkeypatch.setattr(gap_cache, "MAX_BYTES", 2 * size)
    os.utime(store.path("2" * 64), (2e9, 2e9))             # read lately: the newest
    store.put(Entry("5" * 64, None, (), (), 0))             # written now, yet older mtime
    os.utime(store.path("5" * 64), (1e9, 1e9))
    store.prune(keep=store.path("5" * 64))
    assert sorted(p.name for p in tmp_path.glob(f"{PREFIX}*")) == [
        f"{PREFIX}{'2' * 64}.pkl", f"{PREFIX}{'5' * 64}.pkl"]


def test_flag_checks(tmp_path, capsys):
    data, other = tmp_path / "x.csv", tmp_path / "y.csv"
    data.write_text("t\n0\n")
    other.write_text("t\n1\n")
    assert main(["--model", "crazyflie21", str(data), "--cache-dir", str(tmp_path)]) == 2
    assert "--cache-dir: only used with --per-flight" in capsys.readouterr().err
    assert main(["--model", "crazyflie21", "--per-flight", str(data), "--reference", str(other),
                 "--cache-dir", str(tmp_path), "--no-cache"]) == 2
    assert "--cache-dir: not used with --no-cache" in capsys.readouterr().err
    assert main(["--model", "crazyflie21", "--per-flight", str(data), "--cache-dir",
                 str(tmp_path), "--reference-cache", str(tmp_path)]) == 2
    assert "the older name of --cache-dir" in capsys.readouterr().err
    out = tmp_path / "out.json"
    assert main(["--model", "crazyflie21", "--per-flight", str(data), "--reference", str(other),
                 "--cache-dir", str(data), "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {data}: --cache-dir: not a folder"]
    assert not out.exists() and data.read_text() == "t\n0\n"


@pytest.fixture(scope="module")
def flight_files(tmp_path_factory):
    """Three short synthetic flights with a rotor drag (two references, one judged)."""
    return drag_flights(tmp_path_factory.mktemp("flights"))


def _run(tmp_path, files, name, *extra, refs=None):
    refs = [str(p) for p in (refs or files[:2])]
    out = tmp_path / f"{name}.json"
    assert main(["--model", "crazyflie21", "--per-flight", str(files[2]), "--reference", *refs,
                 "--effects", "mass_offset", "--workers", "1", "--json", str(out),
                 *extra]) == 0
    return out.read_bytes()


def test_cached_json_equals_uncached(flight_files, tmp_path, monkeypatch, capsys):
    """The default cache (QUADSIM_CACHE_DIR): the first run writes one entry, the second
    reads it (calibrating again would fail) and writes the same JSON as --no-cache, byte for
    byte; each says so in one stderr line. A changed reference byte misses; a corrupt entry
    warns once and is computed again; --no-cache writes nothing."""
    folder = Path(os.environ["QUADSIM_CACHE_DIR"])
    plain = _run(tmp_path, flight_files, "plain", "--no-cache", "--quiet")
    assert not folder.exists() or not any(folder.iterdir())
    first = _run(tmp_path, flight_files, "first")
    assert "calibration and self-check kept in the cache" in capsys.readouterr().err
    entries = list(folder.glob(f"{PREFIX}*.pkl"))
    assert len(entries) == 1
    diagnose = importlib.import_module("quadsim.gap.diagnose")
    calibrate, prepare = diagnose.calibrate, diagnose.prepare

    def refuse(*args, **kwargs):
        raise AssertionError("calibrated again")

    def only_one(logs, *args, **kwargs):        # only the judged flight is prepared
        assert len(logs) == 1, "the references prepared again"
        return prepare(logs, *args, **kwargs)

    monkeypatch.setattr(diagnose, "calibrate", refuse)
    monkeypatch.setattr(diagnose, "prepare", only_one)
    second = _run(tmp_path, flight_files, "second")
    err = capsys.readouterr().err
    assert "calibration and self-check read from the cache" in err
    assert plain == first == second
    monkeypatch.setattr(diagnose, "calibrate", calibrate)
    monkeypatch.setattr(diagnose, "prepare", prepare)

    # one byte of a reference changed (a copy): another key, computed and written
    changed = tmp_path / "f1.csv.gz"
    changed.write_bytes(gzip.compress(gzip.decompress(flight_files[1].read_bytes()) + b"\n"))
    _run(tmp_path, flight_files, "changed", refs=[flight_files[0], changed])
    assert "kept in the cache" in capsys.readouterr().err
    assert len(list(folder.glob(f"{PREFIX}*.pkl"))) == 2

    # a corrupt entry: one warning, computed again, written anew, the same answers
    entries[0].write_bytes(b"\x80\x04 broken")
    again = _run(tmp_path, flight_files, "again")
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning")]
    assert len(err) == 1 and "not a readable cache entry" in err[0], err
    assert again == plain
    assert pickle.loads(entries[0].read_bytes()).key == entries[0].stem[len(PREFIX):]

    # --no-cache: nothing read or written; --cache-dir: there
    before = sorted(folder.iterdir())
    _run(tmp_path, flight_files, "none", "--no-cache")
    assert "cache" not in capsys.readouterr().err and sorted(folder.iterdir()) == before
    assert _run(tmp_path, flight_files, "dir", "--cache-dir", str(tmp_path / "mine")) == plain
    assert len(list((tmp_path / "mine").glob(f"{PREFIX}*.pkl"))) == 1


def test_command_only_flight_on_a_hit(flight_files, tmp_path, monkeypatch, capsys):
    """A judged log without rotor speeds (synthesised from the references' commands): it is
    judged (the references judged alike, their speeds cut and synthesised: not refused for
    the rotor channel it lacks); on a hit the references are loaded for that, their stage
    still read (not calibrated again), and the JSON is --no-cache's; the references' stage
    as command-only is keyed apart from theirs with speeds."""
    import dataclasses

    from quadsim.logs.flightlog import load_log

    log = load_log(flight_files[2])
    assert log.rotor_speed is not None and log.rotor_command is not None
    only = tmp_path / "commands.csv.gz"
    write_log(only, dataclasses.replace(log, rotor_speed=None))
    files = [flight_files[0], flight_files[1], only]
    plain = _run(tmp_path, files, "plain", "--no-cache", "--quiet")
    judged = json.loads(plain)["flights"][0]
    assert judged["outcome"] != "refused", judged["answer"]
    with_speeds = _run(tmp_path, flight_files, "speeds")       # the same references' stage
    assert _run(tmp_path, files, "first") == plain
    err = capsys.readouterr().err
    assert "kept in the cache" in err and "rotor speeds synthesised" in err
    assert "the references are judged alike" in err
    assert len(list(Path(os.environ["QUADSIM_CACHE_DIR"]).glob(f"{PREFIX}*.pkl"))) >= 2
    assert _run(tmp_path, flight_files, "speeds again") == with_speeds
    diagnose = importlib.import_module("quadsim.gap.diagnose")

    def refuse(*args, **kwargs):
        raise AssertionError("calibrated again")

    monkeypatch.setattr(diagnose, "calibrate", refuse)
    assert _run(tmp_path, files, "second") == plain
    assert "read from the cache" in capsys.readouterr().err


def test_older_flag_is_read_as_cache_dir(flight_files, tmp_path, capsys):
    _run(tmp_path, flight_files, "old", "--quiet", "--reference-cache", str(tmp_path / "old"))
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["warning: --reference-cache: now --cache-dir (the cache is on by default; "
                   "--no-cache turns it off): read as --cache-dir"]
    assert len(list((tmp_path / "old").glob(f"{PREFIX}*.pkl"))) == 1


def test_unwritable_cache_leaves_the_run(flight_files, tmp_path, capsys):
    (tmp_path / "file").write_text("")
    out = _run(tmp_path, flight_files, "x", "--quiet", "--cache-dir",
               str(tmp_path / "file" / "sub"))
    assert out == _run(tmp_path, flight_files, "y", "--quiet", "--no-cache")
    warned = [x for x in capsys.readouterr().err.splitlines() if x.startswith("warning")]
    assert len(warned) == 1 and "not written" in warned[0]


DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "crazyflie21_brushless"
if not DATA.exists():  # worktrees live one level deeper than the main checkout
    DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "crazyflie21_brushless"


@pytest.mark.skipif(not (DATA / "nominal").exists(), reason="shared real data absent")
def test_second_run_reads_the_calibration(tmp_path, monkeypatch):
    """Real flights: the second run with the same references reads the kept calibration
    (calibrating again would fail here) and writes the same JSON, byte for byte."""
    common = ["--model", "crazyflie21", "--per-flight", str(DATA / "mixed" / "flight_100.csv.gz"),
              "--reference", *(str(DATA / "nominal" / f"flight_0{k}.csv.gz") for k in range(3)),
              "--workers", "1", "--quiet", "--cache-dir", str(tmp_path / "cache")]
    assert main([*common, "--json", str(tmp_path / "first.json")]) == 0
    assert len(list((tmp_path / "cache").glob(f"{PREFIX}*.pkl"))) == 1

    def refuse(*args, **kwargs):
        raise AssertionError("calibrated again")

    monkeypatch.setattr(importlib.import_module("quadsim.gap.diagnose"), "calibrate", refuse)
    assert main([*common, "--json", str(tmp_path / "second.json")]) == 0
    assert (tmp_path / "first.json").read_bytes() == (tmp_path / "second.json").read_bytes()
