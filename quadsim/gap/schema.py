"""The JSON Schema of the ``quadsim.gap/1`` result (documented in docs/gap.md).

``python -m quadsim.gap ... --json OUT.json`` writes an object that validates against
:data:`GAP_SCHEMA` (draft 2020-12). Numbers are rounded to 6 significant digits; keys sorted.
"""

from __future__ import annotations

__all__ = ["GAP_SCHEMA", "validate"]

_NUMBER_MAP = {"type": "object", "additionalProperties": {"type": ["number", "null"]}}

_EFFECT = {
    "type": "object",
    "required": ["name", "params", "ci", "heldout_gap_before", "heldout_gap_after", "reduction"],
    "properties": {
        "name": {"type": "string"},
        "params": _NUMBER_MAP,
        "ci": _NUMBER_MAP,
        "identifiable": {"type": "object", "additionalProperties": {"type": "boolean"}},
        "significant": {"type": "object", "additionalProperties": {"type": "boolean"}},
        "heldout_gap_before": {"type": "number"},
        "heldout_gap_after": {"type": "number"},
        "reduction": {"type": "number"},
        "t_statistic": {"type": ["number", "null"]},
        "heldout_rms_after": _NUMBER_MAP,
        "warning": {"type": "string"},
    },
}

_VERDICT = {
    "type": "object",
    "required": ["effect", "reduction", "confusable_with"],
    "properties": {
        "effect": {"type": "string"},
        "reduction": {"type": ["number", "null"]},
        "confusable_with": {"type": "array", "items": {"type": "string"}},
        "separate_by": {"type": "object", "additionalProperties": {"type": "string"}},
        "params": _NUMBER_MAP,
        "ci": _NUMBER_MAP,
        "best_candidate": {"type": ["string", "null"]},
        "lack_of_fit": _NUMBER_MAP,
        "heldout_channel_gap_after": _NUMBER_MAP,
    },
}

_FLIGHT = {
    "type": "object",
    "required": ["file", "verdict", "params"],
    "properties": {"file": {"type": "string"}, "verdict": {"type": "string"},
                   "params": _NUMBER_MAP, "ci": _NUMBER_MAP,
                   "reduction": {"type": ["number", "null"]},
                   "confusable_with": {"type": "array", "items": {"type": "string"}}},
}

#: JSON Schema (draft 2020-12) of the result.
GAP_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "quadsim.gap/1",
    "type": "object",
    "required": ["schema", "where", "effects", "verdict"],
    "properties": {
        "schema": {"const": "quadsim.gap/1"},
        "model": {"type": "string"},
        "mode": {"enum": ["per-flight"]},
        "train": {"type": "array", "items": {"type": "string"}},
        "holdout": {"type": "array", "items": {"type": "string"}},
        "reference": {"type": "array", "items": {"type": "string"}},
        "reference_refit": _NUMBER_MAP,
        "reference_refit_ci": _NUMBER_MAP,
        "where": {
            "type": "object",
            "properties": {
                "channels": {"type": "array", "items": {"type": "string"}},
                "noise_scale": _NUMBER_MAP,
                "heldout_rms_before": _NUMBER_MAP,
                "heldout_rms_after": _NUMBER_MAP,
                "channel_share": _NUMBER_MAP,
                "regime": {"type": "object", "additionalProperties": {
                    "type": "object", "required": ["share", "samples"],
                    "properties": {"share": {"type": "number"}, "samples": {"type": "number"},
                                   "mean_gap": {"type": "number"}}}},
                "band": _NUMBER_MAP,
                "kstep_before": {"type": "object"},
                "kstep_after": {"type": "object"},
            },
        },
        "baseline": _EFFECT,
        "effects": {"type": "array", "items": _EFFECT},
        "combination": _EFFECT,
        "verdict": _VERDICT,
        "flights": {"type": "array", "items": _FLIGHT},
        "notes": {"type": "array", "items": {"type": "string"}},
    },
}


def validate(document: dict) -> None:
    """Raise ``jsonschema.ValidationError`` if ``document`` does not follow the schema."""
    import jsonschema

    jsonschema.validate(document, GAP_SCHEMA)
