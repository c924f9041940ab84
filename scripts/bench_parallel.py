"""Speed-up of gap per-flight diagnosis and of a sweep with 1 worker, 2 local processes and
Ray local (2 CPUs), Ray's per-task overhead, and the cluster extrapolation of docs/scaling.md.

    python scripts/bench_parallel.py [--flights 6] [--sims 32] [--json out.json]

Not a test: wall times depend on the machine and its load (say so when quoting them).
Extrapolation to a cluster of ``nodes`` x ``cores``: tasks spread evenly, each core runs
``ceil(tasks / (nodes cores))`` tasks one after another, each costing its measured
single-core time plus the measured Ray per-task overhead, plus one cluster start/connect.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.synthetic import synthetic_flight
from quadsim.effects import make_effect
from quadsim.gap.__main__ import main as gap_main
from quadsim.logs.flightlog import write_log
from quadsim.sweep.__main__ import main as sweep_main
from quadsim.vehicle.params import load_params


def _noop(x):
    return x


CPU: dict[str, float] = {}


def _timed(fn, key: str = "") -> float:
    """Wall time (s) of fn(); its CPU time in this process goes to CPU[key] (the single-core
    cost of a workers=1 run, which load on a shared machine inflates less than wall time)."""
    start, cpu = time.perf_counter(), time.process_time()
    assert fn() == 0
    CPU[key] = time.process_time() - cpu
    return time.perf_counter() - start


def overheads(tasks: int = 400) -> dict:
    """Fixed start-up costs (Ray local cluster; a 2-process spawn pool) and Ray's per-task
    overhead (no-op tasks, warm workers, wall per task)."""
    from quadsim.core.executor import connect_ray, run_tasks

    start = time.perf_counter()
    connect_ray("local", 2)
    run_tasks(_noop, range(2), ray="local")                      # first tasks start workers
    ray_start = time.perf_counter() - start
    run_tasks(_noop, range(20), ray="local")
    start = time.perf_counter()
    run_tasks(_noop, range(tasks), ray="local")
    per_task = (time.perf_counter() - start) / tasks
    start = time.perf_counter()
    run_tasks(_noop, range(2), workers=2)
    pool_start = time.perf_counter() - start
    return {"ray_start_s": ray_start, "ray_per_task_s": per_task, "pool_start_s": pool_start}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--flights", type=int, default=6)
    parser.add_argument("--sims", type=int, default=32)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    cf = load_params("crazyflie21")
    out: dict = {"cpus": os.cpu_count(), "load_avg_1min": os.getloadavg()[0]}
    out.update(overheads())
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        refs = [str(write_log(tmp / f"r{s}.csv.gz", synthetic_flight(cf, [], seed=s,
                                                                     duration=4.0)))
                for s in (100, 101)]
        logs = [str(write_log(tmp / f"f{s}.csv.gz", synthetic_flight(
            cf, [make_effect("com_offset", x=0.004)] if s % 2 else [], seed=s, duration=4.0)))
            for s in range(args.flights)]
        gap = ["--model", "crazyflie21", "--per-flight", *logs, "--reference", *refs,
               "--quiet", "--no-cache"]    # each way computes the references' stage itself
        sweep = ["--model", "physical", "--path", "hover", "--duration", "2", "--quiet",
                 "--effect", "mass_offset:mass=0..0.1", "--initial", "x=-0.2..0.2",
                 "--samples", str(args.sims), "--chunk-size", "4"]
        for name, argv, count in (("gap", gap, args.flights), ("sweep", sweep, args.sims)):
            for how in (["--workers", "1"], ["--workers", "2"], ["--ray", "local"]):
                extra = ["-o", str(tmp / f"{name}{how[1]}.parquet")] if name == "sweep" else []
                command = gap_main if name == "gap" else sweep_main
                wall = _timed(partial(command, [*argv, *how, *extra]), name + how[1])
                key = f"{name}_{how[1] if how[0] == '--workers' else 'ray'}"
                out[key + "_s"] = wall
                print(f"{key}: {wall:.1f} s for {count} tasks", flush=True)
            base = out[f"{name}_1_s"]
            out[f"{name}_speedup_processes"] = base / out[f"{name}_2_s"]
            out[f"{name}_speedup_ray"] = base / out[f"{name}_ray_s"]
        out["gap_s_per_flight"] = out["gap_1_s"] / args.flights
        out["sweep_s_per_sim"] = out["sweep_1_s"] / args.sims
        out["gap_cpu_s_per_flight"] = CPU["gap1"] / args.flights
        out["sweep_cpu_s_per_sim"] = CPU["sweep1"] / args.sims
    for label, tasks, per_task, batch in (("10,000 flights", 10_000,
                                           out["gap_cpu_s_per_flight"], 1),
                                          ("1,000,000 simulations", 1_000_000,
                                           out["sweep_cpu_s_per_sim"], 64)):
        cores = 100 * 16
        waves = math.ceil(tasks / batch / cores)
        wall = waves * (batch * per_task + out["ray_per_task_s"]) + out["ray_start_s"]
        out[f"estimate {label}, 100 nodes x 16 cores"] = wall
        print(f"estimate {label} on 100 x 16 cores: {wall:.0f} s", flush=True)
    text = json.dumps(out, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")


if __name__ == "__main__":
    main()
