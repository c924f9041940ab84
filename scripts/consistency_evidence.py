"""Delta chi^2 of the two hypothesis checks of ``quadsim.logs.checks`` (gyro frame, rotor
order) on generated Crazyflie figure-8s and, when ``../shared/data`` is there, on the 20
nominal real Crazyflie flights: the numbers of docs/flightlog.md.

    python scripts/consistency_evidence.py            # generated + real (~5 min, 2 cores)
    python scripts/consistency_evidence.py --no-real

Generated: crazyflie21, 6 s, 200 Hz, MuJoCo, gyro noise 0.01 rad/s (attitude noise
0.002 rad for the tilted ones), seeds 0-2. Each row: the log as flown, then the same log with
the body rate turned into the world frame, with rotors 1<->2, 3<->4 swapped and in PX4's order
fed as ours. Rotor-order columns give the best rival order's Delta chi^2 (the right order:
the largest over the 23 others; a wrong one: that of the order that undoes it).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
from pathlib import Path

import numpy as np

from quadsim.core.frames import quat_to_rotmat
from quadsim.effects import EffectSet
from quadsim.logs.checks import cut_nan, gyro_frame_evidence, rotor_order_evidence
from quadsim.logs.flightlog import load_log
from quadsim.logs.generate import generate_flight
from quadsim.logs.sensors import SensorModel
from quadsim.logs.spans import cut_ground
from quadsim.vehicle.params import load_params

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
#: columns fed as ours, and the order (0-based) that undoes them
SWAPS = {"1<->2": ([1, 0, 2, 3], (1, 0, 2, 3)), "3<->4": ([0, 1, 3, 2], (0, 1, 3, 2)),
         "PX4 1,4,2,3": ([0, 2, 3, 1], (0, 3, 1, 2))}


def _tilt_deg(log) -> float:
    return float(np.degrees(np.arccos(np.clip(quat_to_rotmat(log.quat)[:, 2, 2], -1, 1))).max())


def _row(name: str, log, params) -> str:
    world = dataclasses.replace(log, body_rate=np.einsum(
        "nij,nj->ni", quat_to_rotmat(log.quat), log.body_rate))
    frame = gyro_frame_evidence(world)
    own = rotor_order_evidence(log, params)
    cells = [name, f"{_tilt_deg(log):.1f}", f"{frame[3]:.4g}" if frame and frame[2] else "n/a",
             f"{max(own.values()):.4g}"]
    for columns, undo in SWAPS.values():
        swapped = dataclasses.replace(log, rotor_speed=log.rotor_speed[:, columns])
        cells.append(f"{rotor_order_evidence(swapped, params)[undo]:.4g}")
    return "| " + " | ".join(cells) + " |"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-real", action="store_true", help="generated flights only")
    args = parser.parse_args(argv)
    params = load_params("crazyflie21")
    print("| flight | max tilt deg | world-frame gyro | right order's best rival | "
          + " | ".join(SWAPS) + " |")
    print("|---|---|---|---|" + "---|" * len(SWAPS))
    for speed, noise in ((1.0, {"gyro": 0.01}), (1.6, {"gyro": 0.01, "attitude": 0.002}),
                         (1.93, {"gyro": 0.01, "attitude": 0.002})):
        for seed in range(3):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                log, _ = generate_flight(params, "figure8", EffectSet(), SensorModel(noise=noise),
                                         seed, duration=6.0, speed=speed)
            print(_row(f"figure-8 {speed} m/s seed {seed}", log, params), flush=True)
    folder = DATA / "crazyflie21_brushless" / "nominal"
    if args.no_real or not folder.is_dir():
        return 0
    for path in sorted(folder.glob("flight_*.csv.gz")):
        log, _ = cut_ground(cut_nan(load_log(path, warn=False))[0])
        print(_row(f"real {path.name}", log, params), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
