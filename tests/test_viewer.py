"""Viewer: recordings written headless and read back with rerun's own reader (entities, time
range, sample counts, logged values), error paths, lazy import."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from quadsim.core.errors import InputError
from quadsim.core.frames import euler_to_quat
from quadsim.vehicle.params import load_params
from quadsim.vehicle.state import STATE12_NAMES, Trajectory
from quadsim.viewer import (
    check_output_path,
    recording_bytes,
    rotor_thrust,
    save_recording,
    state_residuals,
    try_save_recording,
)

REPO = Path(__file__).resolve().parent.parent


def read_recording(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """entity path -> {"time": (N,) s or absent if static, component: flat values}."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    out: dict[str, dict[str, np.ndarray]] = {}
    for chunk in RrdReader(str(path)).store().stream():
        batch = chunk.to_record_batch()
        entry = out.setdefault(chunk.entity_path.lstrip("/"), {})
        for name in batch.schema.names[1:]:
            column = batch.column(name)
            if name == "time":
                values = column.cast(pa.int64()).to_numpy() * 1e-9
            elif not pa.types.is_list(column.type):
                values = column.to_numpy(zero_copy_only=False)  # another index (sample)
            else:
                values = column.flatten()
                while pa.types.is_list(values.type) or pa.types.is_fixed_size_list(values.type):
                    values = values.flatten()
                values = values.to_numpy(zero_copy_only=False)
            entry[name] = np.concatenate([entry[name], values]) if name in entry else values
    return out


def synthetic(params, *, n=201, dt=0.01, offset=(0.0, 0.0, 0.0), yaw_rate=0.3,
              engine="mujoco") -> Trajectory:
    """A closed-form flight: circle in x-y, slow climb, wobble, spinning yaw."""
    t = np.arange(n) * dt
    position = np.stack([np.sin(t), np.cos(t) - 1.0, 1.0 + 0.1 * t], -1) + offset
    euler = np.stack([0.1 * np.sin(3 * t), 0.1 * np.cos(3 * t), yaw_rate * t], -1)
    speed = 600.0 + 20.0 * np.sin(t)[:, None] * np.array([1.0, -1.0, 1.0, -1.0])
    return Trajectory(t, position, np.gradient(position, t, axis=0), euler_to_quat(euler),
                      np.zeros((n, 3)), speed, speed + 1.0, engine=engine)


@pytest.fixture(scope="module")
def params():
    return load_params("physical")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, params):
    """One recording with two engines and a measured flight (model = measured + 0.1 m in x)."""
    path = tmp_path_factory.mktemp("rec") / "flight.rrd"
    measured = synthetic(params, engine="log")
    trajectories = {"mujoco": synthetic(params, offset=(0.1, 0.0, 0.0)),
                    "analytic": synthetic(params, offset=(0.0, -0.2, 0.0))}
    written = save_recording(path, params=params, trajectories=trajectories, measured=measured,
                             residuals={"wrench": np.ones((201, 2))}, title="test flight")
    return written, read_recording(path), trajectories, measured


def test_recording_verifies_with_rerun_cli(recorded):
    path = recorded[0]
    result = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(path)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr


def test_expected_entities_time_range_and_counts(recorded):
    _, data, _, _ = recorded
    for key in ("mujoco", "analytic", "measured"):
        pose = data[f"world/{key}/vehicle"]
        assert len(pose["time"]) == 201
        assert pose["time"][0] == pytest.approx(0.0, abs=1e-9)
        assert pose["time"][-1] == pytest.approx(2.0, abs=1e-8)
        np.testing.assert_array_equal(pose["sample"], np.arange(201))
        assert "LineStrips3D:strips" in data[f"world/{key}/path"]
        for name in STATE12_NAMES:
            assert len(data[f"states/{name}/{key}"]["Scalars:scalars"]) == 201
        for i in range(1, 5):
            assert len(data[f"rotors/speed_{i}/{key}"]["Scalars:scalars"]) == 201
            assert len(data[f"rotors/thrust_{i}/{key}"]["Scalars:scalars"]) == 201
        assert any(p.startswith(f"world/{key}/vehicle/body/") for p in data)
    for key in ("mujoco", "analytic"):
        for name in STATE12_NAMES:
            assert len(data[f"residuals/{name}/{key}"]["time"]) == 201
        assert len(data[f"rotors/command_1/{key}"]["Scalars:scalars"]) == 201
    assert "residuals/x/measured" not in data
    assert "world/axes" in data and "world/ground" in data
    assert len(data["residuals/wrench/0"]["time"]) == 201


def test_logged_values_match_the_trajectories(recorded, params):
    _, data, trajectories, measured = recorded
    mujoco = trajectories["mujoco"]
    np.testing.assert_allclose(data["states/z/mujoco"]["Scalars:scalars"], mujoco.position[:, 2],
                               rtol=0, atol=1e-12)
    # rerun stores quaternions xyzw (float32); ours are wxyz.
    quat = data["world/mujoco/vehicle"]["Transform3D:quaternion"].reshape(-1, 4)
    np.testing.assert_allclose(quat, mujoco.quat[:, [1, 2, 3, 0]], atol=1e-6)
    # Residuals: model minus measured, exactly the offsets put in.
    np.testing.assert_allclose(data["residuals/x/mujoco"]["Scalars:scalars"], 0.1, atol=1e-12)
    np.testing.assert_allclose(data["residuals/y/analytic"]["Scalars:scalars"], -0.2,
                               atol=1e-12)
    np.testing.assert_allclose(data["residuals/yaw/mujoco"]["Scalars:scalars"], 0.0, atol=1e-9)


def test_thrust_arrows_are_b_omega_squared_along_the_axes(recorded, params):
    _, data, trajectories, _ = recorded
    arrows = data["world/mujoco/vehicle/thrust"]
    vectors = arrows["Arrows3D:vectors"].reshape(201, 4, 3)
    assert len(arrows["time"]) == 201
    origins = arrows["Arrows3D:origins"].reshape(4, 3)  # static: the hubs, body frame
    np.testing.assert_allclose(origins, params.rotor_positions, atol=1e-6)
    thrust = rotor_thrust(params, trajectories["mujoco"].rotor_speed)
    lengths = np.linalg.norm(vectors, axis=-1)
    scale = lengths / thrust  # m per N, one constant for the whole recording
    np.testing.assert_allclose(scale, scale[0, 0], rtol=1e-6)
    hover_thrust = params.weight / 4
    arm = np.linalg.norm(params.rotor_positions[0])
    assert scale[0, 0] * hover_thrust == pytest.approx(0.5 * arm, rel=1e-6)
    np.testing.assert_allclose(vectors / lengths[..., None],
                               np.broadcast_to(params.rotor_axes, vectors.shape), atol=1e-6)


def test_batched_members_each_get_their_own_key(tmp_path, params):
    single = synthetic(params, n=11)
    batch = Trajectory(single.t, *(np.stack([a, a + 1.0]) for a in (
        single.position, single.velocity)), np.stack([single.quat] * 2),
        np.stack([single.body_rate] * 2), np.stack([single.rotor_speed] * 2))
    path = save_recording(tmp_path / "b.rrd", params=params, trajectories={"mujoco": batch},
                          batch_index="all")
    data = read_recording(path)
    np.testing.assert_allclose(data["states/x/mujoco_1"]["Scalars:scalars"],
                               batch.position[1, :, 0], atol=1e-12)
    assert "states/x/mujoco_0" in data
    first_only = read_recording(save_recording(tmp_path / "c.rrd", params=params,
                                               trajectories={"mujoco": batch}))
    assert "states/x/mujoco" in first_only and "states/x/mujoco_1" not in first_only


def test_same_inputs_same_content(tmp_path, params):
    paths = []
    for name in ("a.rrd", "b.rrd"):
        paths.append(save_recording(tmp_path / name, params=params,
                                    trajectories={"mujoco": synthetic(params, n=21)}))
    result = subprocess.run([sys.executable, "-m", "rerun", "rrd", "compare", "--unordered",
                             *map(str, paths)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr


def test_yaw_residual_wraps_across_pi(params):
    model = synthetic(params, n=3, yaw_rate=0.0)
    measured = synthetic(params, n=3, yaw_rate=0.0)
    model = Trajectory(model.t, model.position, model.velocity,
                       euler_to_quat(np.tile([0.0, 0.0, 3.10], (3, 1))), model.body_rate,
                       model.rotor_speed)
    measured = Trajectory(measured.t, measured.position, measured.velocity,
                          euler_to_quat(np.tile([0.0, 0.0, -3.10], (3, 1))),
                          measured.body_rate, measured.rotor_speed)
    residual = state_residuals(model, measured)
    np.testing.assert_allclose(residual[:, 8], 6.20 - 2 * np.pi, atol=1e-9)


def test_unwritable_paths_give_one_line_errors(tmp_path, params, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    traj = synthetic(params, n=5)
    for bad, message in ((blocker / "out.rrd", "is not a directory"),
                         (tmp_path, "must end in .rrd"),
                         (tmp_path / "dir.rrd", "is a directory")):
        if bad.name == "dir.rrd":
            bad.mkdir()
        with pytest.raises(InputError, match=message):
            save_recording(bad, params=params, trajectories={"mujoco": traj})
        assert try_save_recording(bad, params=params, trajectories={"mujoco": traj}) is None
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir.rrd", "file"]


def test_corrupted_existing_file_is_replaced_whole(tmp_path, params):
    path = tmp_path / "old.rrd"
    path.write_bytes(b"\x00garbage")
    save_recording(path, params=params, trajectories={"mujoco": synthetic(params, n=5)})
    assert len(read_recording(path)["states/x/mujoco"]["time"]) == 5
    assert [p.name for p in tmp_path.iterdir()] == ["old.rrd"]  # no temporary left behind


def test_bad_inputs_are_rejected(tmp_path, params):
    traj = synthetic(params, n=5)
    three_rotors = Trajectory(traj.t, traj.position, traj.velocity, traj.quat, traj.body_rate,
                              traj.rotor_speed[:, :3])
    with pytest.raises(InputError, match="3 rotor speeds"):
        recording_bytes(params=params, trajectories={"mujoco": three_rotors})
    with pytest.raises(InputError, match="nothing to log"):
        recording_bytes(params=params, trajectories={})
    with pytest.raises(InputError, match="201 samples"):
        recording_bytes(params=params, trajectories={"mujoco": traj},
                        residuals={"wrench": np.zeros(201)})
    with pytest.raises(InputError, match="does not exist"):  # outputs never create folders
        check_output_path(tmp_path / "new" / "deeper" / "ok.rrd")
    assert not (tmp_path / "new").exists()
    check_output_path(tmp_path / "ok.rrd")


def test_spawn_headless_says_how_to_view(tmp_path, params, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    path = save_recording(tmp_path / "s.rrd", params=params,
                          trajectories={"mujoco": synthetic(params, n=5)}, spawn=True)
    assert path.is_file()
    assert "no display" in capsys.readouterr().err


def test_engines_do_not_import_rerun():
    code = ("import sys, quadsim.sim.engines, quadsim.viewer, quadsim.view; "
            "print('rerun' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            cwd=REPO, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "False"


def test_cad_assembly_meshes_are_logged(tmp_path):
    from quadsim.viewer import assembly_for, vehicle_shapes

    params = load_params("computational")
    assembly = assembly_for(params)
    assert assembly is not None
    shapes = vehicle_shapes(params, assembly)
    assert len(shapes) == sum(len(part.placements) for part in assembly.parts)
    data = read_recording(save_recording(tmp_path / "cad.rrd", params=params,
                                         trajectories={"mujoco": synthetic(params, n=5)},
                                         assembly=assembly))
    logged = [p for p in data if p.startswith("world/mujoco/vehicle/body/")]
    assert len(logged) == len(shapes)


def test_caller_residuals_with_labels_and_tab(tmp_path, params):
    traj = synthetic(params, n=50)
    residuals = {"residual wrench": (traj.t, np.arange(100.0).reshape(50, 2),
                                     ["Fx (N)", "Mz [N m]"])}
    path = save_recording(tmp_path / "r.rrd", params=params, trajectories={"log": traj},
                          residuals=residuals, tab="residuals")
    data = read_recording(path)
    np.testing.assert_allclose(data["residuals/residual_wrench/Mz_N_m"]["Scalars:scalars"],
                               np.arange(1.0, 100.0, 2.0))
    assert data["residuals/residual_wrench/Fx_N"]["SeriesLines:names"][0] == "Fx (N)"
    with pytest.raises(InputError, match="plot tab 'residuals' not in this recording"):
        recording_bytes(params=params, trajectories={"log": traj}, tab="residuals")
