"""Benchmark: quadsim's engines against raw MuJoCo, measured side by side in one run.

The flight: the testbed (``--model``, default physical) from the report's initial state
(z = 1 m, roll = pitch = yaw = 0.261 rad) under a seeded multisine on every rotor (+-3 % of
hover speed, 100 Hz zero-order hold), RK4 at 1 ms. "All effects" is every effect of the
library at once, each at its testbed magnitude (``quadsim.effects.TESTBED_EXAMPLES``).

Rows (simulation steps per second, summed over the batch; one step = 1 ms simulated)::

    raw MuJoCo mj_step loop, 1 sim          the baseline (ratio 1)
    raw mujoco.rollout, --batch sims        MuJoCo's own threaded open-loop rollout
    quadsim MuJoCo, no effects / all effects, 1 sim and --batch sims (compiled path)
    quadsim MuJoCo, all effects, 1 sim, reference step-by-step path
    quadsim analytic, no effects / all effects (compiled and numpy right-hand side), 1 sim
    RotorPy 3.0 Multirotor.step (1 ms, aero on), 1 sim, when rotorpy is installed

and the throughput of quadsim (no effects, all effects) and raw rollout against batch size
1 ... 1024 as a PNG (``--plot``). Ratios are to the raw ``mj_step`` loop of the same run, so
they travel between machines better than the rates; timings still depend on the machine and
its load, which the output names::

    python scripts/bench_engines.py [--duration 2] [--batch 64] [--plot out.png] [--json out.json]
    python scripts/bench_engines.py --quick --plot /tmp/b.png    # does it all run (seconds)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run from a checkout

from quadsim.effects import EFFECTS, TESTBED_EXAMPLES, effect_set_from_specs  # noqa: E402
from quadsim.sim.engines import initial_state, simulate  # noqa: E402
from quadsim.sim.linear import hover_point  # noqa: E402
from quadsim.sim.mujoco_engine import compile_model  # noqa: E402
from quadsim.vehicle.params import load_params  # noqa: E402

PERIOD = 0.01
DT = 1e-3
START = initial_state(position=(0, 0, 1), euler=(0.261, 0.261, 0.261))


def multisine(params, periods: int, batch: int, period: float = PERIOD, seed: int = 0
              ) -> np.ndarray:
    """(batch, periods, R) rotor speeds (rad/s), a different seeded multisine per simulation."""
    _, hover = hover_point(params)
    rng = np.random.default_rng(seed)
    t = np.arange(periods) * period
    freq = rng.uniform(0.2, 3.0, (batch, 5, hover.size))
    phase = rng.uniform(0, 2 * np.pi, (batch, 5, hover.size))
    wobble = np.sin(2 * np.pi * freq[:, None] * t[None, :, None, None] + phase[:, None]).sum(2)
    return hover * (1 + 0.03 * wobble / 5)


def all_effects():
    """Every effect of the library once (``quadsim.effects.EFFECTS``), at its testbed
    magnitude."""
    effects = effect_set_from_specs([specs[0] for specs in TESTBED_EXAMPLES.values()])
    missing = set(EFFECTS) - {e.name for e in effects.effects}
    if missing:
        raise SystemExit(f"no testbed example for effect(s) {sorted(missing)}")
    return effects


def fast_path_note(params, effects) -> str:
    """Which path the "all effects" rows take (the compiled one, or why not)."""
    from quadsim.sim import compiled as fast_mujoco

    problem = fast_mujoco.fast_form_problem([effects], [effects.apply_to_params(params)])
    return "compiled fast path" if problem is None else f"reference path ({problem})"


def best_rate(fn, steps: int, repeat: int = 2) -> float:
    """Steps per second of the fastest of ``repeat`` calls."""
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return steps / best


def raw_loop(params, series: np.ndarray) -> float:
    """Steps/s of :func:`raw_loop_fn`."""
    return best_rate(raw_loop_fn(params, series), len(series) * round(PERIOD / DT))


def raw_loop_fn(params, series: np.ndarray):
    """A callable: mj_step in a Python loop on one MjData, ctrl = Omega^2 set once per control
    period (the model compiled outside it)."""
    model = compile_model(params, DT)
    substeps = round(PERIOD / DT)

    def run():
        data = mujoco.MjData(model)
        data.qpos[:] = [0, 0, 1, *START["quat"]]
        for command in series:
            data.ctrl[:] = command**2
            for _ in range(substeps):
                mujoco.mj_step(model, data)

    return run


def interleaved(fns: dict, steps: int, repeat: int = 3) -> dict:
    """Best steps/s of each callable over ``repeat`` rounds that alternate between them, so
    that a change of machine load hits every configuration alike (the ratios are what the
    targets are about)."""
    best = {k: np.inf for k in fns}
    for _ in range(repeat):
        for key, fn in fns.items():
            start = time.perf_counter()
            fn()
            best[key] = min(best[key], time.perf_counter() - start)
    return {k: steps / v for k, v in best.items()}


def rollout_fn(params, series: np.ndarray, threads: int):
    """A callable running mujoco.rollout of the batch's open-loop controls (set-up done)."""
    from mujoco import rollout

    model = compile_model(params, DT)
    substeps = round(PERIOD / DT)
    control = np.repeat(series**2, substeps, axis=1)
    datas = [mujoco.MjData(model) for _ in range(threads)]
    data = datas[0]
    data.qpos[:] = [0, 0, 1, *START["quat"]]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.zeros(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state, spec)
    initial = np.tile(state, (len(series), 1))
    return lambda: rollout.rollout(model, datas, initial, control)


def quadsim_fn(params, series: np.ndarray, engine: str = "mujoco", **kw):
    """A callable running quadsim's simulate on the series (kernels loaded by a warm-up)."""
    batch, periods = series.shape[:2]
    start = {k: np.tile(v, (batch, 1)) for k, v in START.items()}

    def run(steps=periods):
        return simulate(params, engine=engine, initial=start,
                        rotor_speed_series=series[:, :steps], duration=steps * PERIOD,
                        control_period=PERIOD, **kw)

    run(1)
    return run


def raw_rollout(params, series: np.ndarray, threads: int) -> float:
    """Steps/s of :func:`rollout_fn` (one per 1 ms step, ``threads``)."""
    return best_rate(rollout_fn(params, series, threads),
                     series.shape[0] * series.shape[1] * round(PERIOD / DT))


def quadsim_rate(params, series: np.ndarray, engine: str = "mujoco", repeat: int = 2,
                 **kw) -> float:
    """Steps/s of :func:`quadsim_fn` (best of ``repeat``; the warm-up is outside)."""
    return best_rate(quadsim_fn(params, series, engine, **kw),
                     series.shape[0] * series.shape[1] * round(PERIOD / DT), repeat)


def rotorpy_rate(series: np.ndarray) -> float | None:
    """RotorPy 3.0 ``Multirotor.step`` at 1 ms with aerodynamics on (its Crazyflie)."""
    try:
        from rotorpy.vehicles.crazyflie_params import quad_params
        from rotorpy.vehicles.multirotor import Multirotor
    except ImportError:
        return None
    vehicle = Multirotor(quad_params, aero=True)
    hover = vehicle.initial_state["rotor_speeds"]
    commands = hover * series[0] / series[0].mean()
    steps = min(len(commands) * 10, 400)

    def run():
        state = {k: np.array(v, dtype=float) for k, v in vehicle.initial_state.items()}
        for i in range(steps):
            state = vehicle.step(state, {"cmd_motor_speeds": commands[i // 10]}, DT)

    return best_rate(run, steps, repeat=1)


def target_lines(rows, batch: int) -> list[str]:
    """The speed targets, each as the ratio measured in this run."""
    rate = {(label, sims): r for label, sims, r in rows}
    raw, roll = rate[("raw MuJoCo mj_step loop", 1)], rate[("raw mujoco.rollout", batch)]
    checks = [("all effects, 1 sim / raw mj_step loop", rate[("quadsim MuJoCo, all effects", 1)]
               / raw, 0.45),
              (f"all effects, {batch} sims / raw mujoco.rollout of {batch}",
               rate[("quadsim MuJoCo, all effects", batch)] / roll, 0.85),
              ("no effects, 1 sim / raw mj_step loop",
               rate[("quadsim MuJoCo, no effects", 1)] / raw, 0.8),
              ("analytic all effects, compiled / numpy right-hand side",
               rate[("quadsim analytic, all effects", 1)]
               / rate[("quadsim analytic, all effects, numpy right-hand side", 1)], 10.0)]
    rotorpy = rate.get(("RotorPy 3.0 Multirotor.step, aero on", 1))
    if rotorpy:
        checks.insert(1, ("all effects, 1 sim / RotorPy", rate[("quadsim MuJoCo, all effects", 1)]
                          / rotorpy, 30.0))
    return ["targets, ratios measured in this run:"] + [
        f"  {label}: {value:.3g} (target >= {goal:g}) {'met' if value >= goal else 'NOT MET'}"
        for label, value, goal in checks]


def scaling(params, periods: int, sizes, threads: int) -> dict:
    """Steps/s against batch size for raw rollout and quadsim (no effects / all effects)."""
    out = {"batch": list(sizes), "raw rollout": [], "quadsim no effects": [],
           "quadsim all effects": []}
    effects = all_effects()
    for size in sizes:
        series = multisine(params, periods, size)
        out["raw rollout"].append(raw_rollout(params, series, threads))
        out["quadsim no effects"].append(quadsim_rate(params, series, repeat=1))
        out["quadsim all effects"].append(quadsim_rate(params, series, repeat=1,
                                                       effects=effects))
        print(f"  batch {size:>5}: " + ", ".join(f"{k} {v[-1]:.3g}" for k, v in out.items()
                                                  if k != "batch"), flush=True)
    return out


def plot(result: dict, path: str, machine: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for label in ("raw rollout", "quadsim no effects", "quadsim all effects"):
        ax.loglog(result["batch"], result[label], "o-", label=label)
    ax.set_xlabel("simulations in the batch")
    ax.set_ylabel("simulation steps / s (1 ms steps, summed)")
    ax.set_title(f"throughput vs batch size\n{machine}", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="physical")
    parser.add_argument("--duration", type=float, default=2.0, help="simulated s per flight")
    parser.add_argument("--batch", type=int, default=64, help="simulations in the batch rows")
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1,
                        help="threads for raw rollout (quadsim uses every CPU)")
    parser.add_argument("--plot", help="write the throughput-vs-batch PNG here")
    parser.add_argument("--max-batch", type=int, default=1024, help="largest batch in --plot")
    parser.add_argument("--json", help="write the results here too")
    parser.add_argument("--quick", action="store_true",
                        help="a quick check that everything runs: 0.2 s flights, batch 8, "
                             "plot up to batch 16 (numbers not for reporting)")
    args = parser.parse_args()
    if args.quick:
        args.duration, args.batch, args.max_batch = 0.2, min(args.batch, 8), 16
    if args.duration <= 0 or args.batch < 1 or args.threads < 1:
        parser.error("--duration, --batch and --threads must be positive")
    params = load_params(args.model)
    periods = round(args.duration / PERIOD)
    series = multisine(params, periods, args.batch)
    one = series[:1]
    effects = all_effects()
    machine = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
               f"load average {os.getloadavg()[0]:.1f} at start")
    steps1 = periods * round(PERIOD / DT)
    single = interleaved({"raw": raw_loop_fn(params, series[0]),
                          "none": quadsim_fn(params, one),
                          "all": quadsim_fn(params, one, effects=effects)}, steps1, 5)
    batched = interleaved({"rollout": rollout_fn(params, series, args.threads),
                           "none": quadsim_fn(params, series),
                           "all": quadsim_fn(params, series, effects=effects)},
                          steps1 * args.batch, 3)
    rows = [("raw MuJoCo mj_step loop", 1, single["raw"]),
            ("raw mujoco.rollout", args.batch, batched["rollout"]),
            ("quadsim MuJoCo, no effects", 1, single["none"]),
            ("quadsim MuJoCo, no effects", args.batch, batched["none"]),
            ("quadsim MuJoCo, all effects", 1, single["all"]),
            ("quadsim MuJoCo, all effects", args.batch, batched["all"]),
            ("quadsim MuJoCo, all effects, reference path", 1,
             quadsim_rate(params, one, effects=effects, fast=False, repeat=1)),
            ("quadsim analytic, no effects", 1, quadsim_rate(params, one, "analytic")),
            ("quadsim analytic, all effects", 1,
             quadsim_rate(params, one, "analytic", effects=effects, repeat=1)),
            ("quadsim analytic, all effects, numpy right-hand side", 1,
             quadsim_rate(params, one, "analytic", effects=effects, fast=False, repeat=1))]
    rotorpy = rotorpy_rate(one[0])
    if rotorpy is not None:
        rows.append(("RotorPy 3.0 Multirotor.step, aero on", 1, rotorpy))
    raw = rows[0][2]
    path = fast_path_note(params, effects)
    print(f"{args.model}, RK4 {DT * 1e3:g} ms, {args.duration:g} s multisine; {machine}; "
          f"mujoco {mujoco.__version__}")
    print(f"all effects = {len(effects.effects)} library effects "
          f"({', '.join(e.name for e in effects.effects)}); MuJoCo rows: {path}")
    print("| configuration | sims | sim-steps/s | vs raw mj_step |\n|---|---|---|---|")
    for label, sims, rate in rows:
        print(f"| {label} | {sims} | {rate:.3g} | {rate / raw:.3g} |")
    targets = target_lines(rows, args.batch)
    print("\n".join(targets))
    result = {"model": params.name, "duration_s": args.duration, "machine": machine,
              "targets": targets,
              "mujoco": mujoco.__version__, "all_effects_path": path,
              "rows": [{"config": c, "sims": s, "steps_per_s": r, "vs_raw": r / raw}
                       for c, s, r in rows]}
    if args.plot:
        sizes = [n for n in (1, 4, 16, 64, 256, 1024) if n <= args.max_batch]
        result["scaling"] = scaling(params, max(1, periods // 4), sizes, args.threads)
        plot(result["scaling"], args.plot, machine)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(result, handle, indent=2)


if __name__ == "__main__":
    main()
