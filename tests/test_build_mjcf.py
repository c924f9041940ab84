"""The generated MJCF: compiles, carries the CAD mass properties, and its rotor actuators
give the closed-form wrench (hover = m g and no torque; pure yaw = no roll/pitch)."""

import subprocess
import sys

import mujoco
import numpy as np
import pytest
from test_cad import REPO, generator, layout, write_cad

from quadsim.build_mjcf import main
from quadsim.core.errors import InputError
from quadsim.sim import model as sim_model
from quadsim.sim.model import build_model, write_model
from quadsim.vehicle.params import hover_speed
from quadsim.vehicle.rotors import allocation_matrix, mixer


@pytest.fixture(scope="module")
def testbed(tmp_path_factory):
    out = tmp_path_factory.mktemp("models") / "testbed.xml"
    built = build_model(REPO / "cad", output=out)
    write_model(built, out)
    return built, mujoco.MjModel.from_xml_path(str(out))


def body_inertia(model, body):
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, model.body_iquat[body])
    rotation = rotation.reshape(3, 3)
    return rotation @ np.diag(model.body_inertia[body]) @ rotation.T


def actuator_wrench(model, ctrl):
    """Generalised actuator force on the free joint at identity attitude: force (world =
    body) and torque about the body origin."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    data.ctrl[:] = ctrl
    mujoco.mj_forward(model, data)
    return data.qfrc_actuator[:3].copy(), data.qfrc_actuator[3:6].copy(), data


def test_mjcf_body_carries_the_cad_mass_properties(testbed):
    built, model = testbed
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "vehicle")
    props = built.mass_properties
    assert model.body_mass[body] == pytest.approx(props.mass, rel=1e-6)
    np.testing.assert_allclose(model.body_ipos[body], props.com, atol=1e-6 * 0.2)
    inertia = body_inertia(model, body)
    assert np.linalg.norm(inertia - props.inertia) / np.linalg.norm(props.inertia) < 1e-6
    # visual meshes add no mass: the body has exactly the written inertial
    assert model.nmesh == len(built.assembly.parts)
    assert np.all(model.geom_rgba is not None)


def test_hover_keyframe_gives_weight_and_no_torque(testbed):
    built, model = testbed
    force, torque, _ = actuator_wrench(model, model.key_ctrl[0])
    weight = built.params.mass * built.params.gravity
    np.testing.assert_allclose(force, [0, 0, weight], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(torque, 0, atol=1e-9)
    np.testing.assert_allclose(np.sqrt(model.key_ctrl[0]), hover_speed(built.params), rtol=1e-12)


def test_pure_yaw_command_gives_no_roll_or_pitch_torque(testbed):
    built, model = testbed
    p = built.params
    yaw_torque = 0.05
    omega2 = mixer(p) @ [p.weight, 0.0, 0.0, yaw_torque]
    force, torque, data = actuator_wrench(model, omega2)
    np.testing.assert_allclose(torque[:2], 0, atol=1e-10)
    assert torque[2] == pytest.approx(yaw_torque, rel=1e-9)
    assert force[2] == pytest.approx(p.weight, rel=1e-9)
    # the actuator's scalar force is its control Omega^2 (rad^2/s^2); the gear makes b Omega^2
    np.testing.assert_allclose(data.actuator_force, omega2, rtol=1e-12)


def test_every_actuator_matches_the_allocation_matrix(testbed):
    built, model = testbed
    columns = allocation_matrix(built.params, about=np.zeros(3))
    for i in range(model.nu):
        ctrl = np.zeros(model.nu)
        ctrl[i] = 1e5
        force, torque, _ = actuator_wrench(model, ctrl)
        np.testing.assert_allclose(np.r_[force, torque], 1e5 * columns[:, i], rtol=1e-9,
                                   atol=1e-12)


def test_mesh_paths_are_relative_and_scaled(testbed):
    built, _ = testbed
    assert 'scale="0.001 0.001 0.001"' in built.xml
    assert f'file="{REPO}' not in built.xml


@pytest.mark.parametrize("yaws,spins", [
    ([45, -45, -135, 135], ["ccw", "cw", "ccw", "cw"]),
    ([0, 60, 120, 180, 240, 300], ["ccw", "cw"] * 3),
])
def test_x_layout_and_hexarotor_build_and_hover(tmp_path, yaws, spins):
    folder = layout(200, yaws, spins, tmp_path / "cad")
    out = tmp_path / "out" / "v.xml"
    built = build_model(folder, output=out)
    write_model(built, out)
    model = mujoco.MjModel.from_xml_path(str(out))
    assert model.nu == len(yaws)
    force, torque, _ = actuator_wrench(model, model.key_ctrl[0])
    np.testing.assert_allclose(force, [0, 0, built.params.weight], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(torque, 0, atol=1e-9)


def test_inertial_from_params_is_said_and_written(tmp_path):
    built = build_model(REPO / "cad", output=tmp_path / "x.xml", inertial="params")
    assert "NOT used" in built.inertial_note
    assert built.params.mass == pytest.approx(0.837667)
    assert built.params.inertia[0, 0] != pytest.approx(built.mass_properties.inertia[0, 0])


# ----------------------------------------------------------------------------- bad input

GEN = generator()
GOOD = dict(name="block", shape=GEN.box(100, 50, 20), mass=0.2,
            placements=[("1", [0, 0, 0], [0, 0, 0])])
ROTOR = dict(name="1", part="block", placement="1", spin="cw")


def bad_cases():
    v, f = GEN.box(100, 50, 20)
    flipped = f.copy()
    flipped[0] = flipped[0, ::-1]
    return {
        "not watertight": ([dict(GOOD, shape=(v, f[:-2]))], [ROTOR], "", "is not watertight"),
        "inconsistent winding": ([dict(GOOD, shape=(v, flipped))], [ROTOR], "",
                                 "inconsistently wound"),
        "inside out": ([dict(GOOD, shape=(v, f[:, ::-1]))], [ROTOR], "", "inside out"),
        "mm/m slip": ([dict(GOOD, shape=(v / 1000, f))], [ROTOR], "",
                      (r"part\[0\] \(block\).mesh: block.stl \(read in mesh_unit = \"mm\", "
                       r"scale 0.001 m per unit\): implied density .* drawn in m while")),
        "missing mesh": ([dict(GOOD, mesh="nope.stl")], [ROTOR], "",
                         r"part\[0\] \(block\).mesh: mesh file 'nope.stl' not found"),
        "unknown key": ([GOOD], [dict(ROTOR, speed=3)], "",
                        r"rotor\[0\]: unknown key\(s\) \['speed'\]; valid keys: axis, name, part"),
        "escaping path": ([dict(GOOD, mesh="../block.stl")], [ROTOR], "",
                          "escapes the CAD folder"),
        "zero mass": ([dict(GOOD, mass=0.0)], [ROTOR], "", r"mass: must be a finite number > 0"),
        "negative mass": ([dict(GOOD, mass=-1.0)], [ROTOR], "", r"must be a finite number > 0"),
        "NaN mass": ([dict(GOOD, mass_line='mass = { value = nan, unit = "kg", source = "x" }')],
                     [ROTOR], "", r"must be a finite number > 0, got nan"),
        "zero density": ([dict(GOOD, mass_line='density = { value = 0, unit = "kg/m^3", '
                                               'source = "x" }')], [ROTOR], "",
                         r"density: must be a finite number > 0"),
        "empty assembly": ([], [ROTOR], "", r"part: empty assembly"),
        "mm/m slip, density given": ([dict(GOOD, shape=(v / 1000, f), mass_line=(
            'density = { value = 2700.0, unit = "kg/m^3", source = "x" }'))], [ROTOR], "",
            (r"\(block\).mesh: block.stl \(read in mesh_unit = \"mm\", scale 0.001 m per "
             r"unit\): largest extent 0.0001 m is outside .* drawn in m while mesh_unit says mm")),
        "repeated rotor": ([GOOD], [ROTOR, ROTOR], "", r"rotor: rotor names repeat"),
        "no rotors": ([GOOD], [], "", r"rotor: no rotors"),
    }


@pytest.mark.parametrize("case", list(bad_cases()))
def test_bad_input_is_rejected_naming_file_and_field(tmp_path, case):
    parts, rotors, extra, message = bad_cases()[case]
    folder = write_cad(tmp_path / "cad", parts, rotors, extra)
    if case == "escaping path":
        (tmp_path / "block.stl").write_bytes(GEN.stl_bytes(*GOOD["shape"]))
    out = tmp_path / "out.xml"
    with pytest.raises(InputError, match=r"vehicle.toml: .*" + message):
        write_model(build_model(folder, output=out), out)
    assert not out.exists()


def test_cli_bad_input_one_line_exit_2_nothing_written(tmp_path):
    folder = write_cad(tmp_path / "cad", [dict(GOOD, mesh="nope.stl")], [ROTOR])
    out = tmp_path / "models" / "v.xml"
    run = subprocess.run([sys.executable, "-m", "quadsim.build_mjcf", str(folder), "-o", str(out)],
                         capture_output=True, text=True, cwd=REPO)
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and run.stderr.startswith("error: ")
    assert "vehicle.toml: part[0] (block).mesh" in run.stderr and "Traceback" not in run.stderr
    assert not out.exists() and not out.parent.exists()


def test_cli_writes_model_and_prints_parts_table(tmp_path, capsys):
    out = tmp_path / "testbed.xml"
    assert main([str(REPO / "cad"), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "TOTAL (about CoM)" in printed and "837.667" in printed
    model = mujoco.MjModel.from_xml_path(str(out))
    assert model.nu == 4


def test_mesh_in_other_units_than_declared_is_caught(tmp_path):
    # mm mesh declared as metres: a 0.1 m part becomes 100 m, implied density ~1e-9 of real
    folder = write_cad(tmp_path / "cad", [GOOD], [ROTOR], mesh_unit="m")
    with pytest.raises(InputError, match=r"implied density .* drawn in mm while mesh_unit says m"):
        build_model(folder, output=tmp_path / "x.xml")


def test_mesh_over_mujoco_stl_limit_is_refused_before_writing(tmp_path, monkeypatch):
    # The real limit is 200,000 triangles per STL; a small stand-in keeps the test fast.
    monkeypatch.setattr(sim_model, "MUJOCO_STL_FACE_LIMIT", 200)
    big = dict(GOOD, shape=GEN.cylinder(50, 20, segments=64))  # 252 triangles
    folder = write_cad(tmp_path / "cad", [big], [ROTOR])
    with pytest.raises(InputError, match=r"block.stl has 252 triangles; MuJoCo reads at most 200"):
        build_model(folder, output=tmp_path / "x.xml")
    assert not (tmp_path / "x.xml").exists()


def test_parameter_set_can_take_mass_properties_and_rotors_from_cad(tmp_path):
    from quadsim.cad.assembly import load_assembly
    from quadsim.cad.massprops import vehicle_mass_properties
    from quadsim.vehicle.params import load_params

    cad = REPO / "cad"
    q = 'unit = "{}", source = "test" }}'
    (tmp_path / "cadset.toml").write_text("\n".join([
        'schema = "quadsim.vehicle.params/1"', 'name = "cadset"', "[body]",
        f'from_cad = {{ path = "{cad}", source = "cad/ meshes" }}', "[rotors]",
        "thrust_factor = { value = 1e-5, " + q.format("N s^2/rad^2"),
        "drag_factor = { value = 1e-7, " + q.format("N m s^2/rad^2"),
        "max_speed = { value = 700.0, " + q.format("rad/s"), "[rotor_layout]",
        f'from_cad = {{ path = "{cad}", source = "cad/ manifest" }}']) + "\n")
    p = load_params(tmp_path / "cadset.toml")
    props = vehicle_mass_properties(load_assembly(cad))
    assert p.mass == props.mass and np.array_equal(p.inertia, props.inertia)
    assert [r.name for r in p.rotors] == ["1", "2", "3", "4"] and p.rotors[1].spin == -1


def test_cli_hull_fallback_warns_in_one_line_and_builds(tmp_path, capsys):
    v, f = GEN.box(100, 50, 20)
    folder = write_cad(tmp_path / "cad", [dict(GOOD, shape=(v, f[:-1]))], [ROTOR])
    out = tmp_path / "v.xml"
    assert main([str(folder), "-o", str(out)]) == 2
    assert not out.exists()
    assert "not watertight" in capsys.readouterr().err
    assert main([str(folder), "-o", str(out), "--hull"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("warning: ") and "convex hull" in err[0]
    assert mujoco.MjModel.from_xml_path(str(out)).body_mass[1] == pytest.approx(0.2)
