"""Monte-Carlo and grid sweeps of effect magnitudes and initial states, closed loop.

``python -m quadsim.sweep`` flies one parameter set (``--model``) along one reference path
(:mod:`quadsim.sim.paths`) with the geometric controller (:mod:`quadsim.sim.controllers`), which
knows only the nominal vehicle, while each simulation's vehicle carries sampled effects
(:mod:`quadsim.effects`) and starts from a sampled offset of the path's start. Simulations run
in chunks, each chunk one batch through :func:`quadsim.sim.engines.simulate`, chunks spread over
local processes (``--workers N``) or Ray (``--ray local|HOST:PORT``) by
:mod:`quadsim.core.executor`.

Outputs: ``OUT.parquet``, one row per simulation (``sim`` index, the inputs ``effect.param``
and ``init.key`` in SI units, tracking error statistics and a ``diverged`` flag; see
:mod:`quadsim.sweep.run`), and ``OUT.png``, a summary plot. Chunk files go to
``OUT.parquet.chunks/`` as they finish (atomically): an interrupted sweep, rerun with the same
arguments, reruns only the missing chunks. Same arguments -> same bytes, whichever executor,
chunking excepted (the chunk size is part of the sweep's description).

Example::

    python -m quadsim.sweep --model physical --path hover --duration 5 \\
        --effect mass_offset:mass=0..0.2 --effect motor_lag:time_constant=0.01..0.05 \\
        --initial x=-0.2..0.2,roll=-0.3..0.3 --method mc --samples 256 --seed 0 \\
        -o out/sweep.parquet

    >>> from quadsim.sweep import SweepConfig, design_matrix, parse_effect_ranges, run_sweep
    >>> dims = parse_effect_ranges(["mass_offset:mass=0..0.2"])
    >>> matrix = design_matrix(dims, method="grid", samples=0, points=5, seed=0)
    >>> run_sweep(SweepConfig(load_params("physical"), tuple(dims)), matrix, "s.parquet", seed=0)
"""

from .design import Dimension, design_matrix, parse_effect_ranges, parse_initial_ranges
from .driver import SWEEP_SCHEMA, chunk_folder, run_sweep
from .run import OUTPUT_COLUMNS, SweepConfig, simulate_chunk

__all__ = ["OUTPUT_COLUMNS", "SWEEP_SCHEMA", "Dimension", "SweepConfig", "chunk_folder",
           "design_matrix", "parse_effect_ranges", "parse_initial_ranges", "run_sweep",
           "simulate_chunk"]
