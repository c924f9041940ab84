"""Users' files keep working: a file of an earlier schema name is read with one warning (the
file itself unchanged), any other schema is refused in one line that says what is expected.
The parameter set itself is tested in tests/test_params.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from quadsim.core.errors import InputError, QuadsimWarning
from quadsim.core.files import check_schema, render_toml

EXAMPLES = Path(__file__).resolve().parents[1] / "docs" / "examples"


def test_check_schema_current_earlier_unknown():
    data = {"schema": "x.y/2", "a": 1}
    assert check_schema(data, "f.toml", "x.y/2", {"x/1": "renamed"}) is data
    old = {"schema": "x/1", "a": 1}
    with pytest.warns(QuadsimWarning, match=r"^f.toml: schema: 'x/1' is the earlier name of "
                                            r"'x.y/2' \(renamed\); read as 'x.y/2'"):
        migrated = check_schema(old, "f.toml", "x.y/2", {"x/1": "renamed"})
    assert migrated == {"schema": "x.y/2", "a": 1}
    assert old == {"schema": "x/1", "a": 1}            # the caller's data is not changed
    with pytest.raises(InputError) as err:
        check_schema({"schema": "x/9"}, "f.toml", "x.y/2", {"x/1": "renamed"})
    assert str(err.value) == "f.toml: schema: expected 'x.y/2' (or the earlier 'x/1'), got 'x/9'"
    with pytest.raises(InputError) as err:
        check_schema({}, "f.toml", "x.y/2")
    assert str(err.value) == "f.toml: schema: expected 'x.y/2', got None"


def test_skeleton_of_the_earlier_schema_name(tmp_path):
    from quadsim.identify.skeleton import load_skeleton

    current = EXAMPLES / "copter_skeleton.toml"
    text = current.read_text(encoding="utf-8")
    old = tmp_path / "copter_skeleton.toml"
    old.write_text(text.replace('"quadsim.vehicle.params/1"', '"quadsim.params/1"'))
    with pytest.warns(QuadsimWarning) as caught:
        skeleton, data = load_skeleton(old)
    assert len(caught) == 1 and "'quadsim.params/1' is the earlier name" in str(caught[0].message)
    assert data["schema"] == "quadsim.vehicle.params/1"
    expected, _ = load_skeleton(current)
    assert skeleton.mass == expected.mass == 1.0
    np.testing.assert_array_equal(skeleton.positions, expected.positions)
    np.testing.assert_array_equal(skeleton.spins, expected.spins)


def test_effect_file_of_an_unknown_schema_is_one_line(tmp_path):
    from quadsim.effects.effectfile import load_effect_file, render_effect_file

    text = render_effect_file("crazyflie21", "", [("mass_offset", {"mass": (0.002, "scale")})])
    good = tmp_path / "good.toml"
    good.write_text(text)
    assert [e.name for e in load_effect_file(good).effects.effects] == ["mass_offset"]
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('"quadsim.effects/1"', '"quadsim.effects/2"'))
    with pytest.raises(InputError) as err:
        load_effect_file(bad)
    assert str(err.value) == (f"{bad}: schema: expected 'quadsim.effects/1', "
                              "got 'quadsim.effects/2'")


def test_toml_writer_round_trips_and_keeps_its_old_import_path():
    import tomllib

    from quadsim.identify.skeleton import render_params

    assert render_params is render_toml
    data = {"schema": "s/1", "x": 0.1, "flag": True, "n": np.int64(3),
            "body": {"m": {"value": np.float64(1 / 3), "unit": "kg", "source": "a \"b\""}},
            "rotor": [{"name": "1", "position": np.array([0.1, -0.2, 0.0])}]}
    text = render_toml(data, "head\n\nline")
    assert text.startswith("# head\n#\n# line\nschema = \"s/1\"\n")
    back = tomllib.loads(text)
    assert back["body"]["m"]["value"] == 1 / 3 and back["n"] == 3 and back["flag"] is True
    assert back["rotor"][0]["position"] == [0.1, -0.2, 0.0]
    assert back["body"]["m"]["source"] == 'a "b"'
    with pytest.raises(ValueError, match="non-finite"):
        render_toml({"x": float("nan")})
