"""Outputs of the gap diagnosis: the JSON (``quadsim.gap/3``) and its schema, the human
summary that leads with the answer in words, the effect file, the HTML report
(:mod:`quadsim.gap.page`) and the rerun recording of the residuals.

JSON and summaries
------------------

Outputs of the gap diagnosis: JSON (``quadsim.gap/3``), a human summary that leads with
the answer in words, the HTML report (:mod:`quadsim.gap.page`: the answer first, figures as
inline SVG, the JSON in a collapsed appendix), and a rerun recording of the residuals.

Sections, in the order of the file:

1. **The result's JSON Schema** (:data:`GAP_SCHEMA`, :func:`validate`).
2. **JSON, the summary, the HTML page and the rerun recording** (:func:`to_json`,
   :func:`write_json`, :func:`summary`, :func:`write_html`, :func:`write_rerun`).
3. **The per-flight summary** (:func:`flights_summary`, :func:`gather_delay_notes`).
4. **A diagnosed model as an effect file** (:func:`added_effects`, :func:`named_candidate`).

The result's JSON Schema
------------------------
The JSON Schema of the ``quadsim.gap/3`` result (documented in docs/gap.md).

Version 3 (from 2): per-flight and held-out results are judged by evidence
(:mod:`quadsim.gap.judge`); a held-out verdict carries
``probability`` and ``posterior`` (the per-flight reading rows), each ``effects`` entry
``probability``, ``log_evidence`` and ``undetermined``, the result ``noise_model``.
Each flight carries ``probability`` (of its verdict's reading), ``posterior`` (every reading,
most probable first: name, probability, magnitude in words, log evidence, determined
``params`` with 95 % ``ci``, ``undetermined`` parameter names, ``fixed``, ``variant``),
``lack_of_fit`` (channel -> RMS over the references' typical RMS, only channels beyond
them), ``residual`` (RMS per channel before and after the answer over the references', the
share of the excess removed, in words), ``differ_on`` (channels that separate the two
leading readings), ``symptom`` (the flight's largest mean residual against the reference
model), ``envelope`` (where the flight lies against its references' envelope,
:mod:`quadsim.gap.reference`) and ``tentative``; an outcome
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

Per-flight outputs
------------------
The text summary of ``--per-flight`` results: the batch's answer, then per flight its answer
and its residual against the references' (``residual.text``, the report's words). The HTML
page of both modes is :mod:`quadsim.gap.page` (figures :mod:`quadsim.gap.page`); the rerun
recording carries the same series (:mod:`quadsim.gap.report`).

Store a diagnosed model
-----------------------
The effects a diagnosis fitted, as an effect file.

``python -m quadsim.gap ... --write-effects OUT.toml [--add NAME]`` writes the effects the
model started from (``--effects-file``, their sources kept) followed by one fitted candidate
of this diagnosis -- the named effect (the verdict's effect or combination) by default, or
the ranked candidate ``NAME`` -- every parameter with its unit and a source that says which
logs it was fitted on, its 95 % interval and how much of the held-out gap it explains. The
next round of the diagnosis then starts from that file (``--effects-file OUT.toml``): the
user's loop "diagnose, add what is named, diagnose again" (docs/gap.md).

Only library parameters are stored: a candidate fitted in another parametrisation (the
canted rotor's ``tilt_x``, ``tilt_y``) or an effect already in the starting model is refused
in one line (an effect file holds each effect once).

Example::

    >>> entries = added_effects(result, "rotor_drag", logs="9 training logs")
    >>> entries[0][0], sorted(entries[0][1])
    ('rotor_drag', ['axial_coefficient', 'coefficient'])

Rerun recording
---------------

What the rerun recording of a gap diagnosis carries (``--rerun OUT.rrd``): the same series
as the report's figures (:mod:`quadsim.gap.page`).

Per flight with a residual series (per-flight mode: every judged flight; held out: every
held-out flight): its logged motion as a trajectory, and per wrench channel one plot
view with the residual before the answer, after it, and the references' 95 % band
(+-1.96 sigma_c; held out: the floor), on the flight's own time stamps (s) in the channel's
unit (N, N m).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from ..core.errors import InputError, refuse_moved
from ..core.files import atomic_write_text
from ..effects import EFFECTS
from .page import Z95
from .result import plain

__all__ = ["GAP_SCHEMA", "added_effects", "document", "flights_summary", "gather_delay_notes",
           "named_candidate", "summary", "to_json", "validate", "write_html", "write_json",
           "write_rerun", "recording"]


# --- the result's JSON Schema -----------------------------------------------------------------

_NUMBER_MAP = {"type": "object", "additionalProperties": {"type": ["number", "null"]}}
#: a weighed mass's 95 % half-intervals on another session's air (words.across_sessions)
_ACROSS = {"type": "object", "required": ["thrust_spread", "ci"],
           "properties": {"thrust_spread": {"type": "number", "minimum": 0},
                          "ci": _NUMBER_MAP, "total_ci": {"type": "number", "minimum": 0}},
           "additionalProperties": False}


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

#: parameter consistency (quadsim.gap.judge): the named candidate refitted per regime.
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
        "probability_within_library": {"type": ["number", "null"]},
        "outside_library": {"type": "number"},
        "across_sessions": _ACROSS,
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
                   "variant": {"type": "string"}, "across_sessions": _ACROSS},
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
                   "probability_within_library": {"type": ["number", "null"]},
                   "outside_library": {"type": "number"},
                   "across_sessions": _ACROSS,
                   "posterior": {"type": "array", "items": _READING},
                   "reason": {"type": "string"},
                   "differ_on": {"type": "array", "items": {"type": "string"}},
                   "symptom": {"type": "object"},
                   "signal_delays_ms": {"type": "object"},
                   "envelope": {"type": "object", "properties": {
                       "outside": {"type": "boolean"}, "distance": {"type": "number"},
                       "furthest": {"type": ["string", "null"]}, "rms": _NUMBER_MAP,
                       "place": {"type": ["number", "null"]}, "text": {"type": "string"}}},
                   "lack_of_fit": _NUMBER_MAP,
                   "residual": {"type": "object",
                                "required": ["rms_before", "rms_after", "removed", "text"],
                                "properties": {"rms_before": _NUMBER_MAP,
                                               "rms_after": _NUMBER_MAP,
                                               "removed": {"type": ["number", "null"]},
                                               "text": {"type": "string"}}}},
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
        "reference_file": {"type": "object", "required": ["file", "shipped", "format", "count"],
                           "properties": {"file": {"type": "string"},
                                          "shipped": {"type": "boolean"},
                                          "format": {"type": "integer"},
                                          "judges": {"enum": ["speeds", "commands"]},
                                          "count": {"type": "integer"}}},
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
                "band_top_hz": {"type": "number"},
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


# --- JSON, summary, HTML, rerun ---------------------------------------------------------------

def document(result) -> dict:
    """The JSON object of ``result``: a :class:`~quadsim.gap.result.Diagnosis`'s
    ``to_json()``, or a result already read as a dict (numbers made plain)."""
    return result.to_json() if hasattr(result, "to_json") else plain(result)


def to_json(result) -> str:
    """Stable JSON text: sorted keys, 6 significant digits, newline at the end."""
    def rounded(value):
        if isinstance(value, float):
            return float(f"{value:.6g}")
        if isinstance(value, dict):
            return {k: rounded(v) for k, v in value.items()}
        if isinstance(value, list):
            return [rounded(v) for v in value]
        return value

    return json.dumps(rounded(document(result)), indent=1, sort_keys=True) + "\n"


def write_json(path: str | Path, result) -> Path:
    """``result`` as JSON text (:func:`to_json`) at ``path``, written atomically."""
    return atomic_write_text(path, to_json(result))


def _fmt_params(params: dict, ci: dict, identified: dict | None = None) -> str:
    """``name = value ± ci unit`` for every parameter (units from the effect declarations);
    a parameter marked not identified in ``identified`` (at a bound, or an interval wider
    than half its plausible range) says so."""
    from .fitting import unit_of

    def unit(k):
        u = unit_of(k)
        return "(relative)" if u == "1" else u

    def flag(k):
        return " (not identified: at a bound or too wide)" \
            if identified is not None and not identified.get(k, True) else ""

    return ", ".join(f"{k} = {v:.4g} ± {ci.get(k, float('nan')):.2g} {unit(k)}".rstrip() + flag(k)
                     for k, v in params.items())


def _channel_lines(channels: dict, indent: str = "  ") -> list[str]:
    out = [f"{indent}residual RMS per channel (before -> after, floor):"]
    for name, c in channels.items():
        mark = "at floor" if c["at_floor"] else f"{c['after'] / max(c['floor'], 1e-300):.1f}x floor"
        out.append(f"{indent}  {name:8s} {c['before']:.3g} -> {c['after']:.3g} {c['unit']} "
                    f"(floor {c['floor']:.3g} {c['unit']}; {mark})")
    return out


def summary(result: dict) -> str:
    """A few lines for people: verdict, parameters, where the gap lies, ranking."""
    if result.get("mode") == "per-flight":
        return flights_summary(result)
    v = result["verdict"]
    where = result["where"]
    lines = [f"answer: {v.get('answer', v['effect'])}", f"verdict: {v['effect']}"]
    if v.get("outcome", "effect") == "effect":
        fixed = "".join(f", {k} = {x:g} (held fixed)" for k, x in v.get("fixed", {}).items())
        lines.append(f"  parameters: {_fmt_params(v['params'], v['ci'])}{fixed}")
        lines.append(f"  held-out gap {v['heldout_gap_before']:.3g} -> {v['heldout_gap_after']:.3g}"
                     f" (noise = 1 per channel): -{100 * v['reduction']:.1f} %")
    if v["confusable_with"]:
        lines.append("  confusable with: " + "; ".join(
            f"{k} (separate by: {w})" for k, w in v["separate_by"].items()))
    lines += _channel_lines(v.get("channels", {}))
    share = where["channel_share"]
    top = sorted(share.items(), key=lambda kv: -kv[1])[:3]
    lines.append("where: " + ", ".join(f"{k} {100 * s:.0f} %" for k, s in top)
                 + " of the held-out gap")
    regimes = sorted(where["regime"].items(), key=lambda kv: -kv[1]["share"])[:3]
    lines.append("  by regime: " + ", ".join(
        f"{k} {100 * r['share']:.0f} % (of {100 * r['samples']:.0f} % of samples)"
        for k, r in regimes))
    top = where.get("band_top_hz")      # absent from results written before it
    lines.append("  by band: " + ", ".join(f"{k} {100 * s:.0f} %"
                                           for k, s in where["band"].items())
                 + ("" if top is None else f" (above {top:.2g} Hz smoothed out: not compared)"))
    lines.append("ranking (posterior probability; held-out gap reduction; determined "
                 "parameters only):")
    for e in result["effects"][:6]:
        p = e.get("probability")
        prob = "" if p is None else f"{100 * p:5.1f} %  "
        undetermined = (f" (not determined: {', '.join(e['undetermined'])})"
                        if e.get("undetermined") else "")
        lines.append(f"  {e['name']:16s} {prob}{100 * e['reduction']:6.1f} %  "
                     f"{_fmt_params(e['params'], e['ci'])}{undetermined}")
    b = result.get("baseline") or {}
    if b:
        determined = _fmt_params(b["params"], b["ci"]) or "neither b nor d determined"
        prob = "" if b.get("probability") is None else f"{100 * b['probability']:.1f} %, "
        lines.append(f"  (nominal_refit b,d: {prob}{determined})")
    for note in result.get("notes", []):
        lines.append(f"note: {note}")
    return "\n".join(lines) + "\n"


def write_html(path: str | Path, result) -> Path:
    """The report (:func:`quadsim.gap.page.page`: the answer first, figures as inline SVG, a
    unit in every table cell) with the JSON in a collapsed appendix, written atomically."""
    from .page import page

    return atomic_write_text(path, page(result, to_json(result)))


def write_rerun(path: str | Path, result) -> Path | None:
    """The residual series of the report (:func:`quadsim.gap.report.recording`) as a rerun
    recording via :func:`quadsim.viewer.try_save_recording` (None and a message when there
    is none or the viewer is unavailable)."""
    pass

    options = recording(result)
    if options is None:
        print("note: --rerun: no residual series in this result; skipped")
        return None
    try:
        from ..viewer import try_save_recording
    except ImportError as exc:  # pragma: no cover - viewer is part of the package
        print(f"note: --rerun skipped: {exc}")
        return None
    return try_save_recording(path, **options)


def _short(path: str) -> str:
    return Path(path).name


def _prob(f: dict) -> str:
    p = f.get("probability")
    return "-" if p is None else f"{100 * p:.0f} %"


def flights_summary(result: dict) -> str:
    """A few lines for people: the answer, then per flight its answer and its residual
    against the references' before and after it (the words of the report)."""
    model = result.get("reference_model", {})
    lines = [f"answer: {result['verdict'].get('answer', '')}",
             (f"per-flight diagnosis against {len(result['reference'])} reference flights "
              f"(reference model: {len(model.get('params', {}))} shared parameters calibrated)")]
    for f in result["flights"]:
        answer = f.get("answer", "")
        said = answer.startswith(f["verdict"]) or f["outcome"] == "refused"
        lines.append(f"  {_short(f['file'])}: " + (answer if said else
                                                   f"{f['verdict']} ({_prob(f)}): {answer}"))
        if f.get("residual"):        # the report's words (quadsim.gap.words.residual_text)
            lines.append(f"    {f['residual']['text']}")
    lines += [f"note: {note}" for note in gather_delay_notes(result.get("notes", []))]
    return "\n".join(lines) + "\n"


_UNRESOLVED = re.compile(r"^(?P<file>.*): (?P<signal>\w+): delay not resolvable from this log "
                         r"\(the two halves give (?P<a>\S+) and (?P<b>\S+) ms, (?P<why>.*)\)$")


_ESTIMATED = re.compile(r"^(?P<file>.*): signal delays vs motion capture: (?P<values>.*?) "
                        r"\((?P<how>estimated.*)\)$")


def gather_delay_notes(notes: list[str]) -> list[str]:
    """Notes with the signal delays of many flights gathered
    (:func:`quadsim.logs.delays.delay_notes`): the estimated delays in one line, the
    unresolved ones in one line per signal; other notes as they are."""
    out, seen, estimated = [], {}, []
    for note in notes:
        m = _UNRESOLVED.match(note)
        e = _ESTIMATED.match(note)
        if e is not None:
            if not estimated:
                out.append("")
                where = (len(out) - 1, e["how"])
            estimated.append(f"{_short(e['file'])} {e['values']}")
            continue
        if m is None:
            out.append(note)
            continue
        if m["signal"] not in seen:
            seen[m["signal"]] = (len(out), m["why"], [])
            out.append("")
        seen[m["signal"]][2].append(f"{_short(m['file'])} ({m['a']} / {m['b']} ms)")
    if estimated:
        out[where[0]] = (f"signal delays vs motion capture ({where[1]}): "
                         + "; ".join(estimated))
    for signal, (k, why, files) in seen.items():
        out[k] = (f"{signal}: delay not resolvable on {len(files)} flight"
                  f"{'s' if len(files) > 1 else ''}, the two halves of each log disagree "
                  f"({why}): {', '.join(files)}")
    return out


def named_candidate(result: dict) -> str | None:
    """The candidate the verdict named (a combination's name when one was kept), or None;
    a name the lead rule gave the lead (``body_drag`` for the wind reading that carries it,
    :func:`quadsim.gap.judge.reading_name`) is the most probable candidate's."""
    verdict = result.get("verdict", {})
    if verdict.get("outcome") != "effect":
        return None
    combined = result.get("combination")
    if combined:
        return combined["name"]
    name, entries = verdict.get("effect"), result.get("effects") or []
    if entries and not any(e["name"] == name for e in entries):
        return entries[0]["name"]
    return name


def added_effects(result: dict, name: str | None, *, logs: str,
                  base: tuple[str, ...] = ()) -> list[tuple[str, dict]]:
    """[(effect, {parameter: (value, source)})] of the candidate ``name`` (default: the named
    one) of a ``quadsim.gap/3`` result; ``logs`` words the fitting data for the sources;
    ``base``: effect names already in the model (refused again)."""
    name = name or named_candidate(result)
    if name is None:
        raise InputError("--write-effects: the diagnosis named no effect; choose a ranked "
                         "candidate with --add NAME")
    entries = list(result.get("effects", []))
    if result.get("combination"):
        entries.append(result["combination"])
    entry = next((e for e in entries if e["name"] == name), None)
    if entry is None:
        raise InputError(f"--add: {name!r} is not a fitted candidate of this diagnosis; "
                         f"fitted: {', '.join(e['name'] for e in entries)}")
    share = 100.0 * float(entry["reduction"])
    out: dict[str, dict] = {}
    for key, value in entry["params"].items():
        effect, _, parameter = key.partition(".")
        if effect in base:
            raise InputError(f"--add: {effect} is already in --effects-file (an effect file "
                             "holds each effect once)")
        declared = {p.name for p in EFFECTS[effect].parameters} if effect in EFFECTS else set()
        if parameter not in declared:
            raise InputError(f"--add: {name}: {key} is fitted in the diagnosis' own "
                             "parametrisation, not a library parameter; write it by hand")
        ci = entry["ci"].get(key)
        flag = "" if entry.get("identifiable", {}).get(key, True) else \
            "; not identified (at a bound or CI wider than half the plausible range)"
        out.setdefault(effect, {})[parameter] = (float(value), (
            f"python -m quadsim.gap on {logs}: {name} candidate, {value:.4g} +- {ci:.2g} "
            f"(95 % CI){flag}; {share:.1f} % of the held-out gap"))
    return list(out.items())


__getattr__ = refuse_moved(__name__, {
    "flights_html": "is gone: the whole page is quadsim.gap.page.page(result) (HTML text), "
                    "or write_html(path, result)"})


_WRENCH = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


def _bands(result, series) -> np.ndarray | None:
    if series.sigma is not None:
        return np.asarray(series.sigma, float)
    channels = (result.get("verdict") or {}).get("channels") or {}
    if not channels:
        return None
    return np.array([channels[c]["floor"] if c in channels else np.nan
                     for c in series.channels])


def recording(result) -> dict | None:
    """Keyword arguments of :func:`quadsim.viewer.try_save_recording` for ``result`` (a
    :class:`~quadsim.gap.result.Diagnosis`): ``params``, ``trajectories`` (flight name ->
    its logged :class:`~quadsim.vehicle.state.Trajectory`), ``residuals`` ("channel
    flight" -> (t, (N, K) values, labels: before, after, band + and -)), ``title``,
    ``tab``. None when the result holds no series (a result read back from JSON)."""
    from ..vehicle.state import Trajectory

    if result.get("mode") == "per-flight":
        series = [f.series for f in getattr(result, "flights", ())
                  if getattr(f, "series", None) is not None]
    else:
        series = list(getattr(result, "held_series", ()) or ())
        if not series and getattr(result, "series", None) is not None:
            series = [result.series]
    if not series:
        return None
    trajectories, residuals = {}, {}
    for s in series:
        name = Path(str(s.flight)).name
        st = s.states
        if getattr(st, "position", None) is not None and getattr(st, "quat", None) is not None:
            trajectories[name] = Trajectory(st.t, st.position, st.velocity, st.quat,
                                            st.body_rate, st.rotor_speed, engine="log")
        band = _bands(result, s)
        for k, channel in enumerate(s.channels):
            if channel not in _WRENCH:
                continue
            columns = [s.before[:, k], s.after[:, k]]
            labels = ["before", "after"]
            if band is not None and np.isfinite(band[k]):
                half = np.full(len(s.t), Z95 * band[k])
                columns += [half, -half]
                labels += ["band +", "band -"]
            residuals[f"{channel} {name}"] = (np.asarray(s.t, float),
                                              np.stack(columns, axis=1), labels)
    return {"params": series[0].params, "trajectories": trajectories,
            "residuals": residuals, "title": "quadsim gap: residual wrench before and after "
            "the answer", "tab": "residuals"}
