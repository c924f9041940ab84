"""quadsim.sweep: error statistics on closed-form cases, resumption without rerunning
finished chunks, same bytes across executors, one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pyarrow", reason="the sweep writes Parquet (pyarrow, [parquet] extra)")
import pyarrow.parquet as pq

from quadsim.sweep import (
    SweepConfig,
    design_matrix,
    driver,
    parse_effect_ranges,
    parse_initial_ranges,
    run_sweep,
    simulate_chunk,
)
from quadsim.sweep.__main__ import main
from quadsim.vehicle.params import load_params


@pytest.fixture(scope="module")
def physical():
    return load_params("physical")


def test_initial_offset_is_the_largest_error_and_decays(physical):
    dims = tuple(parse_initial_ranges(["x=0..0.1"]))
    cfg = SweepConfig(physical, dims, path="hover", duration=2.0)
    out = simulate_chunk(cfg, np.array([[0.0], [0.1]]))
    # on the hover path at hover speed, no offset: nothing moves (float noise only)
    assert out["pos_err_max_m"][0] < 1e-9
    # the controller (damping 0.9) only reduces a 0.1 m offset: max = the start, exactly
    assert abs(out["pos_err_max_m"][1] - 0.1) < 1e-12
    assert out["pos_err_final_m"][1] < 0.02 and 0.0 < out["pos_err_rms_m"][1] < 0.1
    assert not out["diverged"].any()
    strict = SweepConfig(physical, dims, path="hover", duration=2.0, diverge_m=0.05)
    assert simulate_chunk(strict, np.array([[0.0], [0.1]]))["diverged"].tolist() == [False, True]


def test_grid_and_mc_designs():
    dims = parse_effect_ranges(["mass_offset:mass=0..0.2"]) + parse_initial_ranges(["z=0.5"])
    grid = design_matrix(dims, method="grid", samples=0, points=3, seed=0)
    assert grid.tolist() == [[0.0, 0.5], [0.1, 0.5], [0.2, 0.5]]
    mc = design_matrix(dims, method="mc", samples=100, points=0, seed=1)
    assert mc.shape == (100, 2) and (mc[:, 0] >= 0).all() and (mc[:, 0] <= 0.2).all()
    assert (mc[:, 1] == 0.5).all()
    assert np.array_equal(mc, design_matrix(dims, method="mc", samples=100, points=0, seed=1))


def test_resumes_only_missing_chunks_same_bytes(physical, tmp_path, monkeypatch):
    dims = tuple(parse_effect_ranges(["mass_offset:mass=0..0.1"]) +
                 parse_initial_ranges(["x=-0.1..0.1"]))
    cfg = SweepConfig(physical, dims, path="hover", duration=0.5)
    matrix = design_matrix(list(dims), method="mc", samples=6, points=0, seed=3)
    clean = tmp_path / "clean.parquet"
    run_sweep(cfg, matrix, clean, seed=3, chunk_size=2, workers=1, show_progress=False)

    calls = []
    real = driver.simulate_chunk

    def interrupted(config, rows):
        calls.append(len(calls))
        if len(calls) == 3:
            raise KeyboardInterrupt                  # killed during the third chunk
        return real(config, rows)

    out = tmp_path / "resumed.parquet"
    monkeypatch.setattr(driver, "simulate_chunk", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(cfg, matrix, out, seed=3, chunk_size=2, workers=1, show_progress=False)
    chunks = sorted(p.name for p in driver.chunk_folder(out).glob("chunk_*"))
    assert chunks == ["chunk_000000.parquet", "chunk_000001.parquet"] and not out.exists()
    calls.clear()
    monkeypatch.setattr(driver, "simulate_chunk", lambda c, r: (calls.append(1), real(c, r))[1])
    summary = run_sweep(cfg, matrix, out, seed=3, chunk_size=2, workers=1, show_progress=False)
    assert len(calls) == 1 and summary["ran"] == 1 and summary["skipped"] == 2
    assert out.read_bytes() == clean.read_bytes()
    table = pq.read_table(out)
    assert table.column("sim").to_pylist() == list(range(6))
    assert np.array_equal(table.column("mass_offset.mass").to_numpy(), matrix[:, 0])


def test_cli_processes_same_bytes_and_bad_input(tmp_path, capsys):
    args = ["--model", "physical", "--path", "hover", "--duration", "0.5", "--quiet",
            "--effect", "mass_offset:mass=0..0.1", "--samples", "4", "--chunk-size", "2"]
    one, two = tmp_path / "one.parquet", tmp_path / "two.parquet"
    assert main([*args, "--workers", "1", "-o", str(one)]) == 0
    assert main([*args, "--workers", "2", "-o", str(two)]) == 0
    assert capsys.readouterr().out == ""          # --quiet: no bar, no summary line
    assert one.read_bytes() == two.read_bytes()
    assert one.with_suffix(".png").read_bytes()[:4] == b"\x89PNG"
    # a different sweep into the same output never mixes with the old chunks
    assert main([*args, "--seed", "1", "--workers", "1", "-o", str(one)]) == 2
    assert "holds chunks of a different sweep" in capsys.readouterr().err
    for bad, message in ((["--effect", "motor_lag:time_constant=0.2..0"], "runs backwards"),
                         (["--effect", "motor_lag:time_constant=0..99"], "plausible range"),
                         (["--initial", "q=1"], "unknown key 'q'"),
                         (["--workers", "0"], "--workers: must be >= 1")):
        assert main([*args, *bad, "-o", str(tmp_path / "bad.parquet")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err
    assert not (tmp_path / "bad.parquet").exists()
