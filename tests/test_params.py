"""Parameter-set loading and the geometry-derived mixer."""

import re

import numpy as np
import pytest

from quadsim.core.errors import InputError, ModelError, QuadsimWarning
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


def _same_numbers(a, b) -> None:
    """Every field of two parameter sets equal (arrays exactly), the file path apart."""
    import dataclasses

    for f in dataclasses.fields(a):
        if f.name in ("path", "sources"):
            continue
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "rotors":
            for r, s in zip(x, y, strict=True):
                assert r.name == s.name and r.spin == s.spin
                np.testing.assert_array_equal(r.position, s.position)
                np.testing.assert_array_equal(r.axis, s.axis)
        elif isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y)
        elif dataclasses.is_dataclass(x):
            for g in dataclasses.fields(x):
                np.testing.assert_array_equal(getattr(x, g.name), getattr(y, g.name))
        else:
            assert x == y, f.name


@pytest.mark.parametrize("name", ["crazyflie21", "physical", "px4_sitl_iris"])
def test_earlier_schema_name_is_read_with_one_warning(tmp_path, name):
    """A set written before the layout change (schema ``quadsim.params/1``) loads, says so in
    one warning naming the old schema and the line to change, and gives the numbers of the
    set under today's name; the user's file is not rewritten."""
    current = load_params(name)
    text = current.path.read_text(encoding="utf-8")
    assert 'schema = "quadsim.vehicle.params/1"' in text
    old = tmp_path / f"{name}.toml"
    old.write_text(text.replace('schema = "quadsim.vehicle.params/1"',
                                'schema = "quadsim.params/1"'), encoding="utf-8")
    before = old.read_bytes()
    with pytest.warns(QuadsimWarning) as caught:
        migrated = load_params(old)
    assert len(caught) == 1
    message = str(caught[0].message)
    assert "\n" not in message
    assert message.startswith(f"{old}: schema: 'quadsim.params/1' is the earlier name of "
                              "'quadsim.vehicle.params/1'")
    assert 'write schema = "quadsim.vehicle.params/1"' in message
    _same_numbers(migrated, current)
    assert old.read_bytes() == before


def test_unknown_schema_is_one_line_error(tmp_path):
    text = load_params("crazyflie21").path.read_text(encoding="utf-8")
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('"quadsim.vehicle.params/1"', '"quadsim.params/7"'))
    with pytest.raises(InputError) as err:
        load_params(bad)
    assert str(err.value) == (f"{bad}: schema: expected 'quadsim.vehicle.params/1' (or the "
                              "earlier 'quadsim.params/1'), got 'quadsim.params/7'")


def test_earlier_schema_through_a_command(tmp_path):
    """The command a user types: one ``warning:`` line on stderr, exit 0, the same MJCF."""
    import subprocess
    import sys

    text = load_params("physical").path.read_text(encoding="utf-8")
    old = tmp_path / "old.toml"
    old.write_text(text.replace('"quadsim.vehicle.params/1"', '"quadsim.params/1"'))
    outs = {}
    for key, params in (("old", str(old)), ("new", "physical")):
        out = tmp_path / f"{key}.xml"
        command = [sys.executable, "-m", "quadsim.build_mjcf", "--params", params,
                   "--inertial", "params", "-o", str(out)]
        run = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
        assert run.returncode == 0, run.stderr[-500:]
        outs[key] = (out.read_text(encoding="utf-8"), run.stderr)
    warned = [line for line in outs["old"][1].splitlines() if "quadsim.params/1" in line]
    assert len(warned) == 1 and warned[0].startswith("warning: ")
    assert "quadsim.params/1" not in outs["new"][1]
    strip = re.compile(r"^<!--.*?-->\n", re.S | re.M)
    assert strip.sub("", outs["old"][0]).replace(str(old), "X") == \
        strip.sub("", outs["new"][0]).replace(str(load_params("physical").path), "X")
