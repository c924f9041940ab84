"""Chunked, resumable sweep driver: chunk files, executor, merge, summary plot."""

from __future__ import annotations

import json
import sys
from functools import partial
from pathlib import Path

import numpy as np

from ..core.errors import InputError
from ..core.executor import TaskFailure, run_tasks
from ..core.files import atomic_write_bytes, atomic_write_text
from .run import OUTPUT_COLUMNS, SweepConfig, simulate_chunk, table_bytes

__all__ = ["SWEEP_SCHEMA", "chunk_folder", "run_sweep"]

SWEEP_SCHEMA = "quadsim.sweep/1"


def chunk_folder(out: Path) -> Path:
    """``sweep.parquet`` -> ``sweep.parquet.chunks/``."""
    return out.with_name(out.name + ".chunks")


def _chunk_path(folder: Path, k: int) -> Path:
    return folder / f"chunk_{k:06d}.parquet"


def _chunk_task(task, config: SweepConfig):
    _, rows = task
    return simulate_chunk(config, rows)


def _columns(config: SweepConfig, matrix: np.ndarray, start: int, result: dict) -> dict:
    cols = {"sim": np.arange(start, start + len(matrix), dtype=np.int64)}
    for j, dim in enumerate(config.dims):
        cols[dim.column] = matrix[:, j]
    cols.update({k: result[k] for k in OUTPUT_COLUMNS})
    return cols


def _manifest(folder: Path, description: dict) -> None:
    path = folder / "sweep.json"
    text = json.dumps(description, indent=2, sort_keys=True) + "\n"
    if path.exists():
        if path.read_text(encoding="utf-8") != text:
            raise InputError(f"{folder}: holds chunks of a different sweep (sweep.json "
                             "differs); delete the folder or choose another output")
        return
    atomic_write_text(path, text)


def run_sweep(config: SweepConfig, matrix: np.ndarray, out: str | Path, *, seed: int,
              chunk_size: int = 16, workers: int | None = None, ray: str | None = None,
              show_progress: bool = True) -> dict:
    """Run every simulation of ``matrix`` (N, D) in chunks; write ``out`` (Parquet, one row
    per simulation, ordered by ``sim``) and ``out`` with ``.png`` (summary plot).
    Returns ``{"simulations", "chunks", "ran", "skipped", "failed"}``; failed chunks (a
    worker died twice) are named in a one-line error after the others are saved."""
    out = Path(out)
    if not out.name.endswith(".parquet"):
        raise InputError(f"{out}: output name must end in .parquet")
    if chunk_size < 1:
        raise InputError(f"--chunk-size: must be >= 1, got {chunk_size}")
    folder = chunk_folder(out)
    description = {"schema": SWEEP_SCHEMA, "seed": seed, "chunk_size": chunk_size,
                   "simulations": len(matrix), **config.describe(),
                   "design_sha": _digest(matrix)}
    folder.mkdir(parents=True, exist_ok=True)
    _manifest(folder, description)
    starts = list(range(0, len(matrix), chunk_size))
    todo = [k for k, s in enumerate(starts) if not _chunk_path(folder, k).exists()]
    bar = None
    if show_progress:
        from tqdm import tqdm

        done = len(matrix) - sum(len(matrix[starts[k]:starts[k] + chunk_size]) for k in todo)
        bar = tqdm(total=len(matrix), initial=done, unit="sim", desc="sweep", file=sys.stderr,
                   dynamic_ncols=True)

    def save(i: int, result: dict) -> None:
        k = todo[i]
        rows = matrix[starts[k]:starts[k] + chunk_size]
        atomic_write_bytes(_chunk_path(folder, k),
                           table_bytes(_columns(config, rows, starts[k], result)))
        if bar is not None:
            bar.update(len(rows))

    tasks = [(starts[k], matrix[starts[k]:starts[k] + chunk_size]) for k in todo]
    try:
        results = run_tasks(partial(_chunk_task, config=config), tasks, workers=workers,
                            ray=ray, progress=save, keep_going=True,
                            labels=[f"chunk {k} (simulations {starts[k]}.."
                                    f"{min(starts[k] + chunk_size, len(matrix)) - 1})"
                                    for k in todo])
    finally:
        if bar is not None:
            bar.close()
    failed = [r.label for r in results if isinstance(r, TaskFailure)]
    if failed:
        raise InputError(f"{out}: worker died twice on {', '.join(failed)}; the other chunks "
                         f"are saved in {folder}; run again to retry only the missing ones")
    _merge(folder, out, len(starts))
    _plot(out, config)
    return {"simulations": len(matrix), "chunks": len(starts), "ran": len(todo),
            "skipped": len(starts) - len(todo), "failed": failed}


def _digest(matrix: np.ndarray) -> str:
    import hashlib

    return hashlib.sha256(np.ascontiguousarray(matrix, dtype="<f8").tobytes()).hexdigest()


def _merge(folder: Path, out: Path, count: int) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    tables = [pq.read_table(_chunk_path(folder, k)) for k in range(count)]
    table = pa.concat_tables(tables).combine_chunks()
    atomic_write_bytes(out, table_bytes({n: table.column(n).to_numpy()
                                         for n in table.column_names}))


def _plot(out: Path, config: SweepConfig) -> None:
    """One panel per swept input: RMS tracking error against it; diverged runs in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pyarrow.parquet as pq

    table = pq.read_table(out)
    swept = [d for d in config.dims if d.swept] or list(config.dims[:1])
    err = table.column("pos_err_rms_m").to_numpy()
    div = table.column("diverged").to_numpy(zero_copy_only=False).astype(bool)
    fig, axes = plt.subplots(1, max(len(swept), 1), figsize=(4 * max(len(swept), 1), 3.2),
                             squeeze=False)
    for ax, dim in zip(axes[0], swept):
        x = table.column(dim.column).to_numpy() if swept else np.arange(len(err))
        ax.scatter(x[~div], err[~div], s=8, label="tracked")
        ax.scatter(x[div], np.where(np.isfinite(err[div]), err[div], config.diverge_m), s=12,
                   c="red", marker="x", label="diverged")
        ax.set_xlabel(dim.column)
        ax.set_ylabel("RMS position error (m)")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"{config.params.name}, {config.path}, {len(err)} simulations, "
                 f"{int(div.sum())} diverged", fontsize=9)
    fig.tight_layout()
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
    plt.close(fig)
    atomic_write_bytes(out.with_suffix(".png"), buf.getvalue())
