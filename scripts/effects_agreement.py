"""Benchmark: every effect in both engines, 5 s open loop and 20 s closed loop; timings.

Run from the repository root: ``python scripts/effects_agreement.py`` (a few minutes). Prints
a Markdown table (max position difference (m) and attitude difference (rad) between MuJoCo
and the analytic engine per effect) and the wall time of a 20 s generated flight, for
docs/effects.md. Targets: <= 1e-4 m / 1e-4 rad open loop over 5 s; <= 1e-3 m closed loop over
20 s. The open-loop scenario is the one of tests/test_effects_engines.py, run 10x longer.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from quadsim.core.frames import quat_conjugate, quat_multiply
from quadsim.effects import TESTBED_EXAMPLES, effect_set_from_specs
from quadsim.logs.generate import generate_flight
from quadsim.sim.controllers import GeometricController
from quadsim.sim.engines import initial_state, simulate
from quadsim.sim.paths import make_reference
from quadsim.vehicle.params import hover_speed, load_params

PARAMS = load_params("physical")
HOVER = hover_speed(PARAMS)
PERIOD = 0.01
REALISTIC = {name: specs for name, specs in TESTBED_EXAMPLES.items()
             if name not in ("motor_lag", "battery_sag")}
LAG = {name: TESTBED_EXAMPLES[name] for name in ("motor_lag", "battery_sag")}  # rotor states


def errors(m, a):
    position = np.abs(m.position - a.position).max(axis=(1, 2))
    relative = quat_multiply(quat_conjugate(m.quat), a.quat)
    angle = 2 * np.arcsin(np.clip(np.linalg.norm(relative[..., 1:], axis=-1), 0, 1)).max(1)
    return position, angle


def open_loop(specs: dict, duration: float = 5.0):
    sets = [effect_set_from_specs(s) for s in specs.values()]
    batch = len(sets)

    def tile(v):
        return np.tile(v, (batch, 1))

    start = initial_state(position=tile([0.0, 0.0, 0.3]), velocity=tile([3.0, -2.0, 0.5]),
                          euler=tile([0.02, -0.01, 0.2]))
    t = np.arange(int(round(duration / PERIOD))) * PERIOD
    series = HOVER * (1 + 0.01 * np.sin(2 * np.pi * 0.7 * t))[:, None] * np.ones(4)
    if "motor_lag" in specs:
        series = HOVER * np.where((t // 0.25) % 2 == 0, 1.03, 0.97)[:, None] * np.ones(4)
    runs = [simulate(PARAMS, engine=e, initial=start, rotor_speed_series=series,
                     duration=duration, control_period=PERIOD, effects=sets)
            for e in ("mujoco", "analytic")]
    return errors(*runs)


def closed_loop(specs: dict, duration: float = 20.0):
    sets = [effect_set_from_specs(s) for s in specs.values()]
    batch = len(sets)
    reference = make_reference("figure8", speed=1.0, height=0.5)
    runs = []
    for engine in ("mujoco", "analytic"):
        ctrl = GeometricController(PARAMS, reference)
        start = {k: np.tile(v, (batch, 1)) for k, v in ctrl.initial_state().items()}
        runs.append(simulate(PARAMS, engine=engine, initial=start, controller=ctrl,
                             duration=duration, control_period=PERIOD, effects=sets))
    return errors(*runs)


def main() -> None:
    rows = {}
    for group in (REALISTIC, LAG):
        t0 = time.perf_counter()
        ol = open_loop(group)
        t1 = time.perf_counter()
        cl = closed_loop(group)
        t2 = time.perf_counter()
        print(f"# batch of {len(group)}: open loop {t1 - t0:.1f} s, closed loop {t2 - t1:.1f} s",
              flush=True)
        for i, name in enumerate(group):
            rows[name] = (ol[0][i], ol[1][i], cl[0][i], cl[1][i])
    print("| effect | open loop 5 s: max dpos (m) | max dangle (rad) | closed loop 20 s: "
          "max dpos (m) | max dangle (rad) |")
    print("|---|---|---|---|---|")
    for name, (a, b, c, d) in rows.items():
        print(f"| {name} | {a:.2e} | {b:.2e} | {c:.2e} | {d:.2e} |")
    effects = effect_set_from_specs(["ground_effect:gain=1.5", "wind:vx=2,gust=0.5",
                                     "body_drag:cd_area=0.02"])
    for engine in ("mujoco", "analytic"):
        t0 = time.perf_counter()
        generate_flight(PARAMS, "figure8", effects, None, seed=0, duration=20.0,
                        control_period=0.005, engine=engine)
        print(f"20 s figure-8 flight at 200 Hz, 3 effects, {engine}: "
              f"{time.perf_counter() - t0:.1f} s wall")


if __name__ == "__main__":
    main()
