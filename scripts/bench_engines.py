"""Benchmark: MuJoCo steps/s (single run and batched through mujoco.batch) vs the analytic
Newton–Euler model through solve_ivp, on the same flight, at matched accuracy.

The flight: the testbed (``--model``, default physical) from the report's initial state
(z = 1 m, roll = pitch = yaw = 0.261 rad) under a seeded multisine on every rotor (+-3 % of
hover speed, 100 Hz zero-order hold) for ``--duration`` s. Accuracy of every configuration is
the largest position error against a reference (analytic, rtol 1e-13, atol 1e-14).

    python scripts/bench_engines.py [--model physical] [--duration 5] [--batch 64] [--json out.json]

Reports wall time, real-time factor (simulated s per wall s, summed over the batch) and, for
MuJoCo, timesteps per second (summed over the batch). Timings depend on the machine and its
load; the numbers in docs/engines.md say where they were taken.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import mujoco
import numpy as np

from quadsim.engines import initial_state, simulate
from quadsim.linear import hover_point
from quadsim.mujoco_engine import compile_model
from quadsim.params import load_params


def multisine(params, periods: int, batch: int, period: float, seed: int = 0) -> np.ndarray:
    """(batch, periods, R) rotor speeds, a different seeded multisine per simulation."""
    _, hover = hover_point(params)
    rng = np.random.default_rng(seed)
    t = np.arange(periods) * period
    freq = rng.uniform(0.2, 3.0, (batch, 5, hover.size))
    phase = rng.uniform(0, 2 * np.pi, (batch, 5, hover.size))
    wobble = np.sin(2 * np.pi * freq[:, None] * t[None, :, None, None] + phase[:, None]).sum(2)
    return hover * (1 + 0.03 * wobble / 5)


def timed(fn, repeat: int = 1):
    best, result = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - start)
    return best, result


def plain_loop_steps_per_s(params, series: np.ndarray, period: float, dt: float) -> float:
    """mj_step in a Python loop on one MjData (the baseline the batch is compared with)."""
    model = compile_model(params, dt)
    data = mujoco.MjData(model)
    data.qpos[:] = [0, 0, 1, *initial_state(euler=(0.261, 0.261, 0.261))["quat"]]
    substeps = int(round(period / dt))
    start = time.perf_counter()
    for command in series:
        data.ctrl[:] = command**2
        for _ in range(substeps):
            mujoco.mj_step(model, data)
    return len(series) * substeps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="physical")
    parser.add_argument("--duration", type=float, default=5.0, help="simulated s")
    parser.add_argument("--batch", type=int, default=64, help="simulations in the batch")
    parser.add_argument("--json", help="write the results here too")
    args = parser.parse_args()
    params = load_params(args.model)
    period = 0.01
    periods = int(round(args.duration / period))
    series = multisine(params, periods, args.batch, period)
    start = initial_state(position=(0, 0, 1), euler=(0.261, 0.261, 0.261))
    run = lambda engine, sims, **kw: simulate(  # noqa: E731
        params, engine=engine, initial=start, rotor_speed_series=series[:sims],
        duration=args.duration, control_period=period, **kw)
    _, reference = timed(lambda: run("analytic", args.batch, rtol=1e-13, atol=1e-14))
    rows = []

    def record(label, engine, sims, steps_per_sim=None, **kw):
        wall, traj = timed(lambda: run(engine, sims, **kw), repeat=2 if sims == 1 else 1)
        error = float(np.abs(traj.position - reference.position[:sims]).max())
        row = {"config": label, "engine": engine, "sims": sims, "wall_s": wall,
               "realtime_factor": sims * args.duration / wall, "max_position_error_m": error}
        if steps_per_sim:
            row["steps_per_s"] = sims * steps_per_sim / wall
        rows.append(row)
        print(f"{label:<34}{sims:>5}{wall:>10.3f} s{row['realtime_factor']:>12.1f}x"
              f"{row.get('steps_per_s', float('nan')):>14.0f}{error:>12.2e} m")

    print(f"{'configuration':<34}{'sims':>5}{'wall':>12}{'realtime':>13}{'steps/s':>14}"
          f"{'pos. error':>14}")
    for dt in (1e-3, 2e-3, 5e-3):
        for sims in (1, args.batch):
            record(f"mujoco RK4 dt={dt * 1e3:g} ms", "mujoco", sims,
                   steps_per_sim=args.duration / dt, timestep=dt)
    for rtol in (1e-6, 1e-8, 1e-11):
        for sims in (1, args.batch):
            record(f"analytic DOP853 rtol={rtol:g}", "analytic", sims, rtol=rtol,
                   atol=rtol * 0.1)
    plain = plain_loop_steps_per_s(params, series[0], period, 1e-3)
    print(f"plain mj_step loop (one MjData, dt=1 ms): {plain:.0f} steps/s")
    result = {"model": params.name, "duration_s": args.duration, "batch": args.batch,
              "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
              "mujoco": mujoco.__version__, "rows": rows, "plain_loop_steps_per_s": plain}
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(result, handle, indent=2)


if __name__ == "__main__":
    main()
