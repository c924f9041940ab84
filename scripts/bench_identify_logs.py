"""Benchmark: ``python -m quadsim.identify --logs`` on 12 one-minute 100 Hz logs (target: under
30 s wall on the 2-core development machine). Not a timed test.

By default the logs are generated once (``benchmarks.synthetic.synthetic_flight`` of the
``crazyflie21`` set, seeds 0-11, 60 s at 100 Hz, sensor noise on) into a temporary folder; the
timed part is the whole command as a user runs it — loading, span cutting, smoothing, every
fit, the d refit and the checked write — in a fresh process, best of ``--repeat``. ``--logs``
times given logs instead (e.g. the nano-drone training runs, 12 logs of 19-60 s at 100 Hz).

Usage::

    python scripts/bench_identify_logs.py [--repeat 3] [--logs LOG... --vehicle SKELETON]
"""

from __future__ import annotations

import argparse
import re
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def _skeleton(folder: Path) -> Path:
    """crazyflie21.toml without thrust_factor, drag_factor, max_speed and the motor map."""
    from quadsim.vehicle.params import MODELS_DIR

    text = (MODELS_DIR / "crazyflie21.toml").read_text()
    text = "\n".join(line for line in text.splitlines()
                     if not re.match(r"(thrust_factor|drag_factor|max_speed) =", line))
    text = re.sub(r"\[motor_map\].*?(?=\n\[\[rotor\]\])", "", text, flags=re.DOTALL)
    path = folder / "skeleton.toml"
    path.write_text(text + "\n")
    return path


def _generate(folder: Path, count: int, duration: float, rate: float) -> list[Path]:
    from benchmarks.synthetic import synthetic_flight
    from quadsim.core.errors import QuadsimWarning
    from quadsim.logs.flightlog import write_log
    from quadsim.vehicle.params import load_params

    cf = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return [write_log(folder / f"flight_{s:02d}.csv.gz",
                          synthetic_flight(cf, [], seed=s, duration=duration, rate_hz=rate))
                for s in range(count)]


def _run(logs: list[Path], skeleton: Path, output: Path) -> tuple[float, float, str]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "quadsim.identify", "--logs", *map(str, logs),
                          "--vehicle", str(skeleton), "-o", str(output)], cwd=ROOT,
                         capture_output=True, text=True, check=False,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if run.returncode != 0:
        raise SystemExit(f"identify failed: {run.stderr.strip()}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    first = run.stdout.splitlines()[0] if run.stdout else ""
    return wall, cpu, first


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--logs", type=Path, nargs="+")
    parser.add_argument("--vehicle", type=Path, help="skeleton for --logs")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if args.logs:
            logs, skeleton = args.logs, args.vehicle
            if skeleton is None:
                raise SystemExit("--logs needs --vehicle SKELETON.toml")
        else:
            t0 = time.perf_counter()
            logs = _generate(folder, 12, 60.0, 100.0)
            print(f"generated 12 one-minute 100 Hz logs in {time.perf_counter() - t0:.1f} s")
            skeleton = _skeleton(folder)
        runs = [_run(logs, skeleton, folder / "vehicle.toml") for _ in range(args.repeat)]
    wall, cpu, first = min(runs)
    print(first)
    print(f"identify --logs, {len(logs)} logs: best of {args.repeat}: {wall:.1f} s wall, "
          f"{cpu:.1f} s CPU (all runs: {', '.join(f'{w:.1f}' for w, _, _ in runs)} s wall; "
          "target < 30 s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
