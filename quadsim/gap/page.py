"""The HTML report an engineer reads (``python -m quadsim.gap ... --report OUT.html``): one
self-contained page, no network (figures inline SVG, :mod:`quadsim.gap.plots`).

Per flight, the first screen answers the question for the batch and for each flight: the
batch's verdict counts, the references' self-check in one line, then one row per flight --
the verdict, the leading reading and its probability among the readings weighed, what
differs (the reading's magnitude with 95 % intervals), how large the residual is against the
references' RMS before and after the answer, the share of its excess the answer removes, and
what remains beyond the references (the lack of fit). The figure across flights follows;
then per flight its answer, the residual against time and against speed and thrust (before
and after, over the references' band), and every reading weighed with its magnitude; one
compact table of signal delays; the notes; the reference model with a unit in every cell;
the JSON in a collapsed appendix.

Held out, the page opens with the answer, the table of channels (RMS before, after and the
floor, each with its unit), the ranking, then the residual of the held-out flight against
time and against speed and thrust, and the k-step errors.

Every sentence is the result's own (``answer``, ``magnitude``: :mod:`quadsim.gap.words`);
the page adds numbers and their units, never other words for the same thing. A table cell
holds a name (a flight, a verdict, a reading, a channel, a parameter) or a value with its
unit; ``tests/test_report_html.py`` checks it.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

import numpy as np

from . import plots

__all__ = ["page"]

_CSS = (
    "body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;max-width:1400px;"
    "margin:auto;padding:0 14px 40px;color:#222;line-height:1.35}"
    "h1{font-size:1.45em;margin:14px 0 6px}h2{font-size:1.2em;margin:26px 0 6px;"
    "border-bottom:1px solid #ddd}h3{font-size:1.05em;margin:16px 0 4px}"
    ".answer{background:#f3f6fa;border-left:4px solid #1f77b4;padding:6px 14px;margin:8px 0}"
    ".answer p{margin:4px 0}"
    "table{border-collapse:collapse;margin:6px 0 10px}"
    "td,th{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top}"
    "th{background:#f7f7f7;font-weight:600;font-size:.92em}"
    "td.name{white-space:nowrap}td.wrap{white-space:normal}td.value{white-space:nowrap;text-align:right}"
    "td.words{min-width:200px;max-width:440px}.key{font-size:.85em;color:#555;margin-top:0}"
    ".effect{color:#1f77b4}.no_significant_gap{color:#2ca02c}.unexplained{color:#d62728}"
    ".refused{color:#7f7f7f}figure{margin:8px 0}svg{max-width:100%;height:auto}"
    "figcaption{font-size:.9em;color:#555}"
    "pre{white-space:pre-wrap;overflow-wrap:anywhere;font-size:.85em}")


def _e(text) -> str:
    return html.escape(str(text))


def _short(path) -> str:
    return Path(str(path)).name


class _Cell:
    """A table cell: ``kind`` ``name`` (a name or words, no number needs a unit),
    ``value`` (a number with its unit, right-aligned) or ``words`` (a sentence with units)."""

    def __init__(self, text, kind: str = "value", css: str = ""):
        self.text, self.kind, self.css = str(text), kind, css

    def html(self) -> str:
        css = f"{self.kind} {self.css}".strip()
        # a pair's name may break after its "+", never inside a name
        text = re.sub(r"(?<=[a-z_])\+(?=[a-z])", "+<wbr>", _e(self.text))
        return f'<td class="{css}">{text}</td>'


def _name(text, css: str = "") -> _Cell:
    return _Cell(text, "name", css)


def _words(text) -> _Cell:
    return _Cell(text, "words")


def _table(head: list[str], rows: list[list[_Cell]]) -> str:
    header = "".join(f"<th>{_e(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(c.html() for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{header}</tr>{body}</table>"


def _figure(svg_text: str, caption: str) -> str:
    if not svg_text:
        return ""
    return f"<figure>{svg_text}<figcaption>{_e(caption)}</figcaption></figure>"


def _pct(p) -> str:
    return "-" if p is None else (f"{100 * p:.0f} %" if p < 0.995 else "> 99 %")


def _pct1(p) -> str:
    """A probability to 0.1 %: "< 0.1 %" and "> 99.9 %" at the ends."""
    if p is None:
        return "-"
    return "< 0.1 %" if p < 5e-4 else (f"{100 * p:.1f} %" if p < 0.9995 else "> 99.9 %")


def _unit(key: str) -> str:
    from .priors import unit_of

    unit = unit_of(key)
    return "(relative)" if unit in ("1", "") else unit


def _value(v: float, unit: str) -> str:
    return f"{v:.4g} {unit}"


# --- per flight ---------------------------------------------------------------------------

def _share(f):
    series = getattr(f, "series", None)
    if series is None or series.sigma is None:
        return None
    return series.share()


def _residual_cells(f, share) -> list[_Cell]:
    if share is None:
        return [_name("-"), _name("-")]
    first, last = int(np.argmax(share.before)), int(np.argmax(share.after))
    cell = (f"{share.before[first]:.2g}x ({share.channels[first]}) -> "
            f"{share.after[last]:.2g}x ({share.channels[last]})")
    removed = ("-" if share.removed is None or f["outcome"] == "no_significant_gap"
               else f"{100 * share.removed:.0f} %")
    return [_Cell(cell), _Cell(removed) if removed != "-" else _name(removed)]


def _remains(f) -> _Cell:
    if f["outcome"] == "refused":
        return _words(f.get("reason", ""))
    lack = f.get("lack_of_fit") or f.get("form_remainder") or {}
    if not lack:
        return _name("nothing beyond the references", "wrap")
    return _words(", ".join(f"{k} {v:.2g}x" for k, v in lack.items()))


def _lead(f) -> dict:
    return f["posterior"][0] if f.get("posterior") else {}


def _first_screen_rows(flights) -> list[list[_Cell]]:
    rows = []
    for f in flights:
        lead = _lead(f)
        what = (lead.get("magnitude", "") if f["outcome"] != "refused" else "not judged")
        reading = (f"{lead['name']} {_pct(lead['probability'])}" if lead else "-")
        rows.append([_name(_short(f["file"])), _name(f["verdict"], f"{f['outcome']} wrap"),
                     _words(reading) if lead else _name(reading), _words(what),
                     *_residual_cells(f, _share(f)), _remains(f)])
    return rows


_FIRST_HEAD = ["flight", "verdict", "leading reading (probability*)",
               "what differs (95 % intervals)", "residual before -> after the answer**",
               "excess removed", "what remains***"]
_FIRST_KEY = ("* among the readings weighed for that flight, the leading one's (of a verdict "
              "unexplained too: the best reading, which still leaves too much). ** the "
              "largest channel's RMS over the references' RMS. *** the channels the answer "
              "leaves beyond the references' typical RMS, as that ratio (lack of fit; of a "
              "tentative name, what it leaves).")


def _self_check(model: dict) -> str:
    check = (model or {}).get("self_check")
    if not check:
        return ("Reference self-check: not run (this version does not judge each reference "
                "against the others).")
    if check.get("text"):
        return str(check["text"])
    n, alarms = len(check.get("flights", [])), check.get("false_alarms", [])
    if not alarms:
        return (f"Reference self-check: each of the {n} reference flights, judged against "
                "the others, comes out no_significant_gap.")
    which = ", ".join(f"{_short(a['flight'])} ({a['verdict']})" for a in alarms[:4])
    return (f"Reference self-check: {len(alarms)} of the {n} reference flights, judged "
            f"against the others, are not no_significant_gap: {which}"
            + ("" if check.get("clean", True) else "; the references disagree with each other")
            + ".")


def _readings(f) -> str:
    """Every reading weighed with its probability and magnitude; those below 0.1 % named in
    one row."""
    shown = [r for r in f.get("posterior", []) if r["probability"] >= 1e-3]
    rest = [r["name"] for r in f.get("posterior", []) if r["probability"] < 1e-3]
    rows = [[_name(r["name"]), _Cell(_pct1(r["probability"])),
             _words(r["magnitude"] + (f" (not determined: {', '.join(r['undetermined'])})"
                                      if r.get("undetermined") else ""))] for r in shown]
    if rest:
        rows.append([_name(f"{len(rest)} more readings", "wrap"), _Cell("< 0.1 % each"),
                     _name(", ".join(rest), "wrap")])
    text = _table(["reading", "probability among the readings weighed",
                   "magnitude (95 % intervals)"], rows)
    post = f.get("posterior", [])
    if f.get("differ_on") and len(post) > 1:
        text += (f"<p>The two leading readings ({_e(post[0]['name'])}, {_e(post[1]['name'])})"
                 f" differ most on {_e(', '.join(f['differ_on']))}.</p>")
    for other, how in (f.get("separate_by") or {}).items():
        text += f"<p>To separate {_e(f['verdict'])} from {_e(other)}: {_e(how)}.</p>"
    return text


def _flight_section(f) -> str:
    name = _short(f["file"])
    parts = [f'<h3 id="{_e(name)}">{_e(name)} <span class="{_e(f["outcome"])}">'
             f'{_e(f["verdict"])}</span></h3>',
             f'<p title="{_e(f["file"])}">{_e(f.get("answer", ""))}</p>']
    if f["outcome"] == "refused":
        return "".join(parts)
    share = _share(f)
    series = getattr(f, "series", None)
    if share is not None:
        from .words import residual_text

        parts.append(f"<p>{_e(residual_text(share, f['outcome']))}</p>")
        parts.append(_figure(plots.residual_time(series, series.sigma),
                             f"{name}: residual force and torque against time, before the "
                             "answer (the reference model) and after it (the answer fitted), "
                             "over the references' 95 % band (±1.96 x their RMS)."))
        parts.append(_figure(plots.residual_against(series, series.sigma),
                             f"{name}: where the gap lives: the mean residual in bins of "
                             "speed and of collective thrust, on the three channels with the "
                             "largest residual before the answer."))
    parts.append(_readings(f))
    notes = [n for n in f.get("notes", []) if not _is_delay_note(n)]
    if notes:
        parts.append("<ul>" + "".join(f"<li>{_e(n)}</li>" for n in notes) + "</ul>")
    return "".join(parts)


# --- shared symptoms ----------------------------------------------------------------------

def _symptoms(flights) -> str:
    """Flights whose largest mean residual against the reference model (``symptom``, one
    sigma or more) lies on the same channel with the same sign, two or more of them: one
    row per symptom, its range, and the flights per verdict."""
    groups: dict[tuple, list] = {}
    for f in flights:
        s = f.get("symptom") or {}
        if s and f["outcome"] != "refused" and s.get("sigmas", 0) >= 1.0:
            groups.setdefault((s["channel"], s["sign"]), []).append(f)
    shared = {key: members for key, members in groups.items() if len(members) >= 2}
    rows = []
    for (channel, sign), members in sorted(shared.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        values = sorted(members, key=lambda f: f["symptom"]["value"])
        span = values[0]["symptom"]["text"]
        if len(values) > 1 and values[-1]["symptom"]["text"] != span:
            span += f" .. {values[-1]['symptom']['text'].split(' ', 1)[-1]}"
        verdicts: dict[str, list[str]] = {}
        for f in members:
            verdicts.setdefault(f["verdict"], []).append(_short(f["file"]))
        judged = "; ".join(f"{v}: {', '.join(names)}" for v, names in
                           sorted(verdicts.items(), key=lambda kv: (-len(kv[1]), kv[0])))
        rows.append([_name(f"{channel} {sign}"), _Cell(f"{len(members)} flights"),
                     _Cell(span), _name(judged, "wrap")])
    if not rows:
        return ""
    return ("<h2>Shared symptoms</h2><p>Flights whose largest mean residual against the "
            "reference model lies on the same channel with the same sign, and what each was "
            "judged.</p>" + _table(["symptom", "flights", "range", "verdicts"], rows))


# --- delays --------------------------------------------------------------------------------

_DELAY = re.compile(r"^(.*?): signal delays vs motion capture: (.*?) \(estimated")
_UNRESOLVED = re.compile(r"^(.*?): (\w+):? delay not resolvable")
_PAIR = re.compile(r"(\w+) ([+-]?\d+(?:\.\d+)?) ms")


def _is_delay_note(note: str) -> bool:
    return bool(_DELAY.match(note) or _UNRESOLVED.match(note)) or \
        "signal delays vs motion capture" in note or "not resolvable" in note


def _delays(result) -> str:
    """One table: a row per reference (from their notes) and per judged flight, a column
    per signal (ms against motion capture; "not resolvable" where the log's halves
    disagree), the references' mean +- sd below them."""
    table: dict[str, dict[str, str]] = {}
    notes = list(result.get("notes", [])) + [n for f in result["flights"]
                                             for n in f.get("notes", [])]
    for note in notes:
        m = _DELAY.match(note)
        if m:
            for sig, val in _PAIR.findall(m.group(2)):
                table.setdefault(_short(m.group(1)), {})[sig] = f"{float(val):+.1f} ms"
        m = _UNRESOLVED.match(note)
        if m:
            table.setdefault(_short(m.group(1)), {})[m.group(2)] = "not resolvable"
    for f in result["flights"]:
        for sig, val in (f.get("signal_delays_ms") or {}).items():
            if val is not None:
                table.setdefault(_short(f["file"]), {}).setdefault(sig, f"{val:+.1f} ms")
    if not table:
        return ""
    ref = (result.get("reference_model") or {}).get("delays_ms", {})
    signals = sorted({s for row in table.values() for s in row} | set(ref))
    refs = [_short(r) for r in result.get("reference", [])]
    judged = [_short(f["file"]) for f in result["flights"]]
    rows = []
    for name in refs + [n for n in judged if n not in refs]:
        row = table.get(name, {})
        role = "reference" if name in refs else "judged"
        rows.append([_name(name), _name(role)] + [
            _Cell(row[s]) if s in row and row[s].endswith("ms") else _name(row.get(s, "-"))
            for s in signals])
    if ref:
        rows.append([_name("references"), _name("mean ± sd")] + [
            _Cell(f"{ref[s]['mean']:+.1f} ± {ref[s]['sd']:.1f} ms") if s in ref else
            _name("-") for s in signals])
    return ("<h2>Signal delays against motion capture</h2><p>Estimated per log (positive: "
            "the signal lags); a gyro delay of 1.5 samples or more is shifted out before "
            "fitting, the others are reported only; not resolvable: the log's two halves "
            "disagree by more than 4 ms.</p>"
            + _table(["flight", "role", *(f"{s} (ms)" for s in signals)], rows))


# --- reference model -----------------------------------------------------------------------

def _reference_model(model: dict) -> str:
    if not model:
        return ""
    known = model.get("identified", {})
    rows = []
    for k, v in model["params"].items():
        unit = _unit(k)
        if known.get(k, True):
            rows.append([_name(k), _Cell(_value(v, unit)),
                         _Cell(_value(model["se"].get(k, float("nan")), unit)),
                         _Cell(_value(model["scatter"].get(k, float("nan")), unit))])
        else:
            rows.append([_name(k), _name("not determined by the reference flights"),
                         _name("-"), _name("-")])
    sigma = model.get("sigma", {})
    from .residual import channel_unit

    noise = [[_name(c), _Cell(_value(s, channel_unit(c)))] for c, s in sigma.items()]
    return ("<h2>Reference model</h2><p>What the reference flights share, calibrated on "
            "them: each shared parameter's value, the standard error of the pooled fit and "
            "the scatter between flights.</p>"
            + _table(["shared parameter", "value", "standard error", "scatter between "
                      "flights"], rows)
            + "<p>The references' residual RMS per channel (the band in the figures is "
              "±1.96 times it):</p>" + _table(["channel", "residual RMS"], noise))


# --- the page ------------------------------------------------------------------------------

def _per_flight(result) -> list[str]:
    flights = list(result.flights) if hasattr(result, "flights") else result["flights"]
    model = result.get("reference_model") or {}
    body = ['<div class="answer">',
            f"<p><b>{_e(result['verdict'].get('answer', ''))}</b> "
            f"({len(result.get('reference', []))} reference flights)</p>",
            f"<p>{_e(_self_check(model))}</p></div>",
            _table(_FIRST_HEAD, _first_screen_rows(flights)),
            f'<p class="key">{_e(_FIRST_KEY)}</p>', _symptoms(flights)]
    judged = [f for f in flights if f["outcome"] != "refused"]
    shares = {f["file"]: s for f in judged if (s := _share(f)) is not None}
    if len(judged) > 1 and hasattr(judged[0], "outcome"):
        body.append(_figure(plots.batch(judged, shares),
                            "Across flights: the residual over the references' RMS before "
                            "(open) and after (filled) each answer, and the leading readings' "
                            "values with their 95 % intervals, flights grouped by verdict."))
    body.append("<h2>Each flight</h2>")
    body += [_flight_section(f) for f in flights]
    body.append(_delays(result))
    notes = [n for n in result.get("notes", []) if not _is_delay_note(n)]
    if notes:
        body.append("<h2>Notes</h2><ul>" + "".join(f"<li>{_e(n)}</li>" for n in notes)
                    + "</ul>")
    body.append(_reference_model(model))
    return body


def _held_out(result) -> list[str]:
    v = result["verdict"]
    body = [f'<div class="answer"><p><b>{_e(v.get("answer", v["effect"]))}</b></p>'
            f"<p>Trained on {len(result.get('train', []))} flights, judged on "
            f"{len(result.get('holdout', []))} held out.</p></div>"]
    channels = v.get("channels", {})
    if channels:
        rows = [[_name(k), _Cell(_value(c["before"], c["unit"])),
                 _Cell(_value(c["after"], c["unit"])), _Cell(_value(c["floor"], c["unit"])),
                 _name("yes" if c["at_floor"] else "no")] for k, c in channels.items()]
        body.append(_table(["channel", "RMS, nominal model", "RMS, with the answer",
                            "floor (the training flights' RMS)", "at the floor"], rows))
    ranking = []
    for e in result.get("effects", [])[:8]:
        params = ", ".join(f"{k} = {x:.3g} ± {e['ci'].get(k, float('nan')):.2g} {_unit(k)}"
                           for k, x in e.get("params", {}).items())
        ranking.append([_name(e["name"]), _Cell(_pct1(e.get("probability"))),
                        _Cell(f"{100 * e['reduction']:.1f} %"), _words(params or "-")])
    if ranking:
        body.append("<h2>Readings weighed</h2>" + _table(
            ["reading", "probability among the readings weighed",
             "held-out gap removed", "parameters (95 % intervals)"], ranking))
    held = tuple(getattr(result, "held_series", ()) or ())
    if not held and getattr(result, "series", None) is not None:
        held = (result.series,)
    for series in held if channels else ():
        band = np.array([channels[c]["floor"] if c in channels else np.nan
                         for c in series.channels])
        name = _short(series.flight)
        body.append(f"<h2>Held-out flight {_e(name)}</h2>")
        body.append(_figure(plots.residual_time(series, band),
                            f"{name}: residual force and torque against time, the nominal "
                            "model and with the answer, over the floor's 95 % band."))
        body.append(_figure(plots.residual_against(series, band),
                            f"{name}: the mean residual in bins of speed and of collective "
                            "thrust."))
    body.append(_figure(plots.kstep(result.get("where") or {}),
                        "k-step prediction error (multiple shooting, analytic engine): the "
                        "nominal model and with the answer."))
    notes = result.get("notes", [])
    if notes:
        body.append("<h2>Notes</h2><ul>" + "".join(f"<li>{_e(n)}</li>" for n in notes)
                    + "</ul>")
    return body


def page(result, appendix: str = "") -> str:
    """The report's HTML text of ``result`` (a :class:`~quadsim.gap.result.Diagnosis`, or
    its JSON read back: then without figures); ``appendix``: the result's JSON text, shown
    collapsed at the end."""
    per_flight = result.get("mode") == "per-flight"
    title = f"quadsim gap diagnosis: {result.get('model', '')}"
    body = [f"<h1>{_e(title)}</h1>"] + (_per_flight(result) if per_flight
                                        else _held_out(result))
    if appendix:
        body.append(f"<details><summary>Appendix: the result's JSON "
                    f"({_e(result.get('schema', ''))})</summary><pre>{_e(appendix)}</pre>"
                    "</details>")
    return ("<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>"
            + "\n".join(part for part in body if part) + "</body></html>\n")
