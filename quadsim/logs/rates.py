"""A channel's native rate: how often it was logged, before any resampling.

The importers resample every topic onto one time base (:func:`quadsim.logs.common.resample`),
and a CSV or Parquet export repeats or interpolates a slow channel onto its rows, so the rows'
rate says nothing about how fast a channel was logged. A rotor speed logged at 4 Hz
(PX4's default ``esc_status`` profile) and spread over 500 Hz rows cannot carry the
attitude loop's 1-20 Hz content; the diagnosis needs to know (:mod:`quadsim.gap.logcheck`,
"Slow channels").

Where the loader knows a channel's rate (ULog: each topic's median interval; DataFlash:
each message's; the Crazyflie uSD reader: the event's), it states it in
``Columns.rates`` and the FlightLog carries it (:attr:`quadsim.logs.flightlog.FlightLog.
rates_hz`). For a CSV or Parquet log, and for a channel the loader did not rate, it is read
from the data by :func:`native_rate`:

* **held** (sample and hold: a logger that repeats the latest value on every row): the
  value changes only on the rows where a new sample arrived; those rows are the *knots*;
* **interpolated** (linear interpolation between the samples, what the importers and most
  resampling exports do): each row lies on the straight line (in time: row instants
  jitter) through its two neighbours between knots, and not at a knot (a sample that falls
  between two rows bends the line on the two rows around it: a knot of two adjacent rows,
  counted once);
* **native**: the value changes and bends on nearly every row.

Each test flags rows (the rotor columns of a channel together: a knot on any column is a
knot of the channel), merges runs of adjacent flagged rows into one knot, and takes the
median time between consecutive knots as the channel's sample interval; the channel's rate
is the slower of the two tests' (a held channel bends only at its steps, so both tests see
its knots; an interpolated one changes on every row, so only the second-difference test
sees them). Runs of flagged rows whose median length is :data:`DENSE_RUN` rows or more
mean the channel changes on nearly every row: native, the rows' own rate. Rows where the
channel is constant for long (on the ground, motors off) add no knots and do not bias a
median.

Thresholds:

* a row is flagged where it differs from the row before (a held value repeats exactly, so
  any change of a rounding step counts), or where its distance from its neighbours' line
  exceeds :data:`ROUND_STEPS` = 2 rounding steps of the column as written (:func:`_quanta`: the
  decimal step of its largest value at the most significant digits its values use; 1e-3
  rad/s for the Crazyflie's 7-digit speeds, 1e-14 of the value for float64): a linearly
  interpolated value rounded so lies at most one step off its neighbours' line (half a step
  of its own rounding, half of theirs), so no rounding is read as a knot, and a smooth
  native channel without noise (a generated log's commands at 1 kHz bend by ~1e-7 of
  their value per row) still bends on every row;
* :data:`DENSE_RUN` = 3 rows: an interpolated sample bends two rows, a held one changes one,
  so longer runs are no knot but a channel that changes everywhere;
* :data:`MIN_KNOTS` = 8: fewer knots read nothing (None: unknown, e.g. a constant column);
* **dense** (the held reading): a held channel's value changes on single rows, where a new
  sample shows; a channel that changes on :data:`DENSE_RUN` or more consecutive rows wherever
  it moves changes on every row there: where more than :data:`DENSE_SHARE` = half of its
  changing rows lie in such runs it is native, whatever the median run. A smooth channel
  without noise that stays on one written value for stretches (a generated 100 Hz rotor
  speed at a steady hover, written to 10 digits: 97 % of its changing rows in such runs,
  between stretches of no change) is native; the Crazyflie's motion-capture pose held on
  its 500 Hz rows (0 %) stays held;
* **regular** (the interpolated reading): a logger samples at one rate, so a slow channel's
  knots tile the time it moves at one interval (rows jitter: within one row): the intervals
  within :data:`REGULAR_SPREAD` = 25 % (and one row) of their median cover at least
  :data:`REGULAR_SHARE` = half of the time from the first knot to the last (a channel constant
  on the ground in between still covers the rest);
* **smooth** (the interpolated reading): an interpolated value rounded as written lies within
  one rounding step of its neighbours' line (module doc above), so between its knots no row
  lies between one and two steps off it; a smooth channel without noise whose rows bend
  beyond the two steps only where it turns fast has rows just under that threshold too,
  wherever its curvature crosses it. Where such *grazing* rows number more than
  :data:`SMOOTH_GRAZING` = 2 per knot and the knots are not regular (above) the channel is
  native (the generated rotor speeds on a gentle path: 66 and 114 grazing rows on 12 and 20
  knots; the interpolated channels of converted ULog and DataFlash logs and of the tests:
  0-1 per knot, except a renormalised quaternion, whose knots are regular). Why both rules:
  read as a 5-50 Hz channel, such speeds would be synthesised from the commands
  (:func:`quadsim.gap.logcheck.slow_rotors`) and judged in their stead;
* :data:`QUANTUM_STEPS` = 2: a native channel quantised so coarsely that it stays on one
  value for several rows (a battery voltage in 1 mV steps, integer PWM commands in a hover)
  changes by one quantum at a time, so the median change is its smallest; a held channel's
  changes are what the signal did between samples, many quanta and unequal. Where every
  column's median change is at most twice its smallest, the channel is read as native.

What it cannot tell: a held channel whose every change is about equal (a held ramp), read
as native; a quantised channel that moves by several quanta between rows yet stays for
several, read as held; a slow interpolated channel that shows only a few knots at no one
interval (a logger that drops most samples) and bends just under the threshold between
them, read as native. It costs a few vector operations per column (it runs on every log).

Example::

    >>> native_rate(t, rotor_speed)          # NativeRate(hz=4.0, form="held", knots=...)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["DENSE_RUN", "DENSE_SHARE", "MAX_DIGITS", "MIN_KNOTS", "QUANTUM_STEPS", "REGULAR_SHARE",
           "REGULAR_SPREAD", "ROUND_STEPS", "SMOOTH_GRAZING", "NativeRate", "native_rate",
           "rates_of"]

#: rounding steps of the column as written (:func:`_quanta`) a change must exceed to count
#: (module doc)
ROUND_STEPS = 2.0
#: the most significant digits a value is read with (float64 holds 15-17)
MAX_DIGITS = 15
#: median run of flagged rows at or above which a channel is native (module doc)
DENSE_RUN = 3
#: fewest knots from which a rate is read (module doc)
MIN_KNOTS = 8
#: a held reading whose changing rows lie in runs of DENSE_RUN or more beyond this share is
#: native (module doc, "dense"): a held channel's changes are single rows, so the runs then
#: hold most of its changes
DENSE_SHARE = 0.5
#: knots come at one rate where the intervals within :data:`REGULAR_SPREAD` of their median
#: cover at least this share of the time from the first knot to the last (module doc,
#: "regular")
REGULAR_SHARE = 0.5
#: the relative spread about the median knot interval that counts as one rate (module doc)
REGULAR_SPREAD = 0.25
#: rows between one and two rounding steps off their neighbours' line, per knot, above which
#: the knots of the "interpolated" reading are a smooth channel's (module doc, "smooth")
SMOOTH_GRAZING = 2.0
#: a column whose changes have a median at most this many times its smallest change is
#: quantised, not held (module doc)
QUANTUM_STEPS = 2.0


@dataclass(frozen=True)
class NativeRate:
    """A channel's native rate: ``hz`` (1/s), ``form`` ("native", "held" or
    "interpolated"), ``knots``: the row indices (int array) where a logged sample shows
    (the first row of each knot; every row for a native channel)."""

    hz: float
    form: str
    knots: np.ndarray


def _regular(gaps: np.ndarray, interval: float, step: float) -> bool:
    """Whether knot intervals ``gaps`` (s) tile the channel's time as a logger's samples do:
    the intervals within :data:`REGULAR_SPREAD` of their median ``interval`` (and within one
    row ``step``, s, of it: rows jitter, and a sample between two rows bends either of them)
    cover at least :data:`REGULAR_SHARE` of the time from the first knot to the last."""
    tolerance = max(REGULAR_SPREAD * interval, step)
    kept = np.abs(gaps - interval) <= tolerance
    return float(np.sum(gaps[kept])) >= REGULAR_SHARE * float(np.sum(gaps))


def _runs(flags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first index, length) of each run of True in ``flags``."""
    padded = np.concatenate([[False], flags, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return edges[0::2], edges[1::2] - edges[0::2]


def _dense_share(flags: np.ndarray) -> float:
    """The share of the flagged rows of ``flags`` that lie in runs of :data:`DENSE_RUN` rows
    or more (module doc, "dense"); 0 without any."""
    _, lengths = _runs(flags)
    total = int(lengths.sum())
    return float(lengths[lengths >= DENSE_RUN].sum()) / total if total else 0.0


def _knots(flags: np.ndarray) -> tuple[np.ndarray, float]:
    """The first index of each run of True in ``flags`` and the runs' median length."""
    starts, lengths = _runs(flags)
    if len(starts) == 0:
        return starts, 0.0
    return starts, float(np.median(lengths))


#: 10.0 ** k (float64, numpy's power: the same numbers) for every whole k that
#: :func:`_quanta` raises 10 to: D - 1 - e with D in 1 .. MAX_DIGITS - 1 and e the decimal
#: exponent of a finite nonzero double (-324 .. 308); looked up, not computed per value
#: (the power was two thirds of its CPU)
_POWERS_FROM = -310
with np.errstate(over="ignore"):
    _POWERS = 10.0 ** np.arange(_POWERS_FROM, 340, dtype=float)
_POWERS.flags.writeable = False


def _quanta(x: np.ndarray) -> np.ndarray:
    """(K,) the rounding step of each column of ``x`` (N, K) as written: 10^(e - D + 1) for
    the column's largest magnitude's decimal exponent e and the most significant digits D
    any of up to 512 of its values (evenly spread) needs (:data:`MAX_DIGITS` at most:
    float64 arithmetic); 0 for a column without a nonzero finite value. Columns that are
    finite and nonzero throughout (a channel's, the common case) are read together, as one
    array: the same numbers as one column at a time."""
    usable = np.isfinite(x) & (x != 0)
    if x.shape[1] > 1 and not usable.all():      # columns of unequal counts: one at a time
        return np.concatenate([_quanta(x[:, j:j + 1]) for j in range(x.shape[1])])
    v = x[usable[:, 0]] if x.shape[1] == 1 else x
    if not len(v):
        return np.zeros(1)
    v = v[np.linspace(0, len(v) - 1, min(len(v), 512)).astype(int)]     # (S, K)
    exponent = np.floor(np.log10(np.abs(v)))
    counts = np.arange(1, MAX_DIGITS)[:, None, None]   # D = 1 .. MAX_DIGITS - 1, one each
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        scale = _POWERS[(counts - 1 - exponent).astype(int) - _POWERS_FROM]
        same = np.abs(np.round(v * scale) / scale - v) <= 1e-12 * np.abs(v)
    # the fewest digits that give each value back (MAX_DIGITS where none does)
    digits = np.where(same.any(axis=0), np.argmax(same, axis=0) + 1, MAX_DIGITS)
    return np.array([10.0 ** (float(np.floor(np.log10(np.max(np.abs(v[:, j])))))
                              - int(digits[:, j].max()) + 1) for j in range(v.shape[1])])


def _quantised(changes: np.ndarray, counted: np.ndarray) -> bool:
    """Whether every column's changes (``changes`` (N-1, K), those ``counted``) are about one
    quantum: median at most :data:`QUANTUM_STEPS` times the smallest (module doc)."""
    seen = False
    for j in range(changes.shape[1]):
        c = changes[counted[:, j], j]
        if len(c) < MIN_KNOTS:
            continue
        seen = True
        if np.median(c) > QUANTUM_STEPS * np.min(c):
            return False
    return seen


def native_rate(t: np.ndarray, values: np.ndarray) -> NativeRate | None:
    """The native rate of one channel (module doc): ``t`` (N,) s, strictly increasing;
    ``values`` (N,) or (N, K) (NaN rows are no knots). Returns None where it cannot tell
    (fewer than :data:`MIN_KNOTS` knots, or fewer than 5 rows)."""
    t = np.asarray(t, dtype=float)
    return _native_rate(t, values, *_time_base(t)) if len(t) >= 5 else None


def _time_base(t: np.ndarray) -> tuple[float, np.ndarray]:
    """What :func:`native_rate` reads of the times ``t`` (N >= 5,) alone, the same for every
    channel of a log: the median row step (s) and each inner row's place (N-2, 1) between
    its neighbours in time."""
    return (float(np.median(np.diff(t))),
            ((t[1:-1] - t[:-2]) / (t[2:] - t[:-2]))[:, None])


def _any_column(flags: np.ndarray) -> np.ndarray:
    """``flags.any(axis=1)`` of a boolean (M, K) with few columns, taken column by column
    (numpy's reduction along a short last axis is ~6x slower)."""
    out = flags[:, 0].copy()
    for j in range(1, flags.shape[1]):
        out |= flags[:, j]
    return out


def _native_rate(t: np.ndarray, values: np.ndarray, step: float, w: np.ndarray
                 ) -> NativeRate | None:
    """:func:`native_rate` on float times ``t`` (N >= 5,) with their :func:`_time_base`
    (``step``, ``w``)."""
    x = np.asarray(values, dtype=float)
    x = x[:, None] if x.ndim == 1 else x
    if x.shape[0] != len(t):
        return None
    finite = np.isfinite(x)
    if not finite.any():
        return None
    quantum = _quanta(x)
    tol = ROUND_STEPS * quantum
    with np.errstate(invalid="ignore"):
        changes = np.abs(np.diff(x, axis=0))
        d1 = changes > 0.5 * quantum                        # row k+1 differs from row k
    if _quantised(changes, d1):                          # steps of one quantum: native
        return NativeRate(1.0 / step, "native", np.arange(len(t)))
    # row k off the straight line through rows k-1 and k+1, in time (logged instants jitter:
    # a line in t is no line in the row index)
    with np.errstate(invalid="ignore"):
        off = np.abs(x[1:-1] - (x[:-2] * (1.0 - w) + x[2:] * w))
    d2 = off > tol                                      # row k+1 bends
    held = np.concatenate([[False], _any_column(d1)])   # rows where a new value shows
    bent = np.concatenate([[False], _any_column(d2), [False]])
    # rows that are no knot (no column beyond two rounding steps of its line) yet have a
    # column beyond one: none on an interpolated channel (module doc, "smooth")
    grazing = int(np.count_nonzero(_any_column(off > 0.5 * tol) & ~bent[1:-1]))
    best = None
    for form, flags in (("held", held), ("interpolated", bent)):
        starts, run = _knots(flags)
        if int(flags.sum()) < MIN_KNOTS:
            continue
        if run >= DENSE_RUN:                            # changes on nearly every row
            candidate = NativeRate(1.0 / step, "native", np.arange(len(t)))
        elif len(starts) < MIN_KNOTS:
            continue
        else:
            gaps = np.diff(t[starts])
            interval = float(np.median(gaps))
            smooth = (_dense_share(flags) > DENSE_SHARE if form == "held" else
                      not _regular(gaps, interval, step)
                      and grazing > SMOOTH_GRAZING * len(starts))
            if interval <= 1.5 * step or smooth:
                # a knot on every row or so, or knots of a smooth channel's bends beyond the
                # rounding (module doc, "regular" and "smooth")
                candidate = NativeRate(1.0 / step, "native", np.arange(len(t)))
            else:
                candidate = NativeRate(1.0 / interval, form, starts)
        if best is None or candidate.hz < 0.99 * best.hz:     # a tie: the held reading
            best = candidate
    return best


def rates_of(t: np.ndarray, channels: dict) -> tuple[tuple[str, float], ...]:
    """``((channel, Hz), ...)`` of the channels ``channels`` (name -> (N,) or (N, K) array
    or None) whose rate :func:`native_rate` reads; in the given order, the unread left
    out."""
    t = np.asarray(t, dtype=float)
    base = _time_base(t) if len(t) >= 5 else None      # one log's times: read once
    out = []
    for name, values in channels.items():
        if values is None:
            continue
        rate = None if base is None else _native_rate(t, values, *base)
        if rate is not None:
            out.append((name, float(rate.hz)))
    return tuple(out)
