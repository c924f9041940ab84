"""The HTML report an engineer reads: one self-contained page whose figures are inline SVG
(matplotlib, no pyplot state, no network), and each judged flight's residual series before and
after its answer.

Figures
-------

The report's figures as inline SVG text (matplotlib, no pyplot state, no network).

* :func:`residual_time`: per channel Fx Fy Fz Mx My Mz against time, the residual before the
  answer (under the reference model) and after it (with the answer fitted), over the
  references' band +-1.96 sigma_c (95 % of a reference flight's residual if it were
  Gaussian; sigma_c the references' residual RMS).
* :func:`residual_against`: where the gap lives: the residual's mean in bins of speed (m/s)
  and of collective thrust (N, b sum Omega^2 with the model's b), before and after, for the
  three channels with the largest residual before, over the same band.
* :func:`kstep` (held out): the k-step prediction error of position and attitude against
  the horizon, with the nominal model and with the answer (:mod:`quadsim.gap.judge`).
* :func:`batch`: across flights (one row each, grouped by verdict), the residual against the
  references' level before and after each answer, and each leading reading's determined
  parameters with their 95 % intervals.

Every axis carries its unit; values are drawn with an SI prefix where they are small
(:func:`scale`: mN, mN m, g). Lines longer than :data:`MAX_POINTS` are reduced to each
bin's minimum and maximum (the envelope stays, the file stays small). Each SVG's ids get
a prefix of their own, so several figures share one HTML page.

Residual series
---------------

The residual of one judged flight over time, before and after its answer: the arrays the
report's plots (:mod:`quadsim.gap.page`) and the rerun recording draw.

*Before* is the flight's residual (N, C) under the reference model as calibrated (theta_ref,
the references' rotor timing, less the centre of what the references share beyond the
library, :mod:`quadsim.gap.reference`). *After* is its residual as the judgment weighed the most
probable reading: the reading's own effects at their fitted values (its rotor delay where it
fits one), the shared groups it does not replace at theta_ref, plus the linear step of the
shared parameters and of the discrepancy term its evidence profiles within the references'
spread (:class:`quadsim.gap.evidence.Marginal`): the residual whose per-channel mean square is the
reading's ``ms``, which the lack-of-fit test reads. Channels: Fx Fy Fz (N), Mx My Mz (N m),
then rotor_1..R (rad/s) where the reference has rotor channels
(:func:`quadsim.gap.evidence.flight_residual`).

How much of the gap an answer removes: :meth:`quadsim.gap.result.Series.share`.

The page
--------

The HTML report an engineer reads (``python -m quadsim.gap ... --report OUT.html``): one
self-contained page, no network (figures inline SVG, :mod:`quadsim.gap.page`).

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
import io
import itertools
import re
from pathlib import Path

import numpy as np

from .evidence import FitInputs, flight_residual
from .explanations import marginal_sd
from .judge import channel_names, posterior
from .reference import Reference, jacobian
from .result import Series

__all__ = ["MAX_PANELS", "MAX_POINTS", "batch", "kstep", "residual_against", "residual_time",
           "scale", "svg", "flight_series", "page"]


#: points per drawn line at most (a 1400 px page shows fewer)
MAX_POINTS = 900
#: 95 % two-sided normal quantile: the references' band is +-Z95 sigma_c
Z95 = 1.96
#: bins of speed and thrust in :func:`residual_against` (quantiles: each holds as many samples)
BINS = 16
#: parameter panels of :func:`batch` at most
MAX_PANELS = 5
#: the verdicts' colours (the report's table uses the same)
COLOURS = {"effect": "#1f77b4", "no_significant_gap": "#2ca02c", "unexplained": "#d62728",
           "refused": "#7f7f7f"}
_WRENCH = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
_ids = itertools.count(1)


def scale(unit: str, values) -> tuple[float, str]:
    """(factor, unit) to draw ``values`` given in SI ``unit`` with: milli where their largest
    magnitude is below 0.5 (N -> mN, N m -> mN m, kg -> g), else as they are."""
    top = float(np.nanmax(np.abs(values))) if np.size(values) else 0.0
    if unit == "kg":
        return 1e3, "g"
    if unit in ("N", "N m", "m") and 0 < top < 0.5:
        return 1e3, "m" + unit
    return 1.0, unit


def svg(fig) -> str:
    """The figure as SVG text for inline use (no XML header, ids made unique per figure)."""
    buffer = io.StringIO()
    fig.savefig(buffer, format="svg", bbox_inches="tight", metadata={"Date": None})
    text = buffer.getvalue()
    text = text[text.find("<svg"):]
    prefix = f"q{next(_ids)}-"
    text = re.sub(r'id="([^"]+)"', lambda m: f'id="{prefix}{m.group(1)}"', text)
    return re.sub(r'(url\(#|href="#)([^")]+)', lambda m: f"{m.group(1)}{prefix}{m.group(2)}",
                  text)


def _figure(width: float, height: float):
    import matplotlib

    matplotlib.rcParams["svg.fonttype"] = "none"      # text stays text: small, searchable
    matplotlib.rcParams["svg.hashsalt"] = "quadsim"   # the same figure, the same file
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height))


def _envelope(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` with at most :data:`MAX_POINTS` points: each bin's minimum and maximum."""
    if len(t) <= MAX_POINTS:
        return t, y
    bins = np.array_split(np.arange(len(t)), MAX_POINTS // 2)
    tt, yy = [], []
    for idx in bins:
        lo, hi = idx[np.argmin(y[idx])], idx[np.argmax(y[idx])]
        for k in sorted((lo, hi)):
            tt.append(t[k])
            yy.append(y[k])
    return np.asarray(tt), np.asarray(yy)


def _unit(channel: str) -> str:
    from .residual import channel_unit

    return channel_unit(channel)


def residual_time(series, band, *, title: str = "") -> str:
    """SVG: the residual of ``series`` (:class:`quadsim.gap.result.Series`) against time,
    one panel per wrench channel, before and after, over ``band`` (C,: the references'
    residual RMS sigma_c per channel, channel units; drawn +-1.96 sigma_c)."""
    channels = [c for c in series.channels if c in _WRENCH]
    fig = _figure(9.0, 1.25 * len(channels) + 0.6)
    axes = fig.subplots(len(channels), 1, sharex=True)
    t = np.asarray(series.t, float)
    for ax, name in zip(np.atleast_1d(axes), channels):
        k = list(series.channels).index(name)
        factor, unit = scale(_unit(name), np.concatenate([series.before[:, k],
                                                          series.after[:, k]]))
        half = Z95 * float(band[k]) * factor
        ax.axhspan(-half, half, color="0.85", lw=0, label="references' 95 % band")
        ax.plot(*_envelope(t, factor * series.before[:, k]), lw=0.7, color="#1f77b4",
                label="before: reference model")
        ax.plot(*_envelope(t, factor * series.after[:, k]), lw=0.7, color="#ff7f0e",
                label="after: with the answer")
        ax.set_ylabel(f"{name} ({unit})")
        ax.grid(alpha=0.3)
    first = np.atleast_1d(axes)[0]
    first.legend(loc="lower left", bbox_to_anchor=(0, 1.02), ncol=3, frameon=False,
                 fontsize=8)
    if title:
        fig.suptitle(title, x=0.99, ha="right", fontsize=9)
    np.atleast_1d(axes)[-1].set_xlabel("time (s)")
    return svg(fig)


def thrust(series) -> np.ndarray | None:
    """Collective thrust (N,) in N, b sum_i Omega_i^2 with the model's thrust factor, or None
    without rotor speeds."""
    speed = getattr(series.states, "rotor_speed", None)
    if speed is None:
        return None
    return series.params.thrust_factor * np.sum(np.asarray(speed, float) ** 2, axis=1)


def _binned(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bin centres (mean x) and mean y over :data:`BINS` quantile bins of ``x``."""
    edges = np.unique(np.quantile(x, np.linspace(0, 1, BINS + 1)))
    which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    keep = [b for b in range(len(edges) - 1) if np.any(which == b)]
    return (np.array([x[which == b].mean() for b in keep]),
            np.array([y[which == b].mean() for b in keep]))


def residual_against(series, band) -> str:
    """SVG: the mean residual in bins of speed and of collective thrust, before and after,
    for the three wrench channels whose residual before is largest against ``band`` ("" for
    a flight with neither velocity nor rotor speeds)."""
    wrench = [k for k, c in enumerate(series.channels) if c in _WRENCH]
    sigma = np.asarray(band, float)
    ms = np.mean(series.before ** 2, axis=0) / sigma ** 2
    top = sorted(wrench, key=lambda k: -ms[k])[:3]
    velocity = getattr(series.states, "velocity", None)
    xs = [] if velocity is None else [("speed (m/s)", np.linalg.norm(velocity, axis=1))]
    total = thrust(series)
    if total is not None:
        xs.append(("collective thrust (N)", total))
    if not xs:
        return ""
    fig = _figure(9.0, 2.3 * len(xs) + 0.4)
    axes = np.atleast_2d(fig.subplots(len(xs), len(top)))
    for row, (label, x) in enumerate(xs):
        for col, k in enumerate(top):
            ax = axes[row, col]
            name = series.channels[k]
            factor, unit = scale(_unit(name), series.before[:, k])
            half = Z95 * sigma[k] * factor
            ax.axhspan(-half, half, color="0.85", lw=0)
            for values, colour, what in ((series.before, "#1f77b4", "before"),
                                         (series.after, "#ff7f0e", "after")):
                cx, cy = _binned(x, factor * values[:, k])
                ax.plot(cx, cy, "o-", ms=3, lw=1, color=colour, label=what)
            ax.set_xlabel(label)
            ax.set_ylabel(f"mean {name} ({unit})")
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, frameon=False)
    fig.tight_layout()
    return svg(fig)


def _short(path: str) -> str:
    return Path(str(path)).name


def batch(flights, shares: dict) -> str:
    """SVG across flights, one row per flight (grouped by verdict, coloured as
    :data:`COLOURS`): left, the residual RMS over the references' (the wrench channels'
    mean square, 1 = a reference flight's level) before (open) and after (filled) each
    answer; right, one panel per parameter of the leading readings (at most
    :data:`MAX_PANELS`, the most frequent first, angles and rates last): the determined
    values with their 95 % intervals. ``flights``: :class:`~quadsim.gap.result.Verdict`
    per flight; ``shares``: file -> :class:`quadsim.gap.result.GapShare` (a flight without
    one has no residual row)."""
    from matplotlib.ticker import MaxNLocator

    from .fitting import unit_of

    order = sorted((f for f in flights if f.outcome != "refused"),
                   key=lambda f: (f.name, _short(f.file)))
    if not order:
        return ""
    count: dict[str, int] = {}
    for f in order:
        if f.outcome in ("effect", "unexplained") and f.posterior:
            for key in f.posterior[0].params:
                count[key] = count.get(key, 0) + 1
    # the most frequent first; angles and rates (a swing's state) after the sizes
    keys = sorted(count, key=lambda k: (unit_of(k) in ("rad", "rad/s"), -count[k]))
    keys = keys[:MAX_PANELS]
    fig = _figure(2.2 * (1 + len(keys)) + 1.6, 0.32 * len(order) + 1.5)
    axes = np.atleast_1d(fig.subplots(1, 1 + len(keys), sharey=True))
    y = np.arange(len(order))[::-1]
    colours = [COLOURS.get(f.outcome, "k") for f in order]
    ax = axes[0]
    for k, f in enumerate(order):
        share = shares.get(f.file)
        if share is None:
            continue
        hi = float(np.sqrt(np.mean(share.before[:6] ** 2)))
        lo = float(np.sqrt(np.mean(share.after[:6] ** 2)))
        ax.plot([lo, hi], [y[k], y[k]], color=colours[k], lw=1.5)
        ax.plot(hi, y[k], "o", mfc="white", color=colours[k])
        ax.plot(lo, y[k], "o", color=colours[k])
    ax.axvline(1.0, color="0.5", lw=0.8)
    ax.set_xscale("log")
    from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

    ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0), numticks=6))
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("residual RMS over the\nreferences' (1 = theirs)", fontsize=8)
    for ax, key in zip(axes[1:], keys):
        values = [(k, f.posterior[0].params[key], f.posterior[0].ci.get(key, 0.0))
                  for k, f in enumerate(order) if f.posterior and key in f.posterior[0].params
                  and f.outcome in ("effect", "unexplained")]
        factor, shown = scale(unit_of(key), [v for _, v, _ in values])
        for k, v, ci in values:
            ax.errorbar(factor * v, y[k], xerr=factor * ci, fmt="o", color=colours[k],
                        capsize=3)
        ax.axvline(0.0, color="0.5", lw=0.8)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.set_xlabel(f"{key}\n({'relative' if shown == '1' else shown})", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=8)
    axes[0].set_yticks(y, [_short(f.file) for f in order])
    for tick, colour in zip(axes[0].get_yticklabels(), colours):
        tick.set_color(colour)
    axes[0].set_ylim(-0.7, len(order) - 0.3)
    handles = [axes[0].plot([], [], "o", color=c, label=v)[0] for v, c in COLOURS.items()
               if any(f.outcome == v for f in order)]
    fig.legend(handles=handles, fontsize=8, frameon=False, loc="lower left",
               bbox_to_anchor=(0.0, 1.0), ncol=len(handles))
    fig.tight_layout()
    return svg(fig)


def kstep(where: dict) -> str:
    """SVG (held out): position RMS (m) and attitude RMS (rad) of the k-step prediction
    against the horizon (s), nominal and with the answer (``where["kstep_before"]``,
    ``["kstep_after"]``: horizon -> ``position_rms_m``, ``attitude_rms_rad``); "" without."""
    if not where.get("kstep_before"):
        return ""
    fig = _figure(9.0, 3.0)
    axes = fig.subplots(1, 2)
    for key, label in (("kstep_before", "nominal model"), ("kstep_after", "with the answer")):
        table = where.get(key) or {}
        horizons = [float(h) for h in table]
        for ax, field in zip(axes, ("position_rms_m", "attitude_rms_rad")):
            ax.loglog(horizons, [np.nan if v[field] is None else v[field]
                                 for v in table.values()], "o-", label=label)
    axes[0].set_ylabel("position RMS (m)")
    axes[1].set_ylabel("attitude RMS (rad)")
    for ax in axes:
        ax.set_xlabel("horizon (s)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, frameon=False)
    fig.tight_layout()
    return svg(fig)


def flight_series(states, reference: Reference, rows, *, name: str,
                  memo: dict | None = None) -> Series:
    """The :class:`~quadsim.gap.result.Series` of one judged flight (module doc).

    ``states``: the flight's fit states aligned to the references' timing
    (:meth:`~quadsim.gap.reference.Reference.align`); ``reference``: the reference model it
    was judged against (at the flight's place); ``rows``: every explanation's
    :class:`~quadsim.gap.evidence.Evidence` (the lead is taken by
    :func:`quadsim.gap.judge.posterior`); ``name``: the flight's file; ``memo``: the residual
    parts and Jacobian the evidence kept for this flight (:func:`quadsim.gap.evidence.
    evaluate`), None to compute them."""
    lead = posterior(rows)[0][2]
    expl = lead.explanation
    chans = len(reference.sigma)
    before = (flight_residual(states, reference, reference.effects(), memo).reshape(-1, chans)
              / np.sqrt(reference.weights))
    prob = FitInputs(states, reference, _jacobian(states, reference, memo),
                     marginal_sd(reference), memo).problem(expl)
    theta = np.array([lead.values[k] for k in expl.parameter_names], float)
    z = (theta - prob.mean) / prob.sd
    weighted, _ = prob.marg.profile(prob.residual(z))
    after = (weighted[:len(states.t) * chans].reshape(-1, chans)
             * np.sqrt(reference.tau) * reference.sigma)
    return Series(np.asarray(states.t, float), before, after, tuple(channel_names(reference)),
                  name, states, reference.params, tuple(prob.shared),
                  np.asarray(reference.sigma, float))


def _jacobian(states, reference: Reference, memo: dict | None) -> np.ndarray:
    """The weighted residual's Jacobian in the shared parameters: the one
    :func:`quadsim.gap.evidence.evaluate` kept in ``memo`` for these states and reference,
    else computed (:func:`quadsim.gap.reference.jacobian`)."""
    kept = (memo or {}).get("evidence.jacobian")
    if kept is not None and kept[0] is states and kept[1] is reference:
        return kept[2]
    names = reference.candidate.parameter_names
    return jacobian(states, reference, list(range(len(names))), reference.candidate.effects,
                    memo=memo)


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


def _page_short(path) -> str:
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


def _page_figure(svg_text: str, caption: str) -> str:
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


def _page_unit(key: str) -> str:
    from .fitting import unit_of

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
        rows.append([_name(_page_short(f["file"])), _name(f["verdict"], f"{f['outcome']} wrap"),
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
    which = ", ".join(f"{_page_short(a['flight'])} ({a['verdict']})" for a in alarms[:4])
    return (f"Reference self-check: {len(alarms)} of the {n} reference flights, judged "
            f"against the others, {'is' if len(alarms) == 1 else 'are'} not "
            f"no_significant_gap: {which}"
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
    if f.get("outside_library"):     # the name's stand-in share (quadsim.gap.judge.with_outside)
        rows.append([_name("outside the library", "wrap"),
                     _Cell(_pct1(f["outside_library"])),
                     _words("the named reading standing in for an effect the library lacks")])
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
    name = _page_short(f["file"])
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
        parts.append(_page_figure(residual_time(series, series.sigma),
                             f"{name}: residual force and torque against time, before the "
                             "answer (the reference model) and after it (the answer fitted), "
                             "over the references' 95 % band (±1.96 x their RMS)."))
        parts.append(_page_figure(residual_against(series, series.sigma),
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
            verdicts.setdefault(f["verdict"], []).append(_page_short(f["file"]))
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
                table.setdefault(_page_short(m.group(1)), {})[sig] = f"{float(val):+.1f} ms"
        m = _UNRESOLVED.match(note)
        if m:
            table.setdefault(_page_short(m.group(1)), {})[m.group(2)] = "not resolvable"
    for f in result["flights"]:
        for sig, val in (f.get("signal_delays_ms") or {}).items():
            if val is not None:
                table.setdefault(_page_short(f["file"]), {}).setdefault(sig, f"{val:+.1f} ms")
    if not table:
        return ""
    ref = (result.get("reference_model") or {}).get("delays_ms", {})
    signals = sorted({s for row in table.values() for s in row} | set(ref))
    refs = [_page_short(r) for r in result.get("reference", [])]
    judged = [_page_short(f["file"]) for f in result["flights"]]
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
        unit = _page_unit(k)
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
        body.append(_page_figure(batch(judged, shares),
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
        params = ", ".join(f"{k} = {x:.3g} ± {e['ci'].get(k, float('nan')):.2g} {_page_unit(k)}"
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
        name = _page_short(series.flight)
        body.append(f"<h2>Held-out flight {_e(name)}</h2>")
        body.append(_page_figure(residual_time(series, band),
                            f"{name}: residual force and torque against time, the nominal "
                            "model and with the answer, over the floor's 95 % band."))
        body.append(_page_figure(residual_against(series, band),
                            f"{name}: the mean residual in bins of speed and of collective "
                            "thrust."))
    body.append(_page_figure(kstep(result.get("where") or {}),
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
