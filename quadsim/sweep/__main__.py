"""``python -m quadsim.sweep``: see :mod:`quadsim.sweep` (``--help`` for the flags)."""

from __future__ import annotations

import argparse
import sys

from ..core.args import ArgumentParser
from ..core.cost import Estimate, check_cost
from ..core.errors import InputError, run_cli
from ..core.executor import default_workers, limit_numeric_threads
from ..sim.engines import ENGINES
from ..sim.paths import PATHS
from ..vehicle.params import load_params
from . import __doc__ as MANUAL
from .design import design_matrix, parse_effect_ranges, parse_initial_ranges
from .driver import run_sweep
from .run import SweepConfig


def _parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="python -m quadsim.sweep", description=MANUAL.split("\n\n")[0],
        epilog="Example:" + MANUAL.split("Example::")[1].split(">>>")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", default="physical", help="parameter set (name or TOML)")
    parser.add_argument("--path", default="figure8", choices=PATHS, help="reference path")
    parser.add_argument("--speed", type=float, default=1.0, help="path speed (m/s)")
    parser.add_argument("--height", type=float, default=1.0, help="flight height (m)")
    parser.add_argument("--size", type=float, default=1.0, help="path size (m)")
    parser.add_argument("--duration", type=float, default=5.0, help="flight time (s)")
    parser.add_argument("--control-period", type=float, default=0.01, help="(s)")
    parser.add_argument("--engine", default="mujoco", choices=ENGINES)
    parser.add_argument("--effect", action="append", default=[], metavar="NAME:p=LO..HI,...",
                        help="effect with swept (LO..HI) or fixed parameters, repeatable")
    parser.add_argument("--initial", action="append", default=[], metavar="KEY=LO..HI,...",
                        help="initial offsets: x y z (m), vx vy vz (m/s), roll pitch yaw (rad)")
    parser.add_argument("--method", default="mc", choices=("mc", "grid"))
    parser.add_argument("--samples", type=int, default=64, help="simulations (mc)")
    parser.add_argument("--points", type=int, default=5, help="values per swept input (grid)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the mc design")
    parser.add_argument("--chunk-size", type=int, default=16, help="simulations per batch")
    parser.add_argument("--diverge", type=float, default=2.0, metavar="M",
                        help="position error (m) above which a run counts as diverged")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="local processes (default: the CPU count; 1 = in this process)")
    parser.add_argument("--ray", metavar="ADDRESS", default=None,
                        help="'local' starts a local Ray cluster, HOST:PORT joins one")
    parser.add_argument("--quiet", action="store_true",
                        help="no progress bar and no closing summary line")
    parser.add_argument("--allow-large", action="store_true",
                        help="run past the cost caps (quadsim.core.cost: 4 h, 8 GiB)")
    parser.add_argument("-o", "--output", required=True, help="results (.parquet); plot .png")
    return parser


#: measured on the 2-core development machine (python -m quadsim.sweep ... --samples 32 and
#: 128 --duration 2 --workers 1, machine shared at load 8): 12 s to start, 0.069 s per
#: simulated second (the 28x-real-time engine benchmark gives 0.036 on a quiet machine).
SWEEP_START_S = 12.0
SWEEP_S_PER_SIM_S = 0.05
#: memory per simulation (design row, result row, Parquet assembly) and to start (bytes).
SWEEP_BYTES_PER_SIM = 1024
SWEEP_BASE_BYTES = 400 * 1024**2


def sweep_cost(args, dims: int) -> Estimate:
    """Time and memory of the sweep ``args`` asks for (:mod:`quadsim.core.cost`)."""
    count = args.samples if args.method == "mc" else float(args.points) ** dims
    workers = args.workers or default_workers()
    seconds = SWEEP_START_S + SWEEP_S_PER_SIM_S * count * args.duration / max(1, workers)
    return Estimate(seconds=seconds, bytes=SWEEP_BASE_BYTES + SWEEP_BYTES_PER_SIM * count,
                    what=f"{count:.4g} simulations of {args.duration:g} s on {workers} "
                         "worker(s)")


@run_cli
@limit_numeric_threads
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if not args.output.endswith(".parquet"):
        raise InputError(f"{args.output}: output name must end in .parquet")
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers: must be >= 1, got {args.workers}")
    for name in ("duration", "control_period", "diverge"):
        if not getattr(args, name) > 0:
            raise InputError(f"--{name.replace('_', '-')}: must be positive")
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        raise InputError("the sweep writes Parquet: pip install -e '.[parquet]'") from None
    dims = parse_effect_ranges(args.effect) + parse_initial_ranges(args.initial)
    if not dims:
        raise InputError("nothing to sweep: give --effect and/or --initial")
    check_cost(sweep_cost(args, len(dims)), "--samples" if args.method == "mc" else "--points",
               allow=args.allow_large)
    matrix = design_matrix(dims, method=args.method, samples=args.samples, points=args.points,
                           seed=args.seed)
    config = SweepConfig(load_params(args.model), tuple(dims), path=args.path,
                         speed=args.speed, height=args.height, size=args.size,
                         duration=args.duration, control_period=args.control_period,
                         engine=args.engine, diverge_m=args.diverge)
    if args.ray is not None:
        from ..core.executor import connect_ray

        connect_ray(args.ray, args.workers)
    summary = run_sweep(config, matrix, args.output, seed=args.seed,
                        chunk_size=args.chunk_size, workers=args.workers, ray=args.ray,
                        show_progress=not args.quiet)
    if not args.quiet:
        print(f"wrote {args.output} ({summary['simulations']} simulations; "
              f"{summary['ran']} chunks run, {summary['skipped']} already done)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
