"""The committed MJCF in models/ is what `python -m quadsim.build_mjcf cad/` writes today."""

import mujoco
import numpy as np

from quadsim.sim.model import build_model
from quadsim.vehicle.params import MODELS_DIR


def test_committed_testbed_xml_is_fresh():
    committed = MODELS_DIR / "testbed.xml"
    fresh = build_model(MODELS_DIR.parent / "cad", output=committed)
    assert committed.read_text(encoding="utf-8") == fresh.xml, (
        "models/testbed.xml is stale: run `python -m quadsim.build_mjcf cad/`")


def test_committed_testbed_xml_compiles_with_mesh_mass_properties():
    model = mujoco.MjModel.from_xml_path(str(MODELS_DIR / "testbed.xml"))
    fresh = build_model(MODELS_DIR.parent / "cad", output=MODELS_DIR / "testbed.xml")
    body = model.body("vehicle")
    np.testing.assert_allclose(body.mass[0], fresh.mass_properties.mass, rtol=1e-12)
    np.testing.assert_allclose(body.ipos, fresh.mass_properties.com, atol=1e-12)
    assert model.nu == 4
