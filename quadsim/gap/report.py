"""Outputs of the gap diagnosis: JSON (``quadsim.gap/3``), a human summary that leads with
the answer in words, an HTML report (answer, evidence per flight with units, plots, the JSON
in a collapsed appendix), and a rerun recording of the residuals.

Sections, in the order of the file:

1. **The result's JSON Schema** (:data:`GAP_SCHEMA`, :func:`validate`).
2. **JSON, the summary, the HTML page and the rerun recording** (:func:`to_json`,
   :func:`write_json`, :func:`summary`, :func:`write_html`, :func:`write_rerun`).
3. **The per-flight summary and page** (:func:`flights_summary`, :func:`flights_html`).
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

Per-flight outputs
------------------
The text summary and the HTML page of ``--per-flight`` results. The page opens with one table --
flight, verdict, probability, magnitude of the leading reading, what remains (channels beyond the
reference flights, or nothing; a refused flight's reason) -- and states each answer there only.
Below it: the shared symptoms (flights whose largest mean residual against the reference model is on
the same channel with the same sign, at least two of them; one column per verdict listing those
flights, so the readings of one symptom stand side by side), the other readings per flight
(runners-up with their magnitudes, what would separate the leaders), one table of every flight's
signal delays and delay notes, the remaining notes, and the reference model. Only values the data
determine are shown (:mod:`quadsim.gap.judge`; a reference value the reference flights do
not determine is written as such). The page fits a 1400 px window (its style sheet,
:func:`write_html`: long cells wrap). ``tests/test_report_flights.py`` parses it.

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
"""

from __future__ import annotations

import base64
import html
import io
import json
import re
from pathlib import Path

import numpy as np

from ..core.errors import InputError
from ..core.files import atomic_write_text
from ..effects import EFFECTS
from .residual import channel_unit
from .result import plain

__all__ = ["GAP_SCHEMA", "added_effects", "document", "flights_html", "flights_summary",
           "gather_delay_notes", "named_candidate", "summary", "to_json", "validate",
           "write_html", "write_json", "write_rerun"]

# --- the result's JSON Schema -----------------------------------------------------------------

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

#: parameter consistency (quadsim.gap.where): the named candidate refitted per regime.
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
    from .priors import unit_of

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
    lines.append("  by band: " + ", ".join(f"{k} {100 * s:.0f} %"
                                           for k, s in where["band"].items()))
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


def _png(fig) -> str:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90, bbox_inches="tight", metadata={"Software": None})
    import matplotlib.pyplot as plt

    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _figures(result: dict) -> list[tuple[str, str]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figs = []
    series = getattr(result, "series", None)
    if series is not None:
        channels = series.channels[:6]
        fig, axes = plt.subplots(6, 1, figsize=(9, 10), sharex=True)
        for k, ax in enumerate(axes):
            ax.plot(series.t, series.before[:, k], lw=0.8, label="nominal")
            ax.plot(series.t, series.after[:, k], lw=0.8, label="with verdict")
            ax.set_ylabel(f"{channels[k]} ({channel_unit(channels[k])})")
        axes[0].legend(loc="upper right")
        axes[-1].set_xlabel("t (s)")
        figs.append((f"Residual wrench, held-out flight {Path(series.flight).name}", _png(fig)))
    effects = result["effects"]
    if effects:
        fig, ax = plt.subplots(figsize=(8, 3.5))
        names = [e["name"] for e in effects] + ["nominal_refit"]
        values = [100 * e["reduction"] for e in effects] + [100 * result["baseline"]["reduction"]]
        ax.barh(names[::-1], values[::-1])
        ax.set_xlabel("held-out gap reduction (%)")
        figs.append(("Candidate effects", _png(fig)))
    where = result["where"]
    if where.get("kstep_before"):
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
        for key, label in (("kstep_before", "nominal"), ("kstep_after", "with verdict")):
            horizons = [float(h) for h in where[key]]
            pos = [v["position_rms_m"] or np.nan for v in where[key].values()]
            att = [v["attitude_rms_rad"] or np.nan for v in where[key].values()]
            ax[0].loglog(horizons, pos, "o-", label=label)
            ax[1].loglog(horizons, att, "o-", label=label)
        ax[0].set_xlabel("horizon (s)"), ax[0].set_ylabel("position RMS (m)")
        ax[1].set_xlabel("horizon (s)"), ax[1].set_ylabel("attitude RMS (rad)")
        ax[0].legend()
        figs.append(("k-step prediction error (multiple shooting, analytic engine)", _png(fig)))
    return figs


def _flight_html(f: dict, reference: bool) -> str:
    rows = "".join(
        f"<tr><td>{html.escape(k)}</td><td>{c['before']:.3g}</td><td>{c['after']:.3g}</td>"
        f"<td>{c['floor']:.3g}</td><td>{html.escape(c['unit'])}</td>"
        f"<td>{'yes' if c['at_floor'] else 'no'}</td></tr>"
        for k, c in f.get("channels", {}).items())
    floor = "reference flights' held-out RMS" if reference else "noise: 0.5 s scatter"
    table = ("<table><tr><th>channel</th><th>RMS nominal</th><th>RMS with verdict</th>"
             f"<th>floor ({floor})</th><th>unit</th><th>at floor</th></tr>{rows}</table>")
    alts = "".join(
        f"<li><b>{html.escape(a['name'])}</b>: {html.escape(a['magnitude'])}"
        f"{'' if a['plausible'] else ' — <i>implausible magnitude, not named</i>'}"
        f"; torques left: {html.escape(a.get('torque_yaw', ''))}"
        f"{'; separate by: ' + html.escape(a['separate_by']) if a.get('separate_by') else ''}"
        f"{'; prior: ' + html.escape(a['prior']) if a.get('prior') else ''}</li>"
        for a in f.get("alternatives", []))
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in f.get("notes", []))
    return (f"<p><b>{html.escape(f.get('answer', ''))}</b></p>{table}"
            + (f"<p>Collinear alternatives (most plausible first):</p><ul>{alts}</ul>"
               if alts else "") + (f"<ul>{notes}</ul>" if notes else ""))


def write_html(path: str | Path, result: dict) -> Path:
    """A self-contained HTML page: the answer in words, the evidence per flight (residual
    RMS before/after with units against the floor, alternatives), plots (base64 PNG), and
    the JSON in a collapsed appendix."""
    per_flight = result.get("mode") == "per-flight"
    body = [f"<h1>quadsim gap diagnosis: {html.escape(str(result.get('model', '')))}</h1>",
            f"<h2>Answer</h2><p><b>{html.escape(result['verdict'].get('answer', ''))}</b></p>"]
    if per_flight:
        body = body[:1] + flights_html(result)
    else:
        body.append("<h2>Evidence</h2>" + _flight_html(result["verdict"], False))
        body.append(f"<h2>Summary</h2><pre>{html.escape(summary(result))}</pre>")
        for title, png in _figures(result):
            body.append(f"<h2>{html.escape(title)}</h2><img src=\"data:image/png;base64,{png}\">")
    body.append(f"<details><summary>Appendix: result JSON ({html.escape(result['schema'])})"
                f"</summary><pre>{html.escape(to_json(result))}</pre></details>")
    page = ("<!doctype html><html><head><meta charset=\"utf-8\"><title>quadsim gap</title>"
            "<style>body{font-family:sans-serif;max-width:1400px;margin:auto}"
            "img{max-width:100%}table{border-collapse:collapse;max-width:100%}"
            "td,th{border:1px solid #ccc;padding:2px 6px;text-align:left;"
            "vertical-align:top;overflow-wrap:anywhere}"
            "pre{white-space:pre-wrap;overflow-wrap:anywhere}</style></head><body>"
            + "\n".join(body) + "</body></html>\n")
    return atomic_write_text(path, page)


def write_rerun(path: str | Path, result: dict) -> Path | None:
    """Residual wrench (nominal and with the verdict) over the first held-out flight, via
    :func:`quadsim.viewer.try_save_recording` (None and a message when unavailable)."""
    series = getattr(result, "series", None)
    if series is None:
        print("note: --rerun: no residual series in this result (per-flight mode); skipped")
        return None
    try:
        from ..viewer import try_save_recording
    except ImportError as exc:  # pragma: no cover - viewer is part of the package
        print(f"note: --rerun skipped: {exc}")
        return None
    from ..vehicle.state import Trajectory

    s = series.states
    flight = Trajectory(s.t, s.position, s.velocity, s.quat, s.body_rate, s.rotor_speed,
                        engine="log")
    labels = list(series.channels[:6])
    residuals = {"nominal": (s.t, series.before[:, :6], labels),
                 "with_verdict": (s.t, series.after[:, :6], labels)}
    return try_save_recording(path, params=series.params, trajectories={"log": flight},
                              residuals=residuals, title="quadsim gap: residual wrench",
                              tab="residuals")


# --- per-flight outputs -----------------------------------------------------------------------

def _short(path: str) -> str:
    return Path(path).name


def _lead(f: dict) -> dict:
    return f["posterior"][0] if f.get("posterior") else {}


def _remains(f: dict) -> str:
    if f["outcome"] == "refused":
        return f.get("reason", "")
    lack = f.get("lack_of_fit") or {}
    if lack:
        return ", ".join(f"{k} {v:.2g}x the references" for k, v in lack.items())
    return "nothing beyond the reference flights"


def _prob(f: dict) -> str:
    p = f.get("probability")
    return "-" if p is None else f"{100 * p:.0f} %"


def flights_summary(result: dict) -> str:
    """A few lines for people: the answer, then one line per flight."""
    model = result.get("reference_model", {})
    lines = [f"answer: {result['verdict'].get('answer', '')}",
             (f"per-flight diagnosis against {len(result['reference'])} reference flights "
              f"(reference model: {len(model.get('params', {}))} shared parameters calibrated)")]
    for f in result["flights"]:
        answer = f.get("answer", "")
        said = answer.startswith(f["verdict"]) or f["outcome"] == "refused"
        lines.append(f"  {_short(f['file'])}: " + (answer if said else
                                                   f"{f['verdict']} ({_prob(f)}): {answer}"))
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


def _table(head: list[str], rows: list[list[str]]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                   for r in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def _groups(flights: list[dict]) -> str:
    groups: dict[tuple, list[dict]] = {}
    for f in flights:
        s = f.get("symptom") or {}
        if s and f["outcome"] != "refused" and s.get("sigmas", 0) >= 1.0:
            groups.setdefault((s["channel"], s["sign"]), []).append(f)
    shared = {key: members for key, members in groups.items() if len(members) >= 2}
    counts: dict[str, int] = {}
    for members in shared.values():
        for f in members:
            counts[f["verdict"]] = counts.get(f["verdict"], 0) + 1
    order = sorted(counts, key=lambda v: (-counts[v], v))
    rows = []
    for (channel, sign), members in sorted(shared.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        verdicts: dict[str, list[str]] = {}
        for f in members:
            verdicts.setdefault(f["verdict"], []).append(_short(f["file"]))
        values = sorted(members, key=lambda f: f["symptom"]["value"])
        span = values[0]["symptom"]["text"]
        if len(values) > 1 and values[-1]["symptom"]["text"] != span:
            span += f" .. {values[-1]['symptom']['text'].split(' ', 1)[-1]}"
        rows.append([f"{channel} {sign}", str(len(members)), span] + [
            f"{len(verdicts.get(v, []))}: {', '.join(verdicts[v])}" if v in verdicts else "-"
            for v in order])
    if not rows:
        return ""
    return ("<h2>Shared symptoms</h2><p>Flights whose largest mean residual against the "
            "reference model lies on the same channel with the same sign, and what each was "
            "judged (one column per verdict).</p>"
            + _table(["symptom", "flights", "range", *order], rows))


def _is_delay_note(note: str) -> bool:
    return "signal delays vs motion capture" in note or "not resolvable" in note


def _delay_remark(f: dict) -> str:
    """A flight's delay notes other than its delay values (an unresolved delay): the part
    after the file name, joined."""
    out = []
    for note in f.get("notes", []):
        if _is_delay_note(note) and "signal delays vs motion capture" not in note:
            out.append(note.split(": ", 1)[-1])
    return "; ".join(out)


def _delays(flights: list[dict], result: dict) -> str:
    """One table of every flight's signal delays (ms) and delay notes, references first."""
    keys = sorted({k for f in flights for k in (f.get("signal_delays_ms") or {})})
    remarks = [_delay_remark(f) for f in flights]
    if not keys and not any(remarks):
        return ""
    ref = (result.get("reference_model") or {}).get("delays_ms", {})
    rows = [["references (mean ± sd)"] + [
        f"{ref[k]['mean']:+.1f} ± {ref[k]['sd']:.1f}" if k in ref else "-" for k in keys] + [""]]
    for f, remark in zip(flights, remarks):
        d = f.get("signal_delays_ms") or {}
        if f["outcome"] == "refused" and not d:
            continue
        rows.append([_short(f["file"])] + ["-" if d.get(k) is None else f"{d[k]:+.1f}"
                                           for k in keys] + [remark])
    return ("<h2>Signal delays against motion capture (ms)</h2><p>Estimated per flight; a "
            "gyro delay of 1.5 samples or more is shifted out before fitting, the others are "
            "reported only.</p>" + _table(["flight"] + keys + ["note"], rows))


def _readings(f: dict) -> str:
    """The readings after the leading one (the table states that one), what separates."""
    items = "".join(
        f"<li><b>{html.escape(r['name'])}</b> {100 * r['probability']:.1f} %: "
        f"{html.escape(r['magnitude'])}"
        + (f" <i>(not determined: {html.escape(', '.join(r['undetermined']))})</i>"
           if r.get("undetermined") else "") + "</li>"
        for r in f.get("posterior", [])[1:4] if r["probability"] >= 0.01)
    extra = ""
    if f.get("differ_on"):
        differ = html.escape(", ".join(f["differ_on"]))
        extra = f"<p>The two leading readings differ most on {differ}.</p>"
    for other, how in (f.get("separate_by") or {}).items():
        extra += f"<p>To separate from {html.escape(other)}: {html.escape(how)}.</p>"
    if not items and not extra:
        return ""
    return (f"<ul>{items}</ul>" if items else "") + extra


def flights_html(result: dict) -> list[str]:
    """The body parts of the per-flight page (module doc)."""
    flights = result["flights"]
    rows = [[_short(f["file"]), f["verdict"], _prob(f),
             _lead(f).get("magnitude", "") if f["outcome"] == "effect" else
             (f.get("answer", "") if f["outcome"] != "no_significant_gap" else "-"),
             _remains(f)] for f in flights]
    body = [f"<p><b>{html.escape(result['verdict'].get('answer', ''))}</b></p>",
            _table(["flight", "verdict", "probability", "magnitude", "what remains"], rows),
            _groups(flights)]
    others = [(f, _readings(f)) for f in flights if f["outcome"] != "refused"]
    if any(text for _, text in others):
        body.append("<h2>Other readings per flight</h2>")
        body += [f"<h3>{html.escape(_short(f['file']))}</h3>" + text for f, text in others
                 if text]
    body.append(_delays(flights, result))
    notes = [n for f in flights for n in f.get("notes", []) if not _is_delay_note(n)]
    notes += gather_delay_notes(result.get("notes", []))     # the references' own
    if notes:
        body.append("<h2>Notes</h2><ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes)
                    + "</ul>")
    body.append(_reference_model(result.get("reference_model") or {}))
    return [part for part in body if part]


def _reference_model(model: dict) -> str:
    """The shared parameters of the reference model; a value the reference flights do not
    determine (``identified`` false) is not printed as a value."""
    if not model:
        return ""
    known = model.get("identified", {})
    rows = []
    for k, v in model["params"].items():
        if known.get(k, True):
            rows.append([k, f"{v:.4g}", f"{model['se'].get(k, float('nan')):.2g}",
                         f"{model['scatter'].get(k, float('nan')):.2g}"])
        else:
            rows.append([k, "not determined by the reference flights", "-", "-"])
    return ("<h2>Reference model</h2>"
            + _table(["shared parameter", "value", "standard error", "scatter"], rows))


# --- a diagnosed model as an effect file ------------------------------------------------------

def named_candidate(result: dict) -> str | None:
    """The candidate the verdict named (a combination's name when one was kept), or None."""
    verdict = result.get("verdict", {})
    if verdict.get("outcome") != "effect":
        return None
    combined = result.get("combination")
    return combined["name"] if combined else verdict.get("effect")


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
