"""The report's figures as inline SVG text (matplotlib, no pyplot state, no network).

* :func:`residual_time`: per channel Fx Fy Fz Mx My Mz against time, the residual before the
  answer (under the reference model) and after it (with the answer fitted), over the
  references' band +-1.96 sigma_c (95 % of a reference flight's residual if it were
  Gaussian; sigma_c the references' residual RMS).
* :func:`residual_against`: where the gap lives: the residual's mean in bins of speed (m/s)
  and of collective thrust (N, b sum Omega^2 with the model's b), before and after, for the
  three channels with the largest residual before, over the same band.
* :func:`kstep` (held out): the k-step prediction error of position and attitude against
  the horizon, with the nominal model and with the answer (:mod:`quadsim.gap.where`).
* :func:`batch`: across flights (one row each, grouped by verdict), the residual against the
  references' level before and after each answer, and each leading reading's determined
  parameters with their 95 % intervals.

Every axis carries its unit; values are drawn with an SI prefix where they are small
(:func:`scale`: mN, mN m, g). Lines longer than :data:`MAX_POINTS` are reduced to each
bin's minimum and maximum (the envelope stays, the file stays small). Each SVG's ids get
a prefix of their own, so several figures share one HTML page.
"""

from __future__ import annotations

import io
import itertools
import re
from pathlib import Path

import numpy as np

__all__ = ["MAX_PANELS", "MAX_POINTS", "batch", "kstep", "residual_against", "residual_time",
           "scale", "svg"]

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

    from .priors import unit_of

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
