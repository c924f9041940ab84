"""Ground, idle and landing spans of a flight log: found, named and cut.

A log usually starts on the ground (motors off, or armed and idling) and often ends there
after the landing. Those samples carry no information about the airborne vehicle and break
every force balance on it: b sum(Omega^2) is far below the weight while the vehicle sits on
its legs (the PX4 SITL log's first 19 s read as "b sum(Omega^2) is 0.147 x the thrust
needed"). :func:`airborne_span` marks each sample

* **idle**: the rotor activity (sum Omega^2 from the rotor speeds, else sum cmd^2 from the
  commands) below :data:`IDLE_FRACTION` of its 90th percentile over the log — motors off or
  near idle (hover needs about a third of full-throttle sum Omega^2; idle is a few per cent);
* **ground**: at rest — speed below :data:`REST_SPEED` and body rate below :data:`REST_RATE`
  for at least :data:`MIN_SPAN_S` — with the rotor activity below :data:`WEAK_FRACTION` of
  its median over the non-idle samples (spinning up on the ground; a hover needs about the
  median, since the mean thrust of a flight is about its weight). Without rotor data: at
  rest within :data:`GROUND_HEIGHT_M` of the log's lowest height (1st percentile), when the
  log spans more than :data:`LIFT_HEIGHT_M` in height;

and finds every stretch with neither (gaps shorter than :data:`MIN_SPAN_S` are bridged,
so one noisy sample does not split a flight; a logging gap -- a time step -- of
:data:`MIN_SPAN_S` or more splits a stretch, since nothing of the flight is known there and
an interpolation across it would invent it: a radio log's dropout, two logs joined):
:func:`split_airborne` keeps each of them (a log with several take-offs is several
segments, all used: ``identify --logs``),
:func:`join_airborne` keeps each as a segment of one flight (``gap`` and ``view``: one flight
per file, its stretches joined with :attr:`~quadsim.logs.flightlog.FlightLog.segments` marking
where the time axis and the states jump; the note says "2 airborne stretches used"), and
:func:`cut_ground` the longest (``convert --model``; the note names the other stretches).
An IMU-only log (no pose) is judged by its rotor activity and its gyro
(at rest: body rate below :data:`REST_RATE`), without the height and speed tests. The cut
parts are named in a note:
"``f.ulg: airborne span t 19.20-31.05 s kept (11.85 of 31.1 s); cut: ground 0.00-19.19 s``".
A log with no airborne stretch of :data:`MIN_SPAN_S` is refused in one line.

Used by :func:`quadsim.logs.checks.check_log` (so ``gap``, ``view`` and ``convert
--model``) and by ``identify --logs``. Units: s, m, m/s, rad/s.

Example::

    >>> from quadsim.logs.spans import cut_ground
    >>> log, note = cut_ground(load_log("sample_px4_events.ulg"))
    >>> segments, note = split_airborne(load_log("log10.csv.gz"))   # every take-off
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..core.errors import field_error
from .flightlog import ARRAYS

#: rotor activity (sum of squares) below this fraction of its 90th percentile is idle.
IDLE_FRACTION = 0.15
#: height (m) above the log's lowest (1st percentile) counted as "on the ground".
GROUND_HEIGHT_M = 0.05
#: at rest with the rotor activity below this fraction of its non-idle median is "ground";
#: without rotor data the log must span more than LIFT_HEIGHT_M (m) in height.
WEAK_FRACTION = 0.8
LIFT_HEIGHT_M = 0.3
#: speed (m/s) and body rate (rad/s) below which the vehicle is at rest.
REST_SPEED = 0.1
REST_RATE = 0.2
#: spans (s) shorter than this are not cut, and no airborne stretch shorter is kept; a
#: logging gap (a time step) of at least this splits an airborne stretch.
MIN_SPAN_S = 0.5


@dataclass(frozen=True)
class Span:
    """The airborne part of a log: samples ``start:stop``; ``cut`` lists the removed parts as
    (kind, t_from, t_to) with kind "idle", "ground" or "idle, ground"."""

    start: int
    stop: int
    cut: tuple[tuple[str, float, float], ...]


def _activity(log) -> np.ndarray | None:
    if log.rotor_speed is not None and log.rotor_speed.shape[1]:
        return np.sum(np.square(log.rotor_speed), axis=1)
    if log.rotor_command is not None and log.rotor_command.shape[1]:
        return np.sum(np.square(log.rotor_command), axis=1)
    return None


def _bridge(mask: np.ndarray, n_min: int) -> np.ndarray:
    """``mask`` with True runs shorter than ``n_min`` samples set False."""
    out = mask.copy()
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a < n_min:
            out[a:b] = False
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def _flying(log) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(flying, idle, ground) masks (N,) of ``log`` (see the module)."""
    t = np.asarray(log.t, float)
    n = len(t)
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    n_min = max(1, round(MIN_SPAN_S / dt))
    idle = np.zeros(n, bool)
    activity = _activity(log)
    weak = np.zeros(n, bool)
    if log.position is not None:
        height = log.position[:, 2]
        low = height < np.percentile(height, 1) + GROUND_HEIGHT_M
        weak = low & (float(np.ptp(height)) > LIFT_HEIGHT_M)
    if activity is not None:
        top = float(np.percentile(activity, 90))
        idle = _bridge(activity < IDLE_FRACTION * top, n_min) if top > 0 else np.ones(n, bool)
        weak = activity < WEAK_FRACTION * float(np.median(activity[~idle])) \
            if (~idle).any() else np.ones(n, bool)
    rest = np.ones(n, bool)
    if log.position is not None:
        velocity = log.velocity if log.velocity is not None else np.gradient(log.position, t,
                                                                             axis=0)
        rest = np.linalg.norm(velocity, axis=1) < REST_SPEED
    if log.body_rate is not None:
        rest &= np.linalg.norm(log.body_rate, axis=1) < REST_RATE
    ground = _bridge(rest & weak, n_min)
    if not (idle | ground).any():            # nothing to cut (also: logs shorter than n_min)
        return np.ones(n, bool), idle, ground
    return _bridge(~(idle | ground), n_min), idle, ground


def airborne_spans(log) -> tuple[Span, ...]:
    """Every airborne stretch of ``log`` (a FlightLog) in time order, each with what was cut
    around it (the same ``cut`` list on each: every part that is not airborne). Refused when
    there is none of ``MIN_SPAN_S``."""
    t = np.asarray(log.t, float)
    n = len(t)
    flying, idle, ground = _flying(log)
    runs = [(0, n)] if flying.all() else _runs(flying)
    cut = []
    for a, b in _runs(~flying):
        kinds = [k for k, m in (("idle", idle), ("ground", ground)) if m[a:b].any()]
        cut.append((", ".join(kinds) or "short", float(t[a]), float(t[b - 1])))
    runs, gaps = _split_at_gaps(t, runs)
    if not runs:
        raise field_error(log.path if log.path is not None else "log", "t",
                          f"no airborne stretch of {MIN_SPAN_S} s: the whole log is on the "
                          "ground or with the motors idle")
    cut = sorted(cut + gaps, key=lambda c: c[1])
    return tuple(Span(a, b, tuple(cut)) for a, b in runs)


def _split_at_gaps(t: np.ndarray, runs: list) -> tuple[list, list]:
    """(runs, cut): each airborne run (start, stop) of the time axis ``t`` (s) split where a
    time step is :data:`MIN_SPAN_S` or longer (a logging gap: nothing of the flight is known
    there, and an interpolation across it would invent it; shorter gaps are bridged, as a
    short ground span is), the pieces shorter than :data:`MIN_SPAN_S` dropped; ``cut``: each
    gap ("logging gap", t before, t after) and each dropped piece ("short", t from, t to)."""
    out, cut = [], []
    for a, b in runs:
        splits = a + 1 + np.flatnonzero(np.diff(t[a:b]) >= MIN_SPAN_S)
        cut += [("logging gap", float(t[k - 1]), float(t[k])) for k in splits]
        edges = [a, *map(int, splits), b]
        for x, y in zip(edges[:-1], edges[1:]):
            if t[y - 1] - t[x] >= MIN_SPAN_S:
                out.append((x, y))
            else:
                cut.append(("short", float(t[x]), float(t[y - 1])))
    return out, cut


def airborne_span(log) -> Span:
    """The longest airborne stretch of ``log`` (a FlightLog) and what was cut around it
    (the other airborne stretches listed as cut, "another airborne stretch")."""
    spans = airborne_spans(log)
    best = max(spans, key=lambda s: (s.stop - s.start, -s.start))
    t = log.t
    cut = list(best.cut) + [("another airborne stretch", float(t[s.start]), float(t[s.stop - 1]))
                            for s in spans if s is not best]
    return Span(best.start, best.stop, tuple(sorted(cut, key=lambda c: c[1])))


def _take(log, span: Span, note: str):
    return dataclasses.replace(log.take(slice(span.start, span.stop)),
                               notes=(*log.notes, note))


def split_airborne(log):
    """(logs, note or None): one log per airborne stretch (:func:`airborne_spans`), in time
    order, each keeping the file's time axis; the note names every stretch kept and every
    part cut. Several take-offs in one log are several segments of it, all used."""
    spans = airborne_spans(log)
    if len(spans) == 1 and spans[0].start == 0 and spans[0].stop == len(log.t):
        return [log], None
    t = log.t
    where = log.path if log.path is not None else "log"
    kept = sum(float(t[s.stop - 1] - t[s.start]) for s in spans)
    note = (f"{where}: {len(spans)} airborne stretch{'es' if len(spans) > 1 else ''} used, t "
            + ", ".join(f"{t[s.start]:.2f}-{t[s.stop - 1]:.2f} s" for s in spans)
            + f" ({kept:.2f} of {float(t[-1] - t[0]):.2f} s); cut: "
            + "; ".join(f"{kind} {a:.2f}-{b:.2f} s" for kind, a, b in spans[0].cut))
    return [_take(log, s, note) for s in spans], note


def join_airborne(log):
    """(log, note or None): every airborne stretch of ``log`` (:func:`airborne_spans`) kept,
    joined in time order into one log whose :attr:`~quadsim.logs.flightlog.FlightLog.segments`
    mark where each stretch after the first starts (the ground spans between them are cut;
    nothing downstream bridges them). One stretch: exactly :func:`cut_ground`."""
    spans = airborne_spans(log)
    if len(spans) == 1:
        return cut_ground(log)
    parts, note = split_airborne(log)
    starts = np.cumsum([len(p.t) for p in parts])[:-1]
    joined = dataclasses.replace(
        log, t=np.concatenate([p.t for p in parts]), notes=(*log.notes, note),
        segments=tuple(int(k) for k in starts),
        **{name: (None if getattr(log, name) is None
                  else np.concatenate([getattr(p, name) for p in parts])) for name in ARRAYS})
    return joined, note


def cut_ground(log):
    """(log, note or None): ``log`` cut to its airborne span; None when nothing was cut."""
    span = airborne_span(log)
    if span.start == 0 and span.stop == len(log.t):
        return log, None
    t = log.t
    where = log.path if log.path is not None else "log"
    kept = float(t[span.stop - 1] - t[span.start])
    note = (f"{where}: airborne span t {t[span.start]:.2f}-{t[span.stop - 1]:.2f} s kept "
            f"({kept:.2f} of {float(t[-1] - t[0]):.2f} s); cut: "
            + "; ".join(f"{kind} {a:.2f}-{b:.2f} s" for kind, a, b in span.cut))
    return _take(log, span, note), note
