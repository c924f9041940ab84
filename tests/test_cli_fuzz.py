"""CLI fuzz test: seeded random argument lists and corrupted files over gap, fly,
view, openloop, build_mjcf and identify. Every case must end with exit status 0 or 2 and
never a traceback (an exception escaping ``main`` fails the case, with its argv).

The CLIs' ``main(argv)`` run in-process (argparse's own errors are ``SystemExit(2)``); two
cases also run as subprocesses to check the real entry points. Values and files are drawn
from pools of plausible, wrong-unit, out-of-range, non-numeric and corrupted inputs; the
pools keep valid runs short (durations <= 0.3 s, 1 s logs), so 200 cases cost ~15 s on a
quiet 2-core machine.
"""

from __future__ import annotations

import contextlib
import gzip
import io
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from quadsim.logs.flightlog import load_log, write_log
from quadsim.logs.generate import generate_flight
from quadsim.vehicle.params import MODELS_DIR, load_params

REPO = Path(__file__).resolve().parents[1]
#: cases per command (200 in all; the commands whose valid runs simulate get fewer)
CASES = {"gap": 50, "fly": 25, "view": 10, "openloop": 15, "build_mjcf": 40, "identify": 60}
SEED = 14

NUMBERS = ["-1", "0", "-0.1", "nan", "inf", "-inf", "1e308", "abc", "", "0.2", "1", "1e-9"]


#: one xdist worker runs this module's tests (pytest-xdist --dist loadgroup): its module-scoped
#: fixtures are built once, not once per worker
pytestmark = pytest.mark.xdist_group("test_cli_fuzz")


@pytest.fixture(scope="module")
def pool(tmp_path_factory):
    """Files for the fuzzer: good logs, corrupted logs, bad models, outputs."""
    root = tmp_path_factory.mktemp("fuzz")
    params = load_params("crazyflie21")
    good = []
    for seed in range(3):
        log, _ = generate_flight(params, "figure8", None, None, seed, duration=1.0, speed=1.0)
        good.append(write_log(root / f"good{seed}.csv.gz", log))
    plain = write_log(root / "plain.csv", load_log(good[0]))
    text = plain.read_text().splitlines()
    header, rows = text[0], text[1:]
    bad = {}

    def put(name, content):
        path = root / name
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
        bad[name] = path

    put("empty.csv", "")
    put("header_only.csv", header + "\n")
    put("two_rows.csv", "\n".join([header, *rows[:2]]) + "\n")
    put("garbage.csv.gz", bytes(range(256)) * 4)
    put("truncated.csv.gz", good[0].read_bytes()[: len(good[0].read_bytes()) // 2])
    put("text.csv", "hello world\n")
    put("no_qz.csv", "\n".join(",".join(c for i, c in enumerate(r.split(","))
                                         if i != header.split(",").index("qz"))
                                for r in [header, *rows]) + "\n")
    put("abc_cell.csv", "\n".join([header, *rows[:50], rows[50].replace(",", ",abc,", 1)
                                   .replace(",abc,", ",abc", 1), *rows[51:]]) + "\n")
    cols = header.split(",")
    matrix = np.array([[float(c) if c else np.nan for c in r.split(",")] for r in rows])

    def put_matrix(name, m, head=header):
        lines = [head] + [",".join("" if not np.isfinite(v) else f"{v:.10g}" for v in r)
                          for r in m]
        put(name, "\n".join(lines) + "\n")

    m = matrix.copy()
    m[100:150, cols.index("rotor_2")] = np.nan
    put_matrix("nan_run.csv", m)
    m = matrix.copy()
    m[::2, cols.index("rotor_1")] = np.nan
    put_matrix("nan_half.csv", m)
    m = matrix.copy()
    m[:, cols.index("t")] = m[::-1, cols.index("t")]
    put_matrix("time_reversed.csv", m)
    m = matrix.copy()
    for c in ("wx", "wy", "wz"):
        m[:, cols.index(c)] = np.degrees(m[:, cols.index(c)])
    put_matrix("deg_gyro.csv", m)
    m = matrix.copy()
    for c in ("ax", "ay", "az"):
        m[:, cols.index(c)] /= 9.81
    put_matrix("accel_g.csv", m)
    put_matrix("dup_header.csv", matrix[:, :-1], ",".join(cols[:-2] + [cols[-3]]))
    put("gz_of_garbage.csv.gz", gzip.compress(b"\x00\xff" * 100, mtime=0))
    logs = [*map(str, good), str(plain), *map(str, bad.values()), str(root / "missing.csv"),
            str(root)]
    cf = (MODELS_DIR / "crazyflie21.toml").read_text()
    models = {"heavy.toml": cf.replace("value = 0.037,", "value = 37.0,"),
              "broken.toml": "schema = \n[body",
              "empty.toml": "",
              "negative.toml": cf.replace("value = 0.037,", "value = -0.037,"),
              "no_rotors.toml": cf.split("[[rotor]]")[0],
              "rpm.toml": cf.replace("value = 2750.0,", "value = 26304.0,")}
    model_paths = []
    for name, content in models.items():
        (root / name).write_text(content)
        model_paths.append(str(root / name))
    blocker = root / "blocker"
    blocker.write_text("x")
    omega = np.linspace(0, 900, 12)           # synthetic sweep: F = 1e-5 w^2, Q = 1.5e-7 w^2
    stand_good = root / "sweep_10inch.csv"
    stand_good.write_text("esc_us,torque_Nm,thrust_N,speed_rpm\n" + "".join(
        f"{1100 + 50 * i},{1.5e-7 * w ** 2:.6g},{1e-5 * w ** 2:.6g},{w * 60 / (2 * np.pi):.6g}\n"
        for i, w in enumerate(omega)))
    stand_bad = root / "stand.csv"
    stand_bad.write_text("esc_us,torque_Nm,thrust_N,speed_rpm\n1100,abc,0,0\n")
    empty_dir = root / "emptycad"
    empty_dir.mkdir()
    out = root / "out"
    out.mkdir()  # outputs never create folders
    return {
        "logs": logs,
        "good": [str(p) for p in good],
        "models": ["crazyflie21", "physical", "report", "nosuchmodel", *model_paths],
        "cad": [str(REPO / "cad"), str(empty_dir), str(blocker), str(root / "nocad")],
        "stand": [str(stand_good), str(stand_bad), str(blocker), str(root / "nostand.csv")],
        "out": lambda ext: [str(out / f"o{ext}"), str(out / "o.txt"), str(root),
                            str(blocker / f"x{ext}"), "/proc/x" + ext],
    }


def _pick(rng, values):
    return values[int(rng.integers(len(values)))]


def _maybe(rng, p=0.5):
    return rng.random() < p


BAD = 0.12  # chance that any one argument is drawn from the bad pool


def _either(rng, good, bad):
    """Mostly a valid value, sometimes (``BAD``) a wrong one."""
    return _pick(rng, bad) if _maybe(rng, BAD) else _pick(rng, good)


def _gap(rng, pool):
    argv = ["--model", _either(rng, ["crazyflie21"], pool["models"])]
    logs = list(rng.permutation(pool["good"]))
    if _maybe(rng, 0.4):
        logs[int(rng.integers(3))] = _pick(rng, pool["logs"])
    argv += [str(x) for x in logs]
    if _maybe(rng, 0.15):
        argv += ["--holdout", _pick(rng, pool["logs"])]
    if _maybe(rng, 0.1):
        argv += ["--per-flight"]
        if _maybe(rng, 0.8):
            argv += ["--reference", *pool["good"][:2]]
    if _maybe(rng, 0.3):
        argv += ["--window", _either(rng, ["0.05", "0.1"], NUMBERS)]
    if _maybe(rng, 0.3):
        argv += ["--json", _either(rng, pool["out"](".json")[:1], pool["out"](".json"))]
    argv += ["--effects", _either(rng, ["mass_offset", "thrust_mismatch"], ["nosuch", "-"]),
             "--quiet"]
    return argv


def _fly(rng, pool):
    argv = ["--model", _either(rng, ["crazyflie21", "physical"], pool["models"]),
            "--path", _either(rng, ["hover", "figure8", "steps"], ["circle", ""])]
    for flag, good, bad in (("--speed", ["0.5", "1"], NUMBERS + ["30"]),
                            ("--size", ["0.5", "1"], NUMBERS),
                            ("--height", ["1", "2"], NUMBERS),
                            ("--control-period", ["0.005", "0.01"], ["-1", "0", "nan", "1"]),
                            ("--sensor-rate", ["100", "250"], ["-5", "0", "1e9", "x"]),
                            ("--sensor-delay", ["0.01", "0"], ["-1", "nan", "100"]),
                            ("--sensor-noise", ["gyro=0.01", "position=1e-3"],
                             ["gyro=-1", "bogus=1", "gyro=abc", "="]),
                            ("--effect", ["ground_effect:gain=1.5", "wind:vx=1"],
                             ["nosuch", "wind:vx=abc", "motor_lag:time_constant=-1", ":"]),
                            ("--engine", ["mujoco", "analytic"], ["x"]),
                            ("--seed", ["0", "3"], ["-1", "x"])):
        if _maybe(rng, 0.25):
            argv += [flag, _either(rng, good, bad)]
    argv += ["--duration", _either(rng, ["0.2", "0.3"], ["-1", "0", "nan", "abc"]),
             "-o", _either(rng, pool["out"](".csv.gz")[:1], pool["out"](".csv.gz")), "--quiet"]
    return argv


def _view(rng, pool):
    argv = ["--model", _either(rng, ["crazyflie21"], pool["models"])]
    if _maybe(rng, 0.5):
        argv += ["--log", _either(rng, pool["good"], pool["logs"])]
    if _maybe(rng, 0.3):
        argv += ["--horizon", _either(rng, ["0.5", "0"], ["-1", "nan", "abc"])]
    if _maybe(rng, 0.3):
        argv += ["--engine", _either(rng, ["analytic"], ["x", ","])]
    else:
        argv += ["--engine", "analytic"]  # one engine keeps the valid runs short
    if _maybe(rng, 0.1):
        argv += ["--cad", _pick(rng, pool["cad"])]
    if _maybe(rng, 0.95):
        argv += ["--rerun", _either(rng, pool["out"](".rrd")[:1], pool["out"](".rrd"))]
    argv += ["--duration", _either(rng, ["0.2"], ["-1", "0", "nan"])]
    return argv


def _openloop(rng, pool):
    argv = ["--model", _either(rng, ["physical", "crazyflie21", "report"], pool["models"])]
    if _maybe(rng, 0.2):
        argv += ["--compare", _either(rng, ["computational"], pool["models"])]
    for flag, good in (("--step-thrust", "0.1"), ("--step-roll", "0.001"), ("--bound", "2"),
                       ("--control-period", "0.02")):
        if _maybe(rng, 0.2):
            argv += [flag, _either(rng, [good], NUMBERS)]
    if _maybe(rng, 0.2):
        argv += ["--controller", _either(rng, ["lqr", "none"], ["pid"])]
    argv += ["--duration", _either(rng, ["0.3"], ["-1", "0", "nan"]),
             "--step-time", _either(rng, ["0.1"], NUMBERS), "--no-plots"]
    if _maybe(rng, 0.3):
        argv += ["--json"]
    return argv


def _build(rng, pool):
    argv = [_either(rng, pool["cad"][:1], pool["cad"])]
    if _maybe(rng, 0.5):
        argv += ["--params", _either(rng, ["physical", "computational"], pool["models"])]
    if _maybe(rng, 0.3):
        argv += ["--inertial", _either(rng, ["cad", "params"], ["x"])]
    argv += ["-o", _either(rng, pool["out"](".xml")[:1], pool["out"](".xml"))]
    return argv


def _identify(rng, pool):
    argv = []
    for _ in range(int(rng.integers(0, 3))):
        argv += ["--stand", _either(rng, pool["stand"][:1], pool["stand"])]
    if _maybe(rng, 0.3):
        argv += ["--stand-radius", _either(rng, ["0.127"], NUMBERS)]
    if _maybe(rng, 0.15):
        argv += ["--cfd", _pick(rng, pool["logs"])]
    if _maybe(rng, 0.2):
        argv += ["--model", _either(rng, ["report", "physical"], pool["models"])]
    if _maybe(rng, 0.4):
        argv += ["--json"]
    return argv


def _mains():
    from quadsim.build_mjcf import main as build
    from quadsim.fly import main as fly
    from quadsim.gap.__main__ import main as gap
    from quadsim.identify.__main__ import main as identify
    from quadsim.openloop import main as openloop
    from quadsim.view import main as view

    return {"gap": (gap, _gap), "fly": (fly, _fly), "view": (view, _view),
            "openloop": (openloop, _openloop), "build_mjcf": (build, _build),
            "identify": (identify, _identify)}


def _run(main, argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
            warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
            code = exc.code
    return code, err.getvalue()


def test_cli_fuzz(pool):
    rng = np.random.default_rng(SEED)
    mains = _mains()
    names = [name for name in sorted(CASES) for _ in range(CASES[name])]
    names = [names[i] for i in rng.permutation(len(names))]
    seen = {name: {0: 0, 2: 0} for name in CASES}
    for case, name in enumerate(names):
        main, make = mains[name]
        argv = make(rng, pool)
        try:
            code, err = _run(main, argv)
        except Exception as exc:  # noqa: BLE001 - a traceback would reach the user
            pytest.fail(f"case {case}: python -m quadsim.{name} {' '.join(argv)} raised "
                        f"{type(exc).__name__}: {exc}")
        assert code in (0, 2), (case, name, argv, code, err[-500:])
        assert "Traceback" not in err, (case, name, argv, err[-2000:])
        if code == 2:
            assert "error:" in err.strip().splitlines()[-1], (case, name, argv, err[-500:])
        seen[name][code] += 1
    # the generator reaches both outcomes for every command (else it tests nothing)
    for name, counts in seen.items():
        assert counts[2] > 0, (name, counts)
    assert sum(c[0] for c in seen.values()) >= 40, seen


@pytest.mark.parametrize("module, argv", [
    ("quadsim.fly", ["--duration", "-1", "-o", "x.csv.gz"]),
    ("quadsim.view", ["--model", "crazyflie21", "--horizon", "-1", "--rerun", "x.rrd"]),
])
def test_cli_subprocess_one_line(pool, module, argv):
    argv = [a.replace("{log}", pool["good"][0]) for a in argv]
    done = subprocess.run([sys.executable, "-m", module, *argv], capture_output=True,
                          text=True, cwd=REPO, timeout=120, check=False)
    assert done.returncode == 2, done.stderr
    lines = [x for x in done.stderr.splitlines() if not x.startswith("warning:")]
    assert len(lines) == 1 and lines[0].startswith("error:"), done.stderr
    assert "Traceback" not in done.stderr
