"""quadsim.core.executor: same results whichever executor; dead workers retried once then named;
Ray missing / unreachable -> one line, exit 2. Ray tests share one local cluster."""

from __future__ import annotations

import os
import sys

import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import InputError
from quadsim.core.executor import TaskFailure, _finish, run_tasks
from quadsim.effects import make_effect
from quadsim.gap.__main__ import main as gap_main
from quadsim.logs.flightlog import write_log
from quadsim.vehicle.params import load_params

sys.path.insert(0, os.path.dirname(__file__))
from _parallel_tasks import bad_input as _bad_input
from _parallel_tasks import die_on_three as _die_on_three
from _parallel_tasks import square_noise as _square_noise

#: one xdist worker runs this module's tests (pytest-xdist --dist loadgroup): its module-scoped
#: fixtures are built once, not once per worker
pytestmark = pytest.mark.xdist_group("test_parallel")


@pytest.fixture(scope="module")
def ray_local():
    ray = pytest.importorskip("ray", reason="Ray is the optional [ray] extra")
    from quadsim.core.executor import connect_ray

    connect_ray("local", 2)
    # this test module is not importable by Ray's workers: ship its functions by value
    ray.cloudpickle.register_pickle_by_value(sys.modules["_parallel_tasks"])
    yield ray
    ray.shutdown()


def test_processes_match_in_process_bit_for_bit():
    tasks = list(range(6))
    serial = run_tasks(_square_noise, tasks, workers=1)
    assert serial == [_square_noise(k) for k in tasks]
    assert run_tasks(_square_noise, tasks, workers=2) == serial


def test_dead_worker_is_retried_then_named_and_the_rest_kept():
    out = run_tasks(_die_on_three, range(5), workers=2, keep_going=True)
    assert out[:3] == [0, 1, 4] and out[4] == 16
    assert isinstance(out[3], TaskFailure) and out[3].index == 3
    with pytest.raises(InputError, match="flight_1.csv: t: not increasing"):
        run_tasks(_bad_input, range(3), workers=2)
    with pytest.raises(InputError, match="worker died twice running flight_3"):
        _finish(out, [out[3]], [f"flight_{k}" for k in range(5)], keep_going=False)


def test_ray_missing_or_unreachable_is_one_line(monkeypatch, capsys, tmp_path):
    log = tmp_path / "f.csv.gz"
    write_log(log, synthetic_flight(load_params("crazyflie21"), [], seed=0, duration=2.0))
    args = ["--model", "crazyflie21", str(log), "--quiet"]
    assert gap_main([*args, "--ray", "127.0.0.1:9"]) == 2          # discard port: refused
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot reach a Ray cluster at 127.0.0.1:9" in err
    monkeypatch.setitem(sys.modules, "ray", None)                   # import ray -> ImportError
    assert gap_main([*args, "--ray", "local"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Ray is not installed" in err


def test_ray_local_matches_in_process(ray_local):
    tasks = list(range(6))
    assert run_tasks(_square_noise, tasks, ray="local") == run_tasks(_square_noise, tasks,
                                                                     workers=1)
    out = run_tasks(_die_on_three, range(5), ray="local", keep_going=True)
    assert out[:3] == [0, 1, 4] and out[4] == 16 and isinstance(out[3], TaskFailure)
    with pytest.raises(InputError, match="flight_1.csv: t: not increasing"):
        run_tasks(_bad_input, range(3), ray="local")


@pytest.mark.parametrize("per_flight", [False, True], ids=["heldout", "per-flight"])
def test_gap_json_same_bytes_in_process_processes_and_ray(ray_local, tmp_path, per_flight):
    cf = load_params("crazyflie21")
    effects = [make_effect("com_offset", x=-0.005)]
    paths = []
    for seed in (20, 21, 22):  # 3 flights: 2 train, 1 held out
        paths.append(str(write_log(tmp_path / f"f{seed}.csv.gz",
                                   synthetic_flight(cf, effects, seed=seed, duration=2.0))))
    args = ["--model", "crazyflie21", *paths, "--quiet",
            "--effects", "com_offset", "mass_offset"]
    if per_flight:
        refs = [str(write_log(tmp_path / f"r{s}.csv.gz", synthetic_flight(cf, [], seed=s,
                                                                          duration=2.0)))
                for s in (30, 31)]
        args += ["--per-flight", "--reference", *refs]
    executors = [["--workers", "1"], ["--ray", "local"]]
    if per_flight:                      # processes: here only (each pool start costs seconds)
        executors.append(["--workers", "2"])
    outputs = []
    for how in executors:
        out = tmp_path / f"gap_{how[1]}.json"
        assert gap_main([*args, *how, "--json", str(out)]) == 0
        outputs.append(out.read_bytes())
    assert all(o == outputs[0] for o in outputs[1:])


def test_sweep_same_bytes_on_ray(ray_local, tmp_path):
    pytest.importorskip("pyarrow", reason="the sweep writes Parquet")
    from quadsim.sweep.__main__ import main as sweep_main

    args = ["--model", "physical", "--path", "hover", "--duration", "0.5", "--quiet",
            "--initial", "x=-0.1..0.1", "--samples", "4", "--chunk-size", "2"]
    one, ray = tmp_path / "one.parquet", tmp_path / "ray.parquet"
    assert sweep_main([*args, "--workers", "1", "-o", str(one)]) == 0
    assert sweep_main([*args, "--ray", "local", "-o", str(ray)]) == 0
    assert one.read_bytes() == ray.read_bytes()


def test_self_check_same_bytes_in_process_and_processes(tmp_path):
    """The references' self-check weighs each reference in the executor's workers
    (``diagnose.reference_self_check(map_fn=)``): the result JSON of three references and
    one flight is the same bytes with ``--workers 1`` and ``--workers 2``, the self-check
    ran (three references) and judged each of them."""
    import json

    cf = load_params("crazyflie21")
    flight = str(write_log(tmp_path / "f.csv.gz", synthetic_flight(
        cf, [make_effect("mass_offset", mass=0.004)], seed=40, duration=2.0)))
    refs = [str(write_log(tmp_path / f"r{s}.csv.gz", synthetic_flight(cf, [], seed=s,
                                                                      duration=2.0)))
            for s in (41, 42, 43)]
    outputs = []
    for workers in ("1", "2"):
        out = tmp_path / f"gap_{workers}.json"
        assert gap_main(["--model", "crazyflie21", "--per-flight", flight, "--reference", *refs,
                         "--effects", "mass_offset", "com_offset", "--quiet", "--no-cache",
                         "--workers", workers, "--json", str(out)]) == 0
        outputs.append(out.read_bytes())
    assert outputs[0] == outputs[1]
    check = json.loads(outputs[0])["reference_model"]["self_check"]
    assert check is not None and len(check["verdicts"]) == 3
