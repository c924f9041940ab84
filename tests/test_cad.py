"""The testbed generator, the manifest loader and layouts other than the report's '+'.

Also holds small helpers (``generator``, ``write_cad``) that the other CAD test files import.
"""

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from quadsim.cad.assembly import load_assembly
from quadsim.cad.massprops import vehicle_mass_properties
from quadsim.vehicle.params import Rotor, load_params
from quadsim.vehicle.rotors import allocation_matrix

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "scripts" / "make_testbed_cad.py"


def generator():
    """The generator script as a module (its mesh primitives are used by the tests)."""
    spec = importlib.util.spec_from_file_location("make_testbed_cad", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_cad(folder: Path, parts: list[dict], rotors: list[dict], extra: str = "",
              mesh_unit: str = "mm") -> Path:
    """Write a CAD folder: ``parts`` = dicts with name, shape (vertices, faces) in mesh units,
    mass (kg), placements [(name, position_m, rpy_deg)]; ``rotors`` = dicts of rotor keys."""
    gen = generator()
    folder.mkdir(parents=True, exist_ok=True)
    lines = ['schema = "quadsim.cad/1"', 'name = "test"', f'mesh_unit = "{mesh_unit}"', extra]
    for p in parts:
        if "shape" in p:
            (folder / f"{p['name']}.stl").write_bytes(gen.stl_bytes(*p["shape"]))
        mesh = p.get("mesh", p["name"] + ".stl")
        mass = p.get("mass_line") or f'mass = {{ value = {p["mass"]!r}, unit = "kg", source = "" }}'
        lines += ["[[part]]", f'name = "{p["name"]}"', f'mesh = "{mesh}"', mass]
        for name, position, rpy in p["placements"]:
            lines += ["[[part.placement]]", f'name = "{name}"',
                      f"position_m = {[float(v) for v in position]}",
                      f"rpy_deg = {[float(v) for v in rpy]}"]
    for r in rotors:
        lines.append("[[rotor]]")
        lines += [f"{k} = {v!r}".replace("'", '"') for k, v in r.items()]
    (folder / "vehicle.toml").write_text("\n".join(lines) + "\n")
    return folder


def layout(arm_mm: float, yaws_deg: list[float], spins: list[str], folder: Path) -> Path:
    """A vehicle with a central box and one motor cylinder + prop box per arm yaw."""
    gen = generator()
    arm = arm_mm / 1000
    hubs = [(str(i + 1), [arm * np.cos(np.radians(y)), arm * np.sin(np.radians(y)), 0.02],
             [0.0, 0.0, y]) for i, y in enumerate(yaws_deg)]
    parts = [
        dict(name="hub", shape=gen.box(100, 100, 20), mass=0.5, placements=[("c", [0, 0, 0],
                                                                              [0, 0, 0])]),
        dict(name="prop", shape=gen.box(200, 20, 4), mass=0.01, placements=hubs),
    ]
    rotors = [dict(name=n, part="prop", placement=n, spin=s) for (n, _, _), s in zip(hubs, spins)]
    return write_cad(folder, parts, rotors)


def test_generator_is_deterministic_and_matches_committed_cad(tmp_path):
    for out in (tmp_path / "a", tmp_path / "b"):
        subprocess.run([sys.executable, str(SCRIPT), "-o", str(out)], check=True,
                       capture_output=True)
    names = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert len(names) == 12 and "testbed.toml" in names
    for name in names:
        data = (tmp_path / "a" / name).read_bytes()
        assert data == (tmp_path / "b" / name).read_bytes(), name
        assert data == (REPO / "cad" / name).read_bytes(), f"cad/{name} is stale: regenerate"


def test_testbed_masses_match_table_4_4():
    assembly = load_assembly(REPO / "cad")
    whole = vehicle_mass_properties(assembly)
    mechanical = vehicle_mass_properties(assembly, groups=("mechanical",))
    assert whole.mass == pytest.approx(0.837667, abs=5e-7)        # weighed total (mean)
    assert mechanical.mass == pytest.approx(0.607, rel=1e-9)      # mechanical parts
    by_part = {p.name: p.instance_mass for p in assembly.parts}
    assert by_part["motor"] == 0.052 and by_part["propeller"] == 0.011
    assert by_part["battery"] == 0.171
    frame_group = 2 * by_part["base_plate"] + 4 * by_part["frame_arm"] + 4 * by_part["landing_gear"]
    assert frame_group == pytest.approx(0.346333, abs=5e-7)
    for part in assembly.parts:
        assert part.mesh.is_watertight and part.mesh.is_winding_consistent
    # Symmetric '+' frame: CoM on the z axis.
    np.testing.assert_allclose(whole.com[:2], 0, atol=1e-12)


def test_testbed_rotors_reproduce_report_equations_3_44_to_3_47():
    assembly = load_assembly(REPO / "cad")
    arm = 0.1976666667  # Table 4.4 l_mtc, Average column (mean of the trials, to 1e-10)
    expected = {"1": ([arm, 0], 1), "2": ([0, -arm], -1), "3": ([-arm, 0], 1), "4": ([0, arm], -1)}
    assert [r.name for r in assembly.rotors] == ["1", "2", "3", "4"]
    for rotor in assembly.rotors:
        xy, spin = expected[rotor.name]
        np.testing.assert_allclose(rotor.position[:2], xy, atol=1e-9)  # manifest: 1 nm
        np.testing.assert_allclose(rotor.axis, [0, 0, 1], atol=1e-15)
        assert rotor.spin == spin
    base = load_params("physical")
    p = base.replace(rotors=tuple(Rotor(r.name, r.position, r.axis, r.spin)
                                  for r in assembly.rotors))
    a = allocation_matrix(p, about=np.zeros(3))
    b, d = p.thrust_factor, p.drag_factor
    np.testing.assert_allclose(a[3], [0, -arm * b, 0, arm * b], rtol=1e-8, atol=1e-20)  # 3.44
    np.testing.assert_allclose(a[4], [-arm * b, 0, arm * b, 0], rtol=1e-8, atol=1e-20)  # 3.45
    np.testing.assert_allclose(a[5], [-d, d, -d, d], rtol=1e-12)              # yaw, eq. 3.46


def test_x_layout_and_hexarotor_come_from_the_manifest(tmp_path):
    x = load_assembly(layout(180, [45, -45, -135, 135], ["ccw", "cw", "ccw", "cw"],
                             tmp_path / "x"))
    hexa = load_assembly(layout(250, [0, 60, 120, 180, 240, 300],
                                ["ccw", "cw", "ccw", "cw", "ccw", "cw"], tmp_path / "hex"))
    r = 0.18 / np.sqrt(2)
    np.testing.assert_allclose(x.rotors[1].position, [r, -r, 0.02], atol=1e-12)
    assert [ro.spin for ro in x.rotors] == [1, -1, 1, -1]
    assert len(hexa.rotors) == 6
    np.testing.assert_allclose(hexa.rotors[2].position, [-0.125, 0.25 * np.sin(np.radians(120)),
                                                         0.02], atol=1e-12)
