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

* a row is flagged where the change (or its distance from its neighbours' line) exceeds
  :data:`REL_TOL` = 1e-6 of the column's largest magnitude: above the rounding of a value
  written with 7 significant digits (a linearly interpolated column written so lies up to
  about 2e-7 of its magnitude off the line), below any change a native channel shows from
  one row to the next (a rotor speed's noise is ~1e-4 of it, a smooth simulated one at
  500 Hz changes by ~1e-5 of it per row);
* :data:`DENSE_RUN` = 3 rows: an interpolated sample bends two rows, a held one changes one,
  so longer runs are no knot but a channel that changes everywhere;
* :data:`MIN_KNOTS` = 8: fewer knots read nothing (None: unknown, e.g. a constant column).

What it cannot tell: a native channel quantised so coarsely that it stays on one value for
several rows (a battery voltage in 1 mV steps) reads as held at the rate of its changes.
It costs a few vector operations per column (it runs on every log).

Example::

    >>> native_rate(t, rotor_speed)          # NativeRate(hz=4.0, form="held", knots=...)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["DENSE_RUN", "MIN_KNOTS", "REL_TOL", "NativeRate", "native_rate", "rates_of"]

#: relative size (of the column's largest magnitude) of a change that counts (module doc)
REL_TOL = 1e-6
#: median run of flagged rows at or above which a channel is native (module doc)
DENSE_RUN = 3
#: fewest knots from which a rate is read (module doc)
MIN_KNOTS = 8


@dataclass(frozen=True)
class NativeRate:
    """A channel's native rate: ``hz`` (1/s), ``form`` ("native", "held" or
    "interpolated"), ``knots``: the row indices (int array) where a logged sample shows
    (the first row of each knot; every row for a native channel)."""

    hz: float
    form: str
    knots: np.ndarray


def _knots(flags: np.ndarray) -> tuple[np.ndarray, float]:
    """The first index of each run of True in ``flags`` and the runs' median length."""
    padded = np.concatenate([[False], flags, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    starts, ends = edges[0::2], edges[1::2]
    if len(starts) == 0:
        return starts, 0.0
    return starts, float(np.median(ends - starts))


def native_rate(t: np.ndarray, values: np.ndarray) -> NativeRate | None:
    """The native rate of one channel (module doc): ``t`` (N,) s, strictly increasing;
    ``values`` (N,) or (N, K) (NaN rows are no knots). Returns None where it cannot tell
    (fewer than :data:`MIN_KNOTS` knots, or fewer than 5 rows)."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(values, dtype=float)
    x = x[:, None] if x.ndim == 1 else x
    if len(t) < 5 or x.shape[0] != len(t):
        return None
    finite = np.isfinite(x)
    if not finite.any():
        return None
    scale = np.max(np.abs(np.where(finite, x, 0.0)), axis=0)
    tol = REL_TOL * np.where(scale > 0, scale, 1.0)
    # row k off the straight line through rows k-1 and k+1, in time (logged instants jitter:
    # a line in t is no line in the row index)
    w = ((t[1:-1] - t[:-2]) / (t[2:] - t[:-2]))[:, None]
    with np.errstate(invalid="ignore"):
        d1 = np.abs(np.diff(x, axis=0)) > tol          # row k+1 differs from row k
        d2 = np.abs(x[1:-1] - (x[:-2] * (1.0 - w) + x[2:] * w)) > tol     # row k+1 bends
    held = np.concatenate([[False], d1.any(axis=1)])   # rows where a new value shows
    bent = np.concatenate([[False], d2.any(axis=1), [False]])
    step = float(np.median(np.diff(t)))
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
            interval = float(np.median(np.diff(t[starts])))
            if interval <= 1.5 * step:                  # a knot on every row or so
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
    out = []
    for name, values in channels.items():
        if values is None:
            continue
        rate = native_rate(t, values)
        if rate is not None:
            out.append((name, float(rate.hz)))
    return tuple(out)
