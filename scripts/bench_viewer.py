"""Benchmark: cost of a rerun recording, in seconds and bytes per simulated second.

    python scripts/bench_viewer.py [--seconds 20] [--rates 100,500] [--repeat 3]

For each sample rate, builds closed-form flights (two engines plus a measured flight, four
rotors, the stand-in meshes) and times :func:`quadsim.viewer.recording_bytes` (everything
but the final file write) and the atomic write; prints a Markdown table for docs/viewer.md.
Also times one simulation of the same length in MuJoCo with no recording, for scale, and
checks that importing the engines does not import rerun (logging off costs nothing).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from quadsim.core.frames import euler_to_quat  # noqa: E402
from quadsim.vehicle.params import hover_speed, load_params  # noqa: E402
from quadsim.vehicle.state import Trajectory  # noqa: E402
from quadsim.viewer import recording_bytes, save_recording  # noqa: E402


def flight(params, seconds: float, rate: float, offset: float) -> Trajectory:
    t = np.arange(int(round(seconds * rate)) + 1) / rate
    position = np.stack([np.sin(t), np.cos(t) - 1.0, 1.0 + 0.05 * t], -1) + offset
    euler = np.stack([0.1 * np.sin(3 * t), 0.1 * np.cos(3 * t), 0.3 * t], -1)
    speed = hover_speed(params) + 20.0 * np.sin(t)[:, None] * np.array([1, -1, 1, -1])
    return Trajectory(t, position, np.gradient(position, t, axis=0), euler_to_quat(euler),
                      np.zeros((len(t), 3)), speed, speed)


def bench(params, seconds: float, rate: float, repeat: int) -> dict:
    trajectories = {"mujoco": flight(params, seconds, rate, 0.0),
                    "analytic": flight(params, seconds, rate, 0.01)}
    measured = flight(params, seconds, rate, 0.02)
    build, write, size = [], [], 0
    with tempfile.TemporaryDirectory() as folder:
        for _ in range(repeat):
            start = time.perf_counter()
            data = recording_bytes(params=params, trajectories=trajectories, measured=measured)
            build.append(time.perf_counter() - start)
            start = time.perf_counter()
            save_recording(Path(folder) / "b.rrd", params=params, trajectories=trajectories,
                           measured=measured)
            write.append(time.perf_counter() - start)
            size = len(data)
    return {"rate": rate, "samples": len(measured.t), "build_s": min(build),
            "save_s": min(write), "bytes": size, "seconds": seconds}


def simulation_time(params, seconds: float) -> float:
    from quadsim.sim.engines import simulate

    start = time.perf_counter()
    simulate(params, engine="mujoco", duration=seconds, control_period=0.01)
    return time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated seconds")
    parser.add_argument("--rates", default="100,500", help="sample rates (Hz), comma-separated")
    parser.add_argument("--repeat", type=int, default=3, help="best of N")
    args = parser.parse_args()
    params = load_params("physical")
    recording_bytes(params=params, trajectories={"mujoco": flight(params, 0.1, 100, 0)})  # warm
    print("| rate (Hz) | samples/flight | build (s) | build+write (s) | s per sim s | "
          "MB | kB per sim s |")
    print("|---|---|---|---|---|---|---|")
    for rate in (float(r) for r in args.rates.split(",")):
        r = bench(params, args.seconds, rate, args.repeat)
        print(f"| {rate:g} | {r['samples']} | {r['build_s']:.3f} | {r['save_s']:.3f} | "
              f"{r['save_s'] / r['seconds']:.4f} | {r['bytes'] / 1e6:.2f} | "
              f"{r['bytes'] / 1e3 / r['seconds']:.0f} |")
    print(f"\nMuJoCo simulation of the same {args.seconds:g} s (100 Hz control, no "
          f"recording): {simulation_time(params, args.seconds):.3f} s")
    code = "import sys, quadsim.sim.engines, quadsim.viewer; print('rerun' in sys.modules)"
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            cwd=REPO).stdout.strip()
    print(f"rerun imported by `import quadsim.sim.engines, quadsim.viewer`: {loaded}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
