"""STEP parts: the same assembly from box.step and box.stl has the same mass properties; a
curved part converges to its closed form at the stated tessellation tolerance; several
solids or an open shell are one-line errors. Fixtures: scripts/make_step_fixture.py."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from test_cad import write_cad

from quadsim.cad.assembly import load_assembly
from quadsim.cad.massprops import mesh_mass_properties, vehicle_mass_properties
from quadsim.core.errors import InputError

pytest.importorskip("cascadio", reason="STEP needs the optional [step] extra (cascadio)")

DATA = Path(__file__).resolve().parent / "data"
HUBS = [(str(i + 1), [0.1 * np.cos(a), 0.1 * np.sin(a), 0.01 * i], [10.0 * i, 0.0, 90.0 * i])
        for i, a in enumerate(np.radians([0, 90, 180, 270]))]
ROTORS = [{"name": n, "part": "block", "placement": n, "spin": s}
          for (n, _, _), s in zip(HUBS, ["ccw", "cw", "ccw", "cw"])]


def _vehicle(folder: Path, mesh: str, mesh_unit: str = "mm") -> Path:
    folder.mkdir(parents=True)
    shutil.copy(DATA / mesh, folder / mesh)
    parts = [{"name": "block", "mesh": mesh, "mass": 0.1, "placements": HUBS}]
    return write_cad(folder, parts, ROTORS, mesh_unit=mesh_unit)


def test_step_assembly_matches_the_same_part_as_stl(tmp_path):
    stl = vehicle_mass_properties(load_assembly(_vehicle(tmp_path / "stl", "box.stl")))
    # the STEP file declares millimetres itself: the manifest's mesh_unit does not apply
    step = vehicle_mass_properties(load_assembly(_vehicle(tmp_path / "step", "box.step",
                                                          mesh_unit="m")))
    assert abs(step.mass - stl.mass) <= 1e-6 * stl.mass
    assert np.abs(step.com - stl.com).max() <= 1e-6 * 0.1              # m, arm 0.1 m
    assert np.abs(step.inertia - stl.inertia).max() <= 1e-6 * np.abs(stl.inertia).max()
    # and the STL box is the closed form: 40 x 30 x 20 mm, 0.1 kg per block
    volume, _, inertia = mesh_mass_properties(load_assembly(tmp_path / "step").parts[0].mesh,
                                              0.1)
    a, b, c = 0.04, 0.03, 0.02
    closed = 0.1 / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    assert abs(volume / (a * b * c) - 1) < 1e-6
    assert np.allclose(np.diag(inertia), closed, rtol=1e-6, atol=0)


def test_curved_part_converges_to_closed_form(tmp_path):
    from quadsim.cad.step import STEP_TOLERANCE, read_step

    r, h = 0.010, 0.030                                                # m
    coarse, fine = read_step(DATA / "cylinder.step", tolerance=1e-3), \
        read_step(DATA / "cylinder.step")
    import trimesh

    volumes = []
    for vertices, faces in (coarse, fine):
        volumes.append(trimesh.Trimesh(vertices, faces, process=False).volume)
    exact = np.pi * r * r * h
    # measured: the volume error is about the relative chord tolerance (an inscribed polygon)
    assert -2e-3 < volumes[0] / exact - 1 < -1e-4
    assert abs(volumes[1] / exact - 1) < 3 * STEP_TOLERANCE


@pytest.mark.parametrize("fixture, message", [("two_boxes.step", "2 separate solids"),
                                              ("open_box.step", "is not watertight")])
def test_several_solids_or_open_shell_is_one_line(tmp_path, fixture, message):
    with pytest.raises(InputError, match=message) as caught:
        load_assembly(_vehicle(tmp_path / "v", fixture))
    assert "\n" not in str(caught.value)


def test_mjcf_from_step_compiles_with_the_stl_inertia(tmp_path):
    import mujoco

    from quadsim.sim.model import build_model, write_model

    models = []
    for mesh in ("box.stl", "box.step"):
        out = tmp_path / f"{mesh}.xml"
        write_model(build_model(_vehicle(tmp_path / mesh, mesh), output=out), out)
        models.append(mujoco.MjModel.from_xml_path(str(out)))
    stl, step = models
    # the vehicle body and MuJoCo's own compile of the meshes (visual geoms) agree
    assert np.allclose(step.body_mass, stl.body_mass, rtol=1e-6, atol=0)
    assert np.allclose(step.body_inertia, stl.body_inertia, rtol=1e-6, atol=1e-12)
    def rows(v):
        return v[np.lexsort(v.T)]

    assert np.allclose(rows(step.mesh_vert), rows(stl.mesh_vert), rtol=0, atol=1e-9)
