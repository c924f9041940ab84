"""The parameter sets written from the identification: regenerated files equal the committed
ones, they load, and the published ``report`` set is refused by the physical check."""

import importlib.util

import numpy as np
import pytest

from quadsim.core.errors import ModelError
from quadsim.identify import identify_testbed
from quadsim.identify.paramsets import render_computational, render_physical
from quadsim.vehicle.params import MODELS_DIR, hover_speed, load_params


@pytest.fixture(scope="module")
def ident():
    return identify_testbed()


def test_committed_sets_equal_a_fresh_regeneration(ident):
    assert (MODELS_DIR / "physical.toml").read_text() == render_physical(ident), \
        "models/physical.toml is stale: run python scripts/write_params.py"
    assert (MODELS_DIR / "computational.toml").read_text() == render_computational(ident), \
        "models/computational.toml is stale: run python scripts/write_params.py"


def test_physical_set(ident):
    p = load_params("physical")
    assert p.thrust_factor == pytest.approx(ident.thrust_factor, rel=1e-5)
    assert p.drag_factor / p.thrust_factor == pytest.approx(ident.torque_thrust_ratio, rel=1e-5)
    assert p.mass == pytest.approx(0.837667, abs=1e-6)
    assert np.linalg.norm(p.rotor_positions, axis=1) == pytest.approx([0.197667] * 4, abs=1e-6)
    assert any("NOT the bifilar test" in w for w in p.warnings)
    assert np.diag(p.inertia) == pytest.approx(ident.lumped, rel=1e-5)
    # motor map: dead below PWM 50, measured top speed held above the last command
    speeds = p.motor_map.speed_of(np.array([[40.0] * 4, [200.0] * 4]))
    assert np.all(speeds[0] == 0) and speeds[1] == pytest.approx(p.motor_map.speed[:, -1])
    assert p.max_speed == pytest.approx(p.motor_map.speed[:, -1].max())
    # the measured vehicle hovers at ~450 rad/s, inside the measured range
    assert 400 < hover_speed(p) < 500


def test_report_set_is_refused_in_one_line_and_runs_unchecked():
    with pytest.raises(ModelError) as info:
        load_params("report")
    assert "\n" not in str(info.value) and "triangle inequality" in str(info.value)
    p = load_params("report", check=False)
    assert (p.thrust_factor, p.drag_factor) == (6.0722e-5, 1.518e-5)
    assert np.diag(p.inertia) == pytest.approx([0.01931, 0.01931, 0.1931])


@pytest.mark.skipif(importlib.util.find_spec("quadsim.cad.assembly") is None,
                    reason="quadsim.cad.assembly (CAD loader) not present")
def test_computational_set_takes_mass_and_layout_from_cad(ident):
    p = load_params("computational")
    assert p.thrust_factor == pytest.approx(ident.cfd_fit["b"], rel=1e-5)
    assert p.rotor_count == 4 and 0.3 < p.mass < 2.0
    assert not np.allclose(p.inertia, load_params("physical").inertia)
