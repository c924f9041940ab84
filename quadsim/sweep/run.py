"""Run a sweep: chunks of simulations, batched through :func:`quadsim.sim.engines.simulate`.

Each simulation flies the reference path in closed loop with the geometric controller, which
knows only the nominal parameter set, while the simulated vehicle carries the row's effects
and starts from the path's start plus the row's initial offsets (see :mod:`.design`). Tracking
error ``e(t) = |p(t) - p_ref(t)|`` (m) at the control-period samples gives one row:

* ``pos_err_rms_m``, ``pos_err_max_m``, ``pos_err_final_m`` (m), ``tilt_max_rad`` (rad,
  angle of the body z axis from the world z axis);
* ``diverged``: the simulation raised (NaN, MuJoCo warning), or ``pos_err_max_m`` exceeded
  the divergence threshold (m); the error columns are NaN when it raised.

A chunk is one batch (``simulate`` with one EffectSet and one initial state per row). If the
batch raises, its rows are rerun one by one so that only the simulations that fail are
flagged. Chunk results are Parquet files written atomically in ``<out>.chunks/``; a run skips
chunks whose file exists (resumption), and the folder's ``sweep.json`` (the full input
description) must match, so that a changed sweep never mixes with old chunks.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np

from ..core.errors import QuadsimError
from ..core.frames import euler_to_quat, quat_multiply, quat_to_rotmat
from ..effects import EffectSet, make_effect
from ..sim.controllers import GeometricController
from ..sim.engines import simulate
from ..sim.paths import make_reference
from ..vehicle.params import VehicleParams
from .design import Dimension

__all__ = ["OUTPUT_COLUMNS", "SweepConfig", "simulate_chunk", "table_bytes"]

OUTPUT_COLUMNS = ("pos_err_rms_m", "pos_err_max_m", "pos_err_final_m", "tilt_max_rad",
                  "diverged")


@dataclass(frozen=True)
class SweepConfig:
    """Everything a chunk needs (picklable; shipped to workers)."""

    params: VehicleParams
    dims: tuple[Dimension, ...]
    path: str = "figure8"
    speed: float = 1.0          # m/s
    height: float = 1.0         # m
    size: float = 1.0           # m
    duration: float = 5.0       # s
    control_period: float = 0.01  # s
    engine: str = "mujoco"
    diverge_m: float = 2.0      # m

    def describe(self) -> dict:
        return {"model": self.params.name, "path": self.path, "speed_m_s": self.speed,
                "height_m": self.height, "size_m": self.size, "duration_s": self.duration,
                "control_period_s": self.control_period, "engine": self.engine,
                "diverge_m": self.diverge_m,
                "dims": [[d.column, d.low, d.high] for d in self.dims]}


def _row_inputs(config: SweepConfig, row: np.ndarray, start: dict):
    values: dict[str, dict[str, float]] = {}
    offset = dict.fromkeys(("x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw"), 0.0)
    for dim, value in zip(config.dims, row):
        head, _, tail = dim.column.partition(".")
        if head == "init":
            offset[tail] = float(value)
        else:
            values.setdefault(head, {})
            if tail:
                values[head][tail] = float(value)
    effects = EffectSet(tuple(make_effect(name, **v) for name, v in values.items()))
    position = start["position"] + [offset["x"], offset["y"], offset["z"]]
    velocity = start["velocity"] + [offset["vx"], offset["vy"], offset["vz"]]
    quat = quat_multiply(start["quat"], euler_to_quat(
        np.array([offset["roll"], offset["pitch"], offset["yaw"]])))
    return effects, position, velocity, quat


def _run(config: SweepConfig, rows: np.ndarray) -> dict[str, np.ndarray]:
    reference = make_reference(config.path, speed=config.speed, height=config.height,
                               size=config.size, duration=config.duration)
    controller = GeometricController(config.params, reference)
    start = controller.initial_state()
    inputs = [_row_inputs(config, r, start) for r in rows]
    initial = {"position": np.array([i[1] for i in inputs]),
               "velocity": np.array([i[2] for i in inputs]),
               "quat": np.array([i[3] for i in inputs]),
               "body_rate": np.zeros((len(rows), 3))}
    traj = simulate(config.params, engine=config.engine, initial=initial, controller=controller,
                    duration=config.duration, control_period=config.control_period,
                    effects=[i[0] for i in inputs], nthread=1, batch=len(rows))
    ref = reference(traj.t)
    error = np.linalg.norm(traj.position - ref.position[None], axis=-1)      # (B, N) m
    tilt = np.arccos(np.clip(quat_to_rotmat(traj.quat)[..., 2, 2], -1.0, 1.0))
    out = {"pos_err_rms_m": np.sqrt(np.mean(error**2, axis=1)),
           "pos_err_max_m": error.max(axis=1), "pos_err_final_m": error[:, -1],
           "tilt_max_rad": tilt.max(axis=1)}
    out["diverged"] = ~np.isfinite(out["pos_err_max_m"]) | (out["pos_err_max_m"] > config.diverge_m)
    return out


def simulate_chunk(config: SweepConfig, rows: np.ndarray) -> dict[str, np.ndarray]:
    """Output columns (see the module docstring) for the simulations ``rows`` (B, D)."""
    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    try:
        return _run(config, rows)
    except QuadsimError:
        if len(rows) == 1:
            nan = np.full(1, np.nan)
            return {"pos_err_rms_m": nan, "pos_err_max_m": nan, "pos_err_final_m": nan,
                    "tilt_max_rad": nan, "diverged": np.ones(1, bool)}
    parts = [simulate_chunk(config, r[None]) for r in rows]   # find the failing ones
    return {k: np.concatenate([p[k] for p in parts]) for k in OUTPUT_COLUMNS}


def table_bytes(columns: dict[str, np.ndarray]) -> bytes:
    """Parquet bytes (zstd, no pandas metadata) of equal-length numpy columns, in order."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({k: pa.array(v) for k, v in columns.items()})
    sink = io.BytesIO()
    pq.write_table(table, sink, compression="zstd")
    return sink.getvalue()
