"""Effect files: a diagnosed model as data (TOML), every number with its unit and source.

A parameter set (``models/*.toml``) describes the vehicle; an effect file lists the effects the
gap diagnosis named for it, with the fitted magnitudes, so that a diagnosed model can be
stored, reviewed and rerun. Format (schema ``quadsim.effects/1``)::

    schema = "quadsim.effects/1"
    params = "nanodrone_cf21bl"                   # the parameter set it completes
    description = "..."

    [[effect]]
    name = "rotor_drag"
    coefficient = { value = 2.745e-6, unit = "kg/rad", source = "quadsim.gap on ..." }

Each parameter's unit must be the one the effect declares (``EFFECTS[name].parameters``);
unknown effects, unknown parameters, missing units or sources and values outside the
plausible range are refused in one line (:class:`~quadsim.core.errors.InputError`)::

    >>> from quadsim.effects.effectfile import load_effect_file
    >>> model = load_effect_file("models/effects/nanodrone_cf21bl_diagnosed.toml")
    >>> model.params, [e.name for e in model.effects.effects]

:func:`render_effect_file` writes one (the text; ``python -m quadsim.gap --write-effects``
uses it to store a diagnosed model).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..core.errors import InputError, field_error
from ..core.files import check_schema, read_toml, render_toml
from . import EFFECTS, make_effect
from .base import EffectSet

__all__ = ["SCHEMA", "EffectModel", "load_effect_file", "render_effect_file"]

SCHEMA = "quadsim.effects/1"


@dataclass(frozen=True)
class EffectModel:
    """The effects of a diagnosed model, the parameter set they complete and each number's
    source (``sources[(effect, parameter)]``)."""

    params: str
    description: str
    effects: EffectSet
    sources: dict


def load_effect_file(path: str | Path) -> EffectModel:
    """Read and validate an effect file (module docstring); raises :class:`InputError`."""
    path = Path(path)
    return _parse(read_toml(path), path)


def _parse(data: dict, path) -> EffectModel:
    unknown = sorted(set(data) - {"schema", "params", "description", "effect"})
    if unknown:
        raise field_error(path, unknown[0], "unknown key (valid: schema, params, description, "
                                            "effect)")
    data = check_schema(data, path, SCHEMA)     # quadsim.effects/1 has had no other name
    if not isinstance(data.get("params"), str):
        raise field_error(path, "params", "missing: name or path of the parameter set")
    effects, sources, seen = [], {}, set()
    for k, entry in enumerate(data.get("effect", [])):
        where = f"effect[{k}]"
        name = entry.get("name")
        if name not in EFFECTS:
            raise field_error(path, f"{where}.name", f"unknown effect {name!r}; valid: "
                                                     f"{', '.join(sorted(EFFECTS))}")
        if name in seen:
            raise field_error(path, f"{where}.name", f"effect {name!r} given twice")
        seen.add(name)
        units = {p.name: p.unit for p in EFFECTS[name].parameters}
        values = {}
        for key, item in entry.items():
            if key == "name":
                continue
            field = f"{where}.{key}"
            if key not in units:
                raise field_error(path, field, f"unknown parameter of {name}; valid: "
                                               f"{', '.join(units)}")
            if not isinstance(item, dict) or set(item) != {"value", "unit", "source"}:
                raise field_error(path, field, "expected { value, unit, source }")
            if item["unit"] != units[key]:
                raise field_error(path, field, f"unit {item['unit']!r}, expected "
                                               f"{units[key]!r}")
            if not isinstance(item["value"], (int, float)) or isinstance(item["value"], bool):
                raise field_error(path, field, f"value {item['value']!r} is not a number")
            values[key] = float(item["value"])
            sources[(name, key)] = str(item["source"])
        try:
            effects.append(make_effect(name, **values))
        except InputError as exc:
            raise field_error(path, where, str(exc)) from None
    return EffectModel(data["params"], str(data.get("description", "")),
                       EffectSet(tuple(effects)), sources)


def render_effect_file(params: str, description: str, effects: list[tuple[str, dict]],
                       header: str = "") -> str:
    """TOML text of an effect file: ``effects`` = [(effect name, {parameter: (value,
    source)}), ...] in order; units from the effects' declarations. The text loads with
    :func:`load_effect_file` (checked here: unknown names, units, ranges raise)."""
    entries = []
    for name, values in effects:
        if name not in EFFECTS:
            raise InputError(f"effect {name!r}: unknown; valid: {', '.join(sorted(EFFECTS))}")
        units = {p.name: p.unit for p in EFFECTS[name].parameters}
        entry: dict = {"name": name}
        for key, (value, source) in values.items():
            if key not in units:
                raise InputError(f"effect {name!r}: unknown parameter {key!r}; valid: "
                                 f"{', '.join(units)}")
            entry[key] = {"value": float(value), "unit": units[key], "source": str(source)}
        entries.append(entry)
    text = render_toml({"schema": SCHEMA, "params": params, "description": description,
                        "effect": entries}, header)
    import tomllib

    _parse(tomllib.loads(text), "effect file")     # refuse what load_effect_file refuses
    return text
