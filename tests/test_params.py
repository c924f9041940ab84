"""Parameter-set loading and the geometry-derived mixer."""

import re

import numpy as np
import pytest

from quadsim.core.errors import InputError, ModelError
from quadsim.vehicle.params import hover_speed, inertia_problems, load_params
from quadsim.vehicle.rotors import allocation_matrix, mixer, rotor_wrench


def test_plus_layout_reproduces_report_input_equations():
    # Eq. 3.44-3.47: u_roll = l b (-w2^2 + w4^2), u_pitch = l b (-w1^2 + w3^2),
    # u_yaw = d (-w1^2 + w2^2 - w3^2 + w4^2), thrust = b sum w^2.
    p = load_params("physical")
    a = allocation_matrix(p)
    arm = np.linalg.norm(p.rotor_positions[0])
    b, d = p.thrust_factor, p.drag_factor
    np.testing.assert_allclose(a[2], [b] * 4, rtol=1e-12)
    np.testing.assert_allclose(a[3], [0, -arm * b, 0, arm * b], atol=1e-18)
    np.testing.assert_allclose(a[4], [-arm * b, 0, arm * b, 0], atol=1e-18)
    np.testing.assert_allclose(a[5], [-d, d, -d, d], rtol=1e-12)


def test_hover_speeds_give_weight_and_no_torque():
    p = load_params("physical")
    force, torque = rotor_wrench(p, np.full((2, 4), hover_speed(p)))
    np.testing.assert_allclose(force[:, 2], p.weight, rtol=1e-12)
    np.testing.assert_allclose(torque, 0, atol=1e-12)


def test_mixer_inverts_allocation():
    p = load_params("physical")
    a = allocation_matrix(p)[[2, 3, 4, 5]]
    np.testing.assert_allclose(a @ mixer(p), np.eye(4), atol=1e-9)


def test_triangle_inequality_detected():
    assert inertia_problems(np.diag([0.01931, 0.01931, 0.1931]))
    assert not inertia_problems(np.diag([0.00628, 0.00631, 0.01206]))


def test_unknown_model_lists_valid_names():
    with pytest.raises(InputError, match="valid names are .*physical"):
        load_params("no-such-model")


def test_wrong_unit_is_named(tmp_path):
    text = re.sub(r'^(mass = \{ value = [^,]+, unit = )"kg"', r'\1"g"',
                  load_params("physical").path.read_text(), count=1, flags=re.M)
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(InputError, match=r"bad.toml: body.mass: unit 'g' where 'kg'"):
        load_params(f)


def test_non_physical_inertia_refused(tmp_path):
    text = re.sub(r"(\[0\.0, 0\.0, )[0-9.e-]+\]\]", r"\g<1>0.0825]]",
                  load_params("physical").path.read_text(), count=1)
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ModelError, match="triangle inequality"):
        load_params(f)
    assert load_params(f, check=False).inertia[2, 2] == 0.0825


def test_atomic_write_has_plain_file_permissions(tmp_path):
    import os
    import stat

    from quadsim.core.files import atomic_write_text

    mask = os.umask(0o022)
    try:
        path = atomic_write_text(tmp_path / "out.txt", "x")
    finally:
        os.umask(mask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert path.read_text() == "x"
