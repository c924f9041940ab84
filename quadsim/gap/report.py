"""Outputs of the gap diagnosis: JSON (``quadsim.gap/3``), a human summary that leads with
the answer in words, an HTML report (answer, evidence per flight with units, plots, the JSON
in a collapsed appendix), and a rerun recording of the residuals.
"""

from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path

import numpy as np

from ..core.files import atomic_write_text
from .residual import channel_unit
from .result import plain

__all__ = ["document", "summary", "to_json", "write_html", "write_json", "write_rerun"]


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
    from .collinear import unit_of

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
        from .report_flights import flights_summary

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
        from .report_flights import flights_html

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
