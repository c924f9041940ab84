"""The JSON Schema of the ``quadsim.gap/3`` result (documented in docs/gap.md).

Version 3 (from 2): per-flight and held-out results are judged by evidence
(:mod:`quadsim.gap.judge`); a held-out verdict carries
``probability`` and ``posterior`` (the per-flight reading rows), each ``effects`` entry
``probability``, ``log_evidence`` and ``undetermined``, the result ``noise_model``.
Each flight carries ``probability`` (of its verdict's reading), ``posterior`` (every reading,
most probable first: name, probability, magnitude in words, log evidence, determined
``params`` with 95 % ``ci``, ``undetermined`` parameter names, ``fixed``, ``variant``),
``lack_of_fit`` (channel -> RMS over the references' typical RMS, only channels beyond
them), ``differ_on`` (channels that separate the two leading readings), ``symptom`` (the
flight's largest mean residual against the reference model), ``envelope`` (where the flight
lies against its references' envelope, :mod:`quadsim.gap.envelope`) and ``tentative``; an outcome
``refused`` with its ``reason`` for a flight that could not be judged. The result carries
``reference_model`` (shared parameters with standard error and between-flight scatter,
per-channel sigma and correlation time, reference delays) instead of
``reference_floor``.

Version 2 (from 1): the verdict has an ``outcome`` (``no_significant_gap`` | ``effect`` |
``unexplained``), an ``answer`` in words, per-channel ``channels`` (RMS before/after/floor in
units, ``at_floor``), the ``alternatives`` (collinear candidates with physical magnitudes
and plausibility), parameter ``units``; each per-flight entry carries the same, plus
``checks`` (model/vehicle consistency) in the result.

The object is :meth:`quadsim.gap.result.Diagnosis.to_json`.
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
        "fixed": _NUMBER_MAP,
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

_CHANNEL = {
    "type": "object",
    "required": ["before", "after", "floor", "unit", "at_floor"],
    "properties": {"before": {"type": "number"}, "after": {"type": "number"},
                   "floor": {"type": "number"}, "unit": {"type": "string"},
                   "at_floor": {"type": "boolean"}},
}

_ALTERNATIVE = {
    "type": "object",
    "required": ["name", "magnitude", "params", "plausible"],
    "properties": {"name": {"type": "string"}, "magnitude": {"type": "string"},
                   "params": _NUMBER_MAP, "ci": _NUMBER_MAP,
                   "units": {"type": "object", "additionalProperties": {"type": "string"}},
                   "reduction": {"type": ["number", "null"]},
                   "torque_yaw": {"type": "string"}, "plausible": {"type": "boolean"},
                   "plausibility": {"type": ["number", "null"]}, "prior": {"type": "string"},
                   "separate_by": {"type": "string"}},
}

OUTCOMES = ["no_significant_gap", "effect", "unexplained", "refused"]

#: parameter consistency (quadsim.gap.consistency): the named candidate refitted per regime.
_CONSISTENCY = {
    "type": "object",
    "required": ["consistent", "splits", "inconsistent"],
    "properties": {
        "consistent": {"type": "boolean"},
        "inconsistent": {"type": "array", "items": {"type": "string"}},
        "shifted": {"type": "array", "items": {"type": "string"}},
        "splits": {"type": "object", "additionalProperties": {
            "type": "object", "required": ["threshold", "unit", "params"],
            "properties": {"threshold": {"type": "number"}, "unit": {"type": "string"},
                           "params": {"type": "object", "additionalProperties": {
                               "type": "object",
                               "required": ["low", "high", "ci_low", "ci_high", "consistent"],
                           }}}}},
    },
}
#: a candidate not named because its parameters are inconsistent: a partial explanation.
_PARTIAL = {"type": "object", "required": ["name", "reduction", "params"],
            "properties": {"name": {"type": "string"}, "reduction": {"type": ["number", "null"]},
                           "params": _NUMBER_MAP}}

_VERDICT = {
    "type": "object",
    "required": ["outcome", "effect", "answer", "reduction", "confusable_with"],
    "properties": {
        "outcome": {"enum": OUTCOMES},
        "answer": {"type": "string"},
        "floor_source": {"type": "string"},
        "channels": {"type": "object", "additionalProperties": _CHANNEL},
        "alternatives": {"type": "array", "items": _ALTERNATIVE},
        "units": {"type": "object", "additionalProperties": {"type": "string"}},
        "effect": {"type": "string"},
        "reduction": {"type": ["number", "null"]},
        "confusable_with": {"type": "array", "items": {"type": "string"}},
        "readings": {"type": "array", "items": {"type": "string"}},
        "separate_by": {"type": "object", "additionalProperties": {"type": "string"}},
        "params": _NUMBER_MAP,
        "fixed": _NUMBER_MAP,
        "ci": _NUMBER_MAP,
        "best_candidate": {"type": ["string", "null"]},
        "lack_of_fit": _NUMBER_MAP,
        "heldout_channel_gap_after": _NUMBER_MAP,
        "consistency": _CONSISTENCY,
        "partial": _PARTIAL,
        "tentative": {"type": "boolean"},
        "probability": {"type": ["number", "null"]},
        "posterior": {"type": "array", "items": {"type": "object",
                                                 "required": ["name", "probability"]}},
    },
}

_READING = {
    "type": "object",
    "required": ["name", "probability", "magnitude", "log_evidence", "params", "ci"],
    "properties": {"name": {"type": "string"}, "probability": {"type": "number"},
                   "magnitude": {"type": "string"}, "log_evidence": {"type": "number"},
                   "params": _NUMBER_MAP, "ci": _NUMBER_MAP, "fixed": _NUMBER_MAP,
                   "undetermined": {"type": "array", "items": {"type": "string"}},
                   "variant": {"type": "string"}},
}

_FLIGHT = {
    "type": "object",
    "required": ["file", "outcome", "verdict", "answer", "probability", "posterior"],
    "properties": {"file": {"type": "string"}, "verdict": {"type": "string"},
                   "outcome": {"enum": OUTCOMES}, "answer": {"type": "string"},
                   "channels": {"type": "object", "additionalProperties": _CHANNEL},
                   "alternatives": {"type": "array", "items": _ALTERNATIVE},
                   "units": {"type": "object", "additionalProperties": {"type": "string"}},
                   "notes": {"type": "array", "items": {"type": "string"}},
                   "params": _NUMBER_MAP, "ci": _NUMBER_MAP, "fixed": _NUMBER_MAP,
                   "reduction": {"type": ["number", "null"]},
                   "confusable_with": {"type": "array", "items": {"type": "string"}},
                   "readings": {"type": "array", "items": {"type": "string"}},
                   "consistency": _CONSISTENCY, "partial": _PARTIAL,
                   "tentative": {"type": "boolean"},
                   "probability": {"type": ["number", "null"]},
                   "posterior": {"type": "array", "items": _READING},
                   "reason": {"type": "string"},
                   "differ_on": {"type": "array", "items": {"type": "string"}},
                   "symptom": {"type": "object"},
                   "signal_delays_ms": {"type": "object"},
                   "envelope": {"type": "object", "properties": {
                       "outside": {"type": "boolean"}, "distance": {"type": "number"},
                       "furthest": {"type": ["string", "null"]}, "rms": _NUMBER_MAP,
                       "place": {"type": ["number", "null"]}, "text": {"type": "string"}}},
                   "lack_of_fit": _NUMBER_MAP},
}

#: JSON Schema (draft 2020-12) of the result.
GAP_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "quadsim.gap/3",
    "type": "object",
    "required": ["schema", "where", "effects", "verdict"],
    "properties": {
        "schema": {"const": "quadsim.gap/3"},
        "model": {"type": "string"},
        "mode": {"enum": ["per-flight"]},
        "train": {"type": "array", "items": {"type": "string"}},
        "holdout": {"type": "array", "items": {"type": "string"}},
        "reference": {"type": "array", "items": {"type": "string"}},
        "reference_refit": _NUMBER_MAP,
        "reference_refit_ci": _NUMBER_MAP,
        "reference_refit_identified": {"type": "object",
                                       "additionalProperties": {"type": "boolean"}},
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
        "checks": {"type": "object"},
        "reference_floor": {"type": "object"},
        "reference_model": {"type": "object"},
    },
}


def validate(document) -> None:
    """Raise ``jsonschema.ValidationError`` if ``document`` (a JSON object, or a
    :class:`quadsim.gap.result.Diagnosis`: its ``to_json()``) does not follow the schema."""
    import jsonschema

    if hasattr(document, "to_json"):
        document = document.to_json()
    jsonschema.validate(document, GAP_SCHEMA)
