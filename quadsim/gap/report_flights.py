"""Per-flight outputs: the text summary and the HTML page of ``--per-flight`` results.

The page opens with one table -- flight, verdict, probability, magnitude of the leading
reading, what remains (channels beyond the reference flights, or nothing; a refused
flight's reason) -- and states each answer there only. Below it: the shared symptoms
(flights whose largest mean residual against the reference model is on the same channel with
the same sign, at least two of them; one column per verdict listing those flights, so the
readings of one symptom stand side by side), the other readings per flight (runners-up with
their magnitudes, what would separate the leaders), one table of every flight's signal
delays and delay notes, the remaining notes, and the reference model. Only values the data
determine are shown (:mod:`quadsim.gap.judge`; a reference value the reference flights do
not determine is written as such). The page fits a 1400 px window (:mod:`quadsim.gap.report`:
long cells wrap). ``tests/test_report_flights.py`` parses it.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

__all__ = ["flights_html", "flights_summary", "gather_delay_notes"]


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
        extra = f"<p>The two leading readings differ most on {html.escape(', '.join(f['differ_on']))}.</p>"
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
