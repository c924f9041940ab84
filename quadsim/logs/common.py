"""Shared pieces of the log importers: one time base, resampling, frames, rotor numbering.

**Resampling** (:func:`resample`): every topic of a multi-rate log is linearly interpolated
onto one time base (by default the instants of the log's attitude topic: every output row is
a real attitude sample). A value is produced only *between* two source samples that are at
most ``max_gap`` apart (default ``GAP_FACTOR`` = 5 times the topic's median step): outside
the topic's first..last sample, and inside a longer gap, the value is NaN. Nothing is ever
extrapolated or held across a gap. Linear interpolation of a sampled sine has no lag (the
error is O(dt^2 w^2), symmetric); zero-order hold would lag by dt/2.

**Frames** (:func:`ned_to_world`, :func:`frd_to_body`, :func:`quat_ned_frd_to_world_body`):
PX4 and ArduPilot use a north-east-down (NED) world and a forward-right-down (FRD) body. Our
world is z up and our body is x forward, y left, z up (FLU). Both conversions are the same
proper rotation, a half turn about x, ``P = diag(1, -1, -1)``:

* world: ``p_ours = P p_ned``, i.e. x = north, y = west, z = up (a right-handed z-up frame;
  not east-north-up, which would need a further yaw by 90 degrees and would change yaw);
* body: ``v_flu = P v_frd`` (rates, specific force);
* attitude: ``R_ours = P R_ned P`` (P = P^T = P^-1), so in quaternions (w, x, y, z) ->
  (w, x, -y, -z). A roll phi about the forward axis stays a roll phi (right side down is a
  positive rotation about +x in both); pitch and yaw change sign (nose-up is +pitch in FRD,
  -pitch about our left y; yaw is measured from north clockwise in NED and anticlockwise
  from x = north in ours).

**Rotor numbering** (:func:`map_rotors`): ``rotor_map = (m1, m2, ...)`` gives, for our rotor
i (1-based, the parameter set's order), the 1-based motor number in the log. ``None`` keeps
the log's order. Example: a PX4/ArduPilot quad X numbers motors 1 front-right, 2 rear-left,
3 front-left, 4 rear-right; the ``crazyflie21`` parameter set numbers 1 front-right,
2 rear-right, 3 rear-left, 4 front-left, so ``rotor_map=(1, 4, 2, 3)``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import field_error

#: a step over GAP_FACTOR x a topic's median step is a gap: nothing is interpolated across it.
GAP_FACTOR = 5.0
#: half turn about x: NED -> (north, west, up) and FRD -> FLU.
P_FLIP = np.diag([1.0, -1.0, -1.0])
#: rad/s per RPM.
RPM_TO_RAD_S = 2.0 * np.pi / 60.0


class Columns(dict):
    """Schema columns (name -> float array) and ``notes``: what the importer has to say
    about them (the parser's corruption flags, spans lost, signals left out). The
    validation (:func:`quadsim.logs.flightlog.log_from_columns`) adds the notes to the log."""

    def __init__(self, *args, notes: tuple[str, ...] = (), vehicle: dict | None = None,
                 rates: dict | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.notes = list(notes)
        #: what the log says about the vehicle: ``{"rotors": int, "kind": str, "source": str}``
        self.vehicle = dict(vehicle or {})
        #: each signal's native rate (Hz) where the importer knows it, before resampling:
        #: ``{"rotor_speed": 4.0, ...}`` (signal names of :data:`quadsim.logs.flightlog.
        #: ARRAYS`; :mod:`quadsim.logs.rates`)
        self.rates = dict(rates or {})

    def __reduce__(self):
        return (Columns, (dict(self),), {"notes": self.notes, "vehicle": self.vehicle,
                                         "rates": self.rates})


def median_rate(t: np.ndarray) -> float | None:
    """1 / the median step (Hz) of sample times ``t`` (s); None for fewer than 2 samples or
    no positive step (a topic's native rate, :attr:`Columns.rates`)."""
    steps = np.diff(np.asarray(t, dtype=float))
    steps = steps[np.isfinite(steps) & (steps > 0)]
    return float(1.0 / np.median(steps)) if len(steps) else None


def resample(t_src: np.ndarray, values: np.ndarray, t_out: np.ndarray, *,
             max_gap: float | None = None) -> np.ndarray:
    """Linear interpolation of ``values`` (N,) or (N, K) sampled at ``t_src`` (N,) s onto
    ``t_out`` (M,) s. NaN outside [t_src[0], t_src[-1]] and between two source samples more
    than ``max_gap`` s apart (default GAP_FACTOR x median step). Source samples that are
    NaN make their neighbourhood NaN (no interpolation through missing data)."""
    t_src = np.asarray(t_src, dtype=float)
    values = np.asarray(values, dtype=float)
    t_out = np.asarray(t_out, dtype=float)
    squeeze = values.ndim == 1
    values2 = values[:, None] if squeeze else values
    out = np.full((len(t_out), values2.shape[1]), np.nan)
    if len(t_src) == 0:
        return out[:, 0] if squeeze else out
    if len(t_src) == 1:
        hit = t_out == t_src[0]
        out[hit] = values2[0]
        return out[:, 0] if squeeze else out
    steps = np.diff(t_src)
    if max_gap is None:
        max_gap = GAP_FACTOR * float(np.median(steps))
    # index of the source interval [k, k+1] that holds each output instant
    k = np.clip(np.searchsorted(t_src, t_out, side="right") - 1, 0, len(t_src) - 2)
    inside = (t_out >= t_src[0]) & (t_out <= t_src[-1]) & (steps[k] <= max_gap)
    frac = (t_out - t_src[k]) / steps[k]
    mixed = values2[k] * (1.0 - frac)[:, None] + values2[k + 1] * frac[:, None]
    # exact hits on a sample take that sample (no NaN from the other neighbour)
    exact = np.isclose(frac, 0.0, atol=1e-12)
    mixed[exact] = values2[k[exact]]
    exact1 = np.isclose(frac, 1.0, atol=1e-12)
    mixed[exact1] = values2[k[exact1] + 1]
    out[inside] = mixed[inside]
    return out[:, 0] if squeeze else out


def resample_quat(t_src: np.ndarray, quat: np.ndarray, t_out: np.ndarray, *,
                  max_gap: float | None = None) -> np.ndarray:
    """Quaternions (N, 4) onto ``t_out``: signs made continuous, interpolated linearly
    component-wise, renormalised (equal to slerp to second order in the step)."""
    q = np.asarray(quat, dtype=float).copy()
    flips = np.sign(np.sum(q[1:] * q[:-1], axis=-1))
    q[1:] *= np.cumprod(np.where(flips == 0, 1.0, flips))[:, None]
    out = resample(t_src, q, t_out, max_gap=max_gap)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def ned_to_world(v: np.ndarray) -> np.ndarray:
    """World vectors (..., 3): NED -> ours (x north, y west, z up)."""
    return np.asarray(v, dtype=float) @ P_FLIP


def frd_to_body(v: np.ndarray) -> np.ndarray:
    """Body vectors (..., 3): FRD -> FLU (x forward, y left, z up)."""
    return np.asarray(v, dtype=float) @ P_FLIP


def quat_ned_frd_to_world_body(q: np.ndarray) -> np.ndarray:
    """Body-to-world quaternions (..., 4) wxyz: FRD->NED -> FLU->ours; R' = P R P, which is
    (w, x, y, z) -> (w, x, -y, -z)."""
    return np.asarray(q, dtype=float) * np.array([1.0, 1.0, -1.0, -1.0])


def quat_world_body_to_ned_frd(q: np.ndarray) -> np.ndarray:
    """Inverse of :func:`quat_ned_frd_to_world_body` (the same map: it is an involution)."""
    return quat_ned_frd_to_world_body(q)


def map_rotors(path: Path | str, field: str, values: np.ndarray | None,
               rotor_map: tuple[int, ...] | None) -> np.ndarray | None:
    """Columns (N, R) reordered so that column i is log motor ``rotor_map[i]`` (1-based)."""
    if values is None or rotor_map is None:
        return values
    count = values.shape[1]
    if sorted(rotor_map) != list(range(1, count + 1)):
        raise field_error(path, field, f"rotor map {','.join(map(str, rotor_map))} is not a "
                          f"permutation of 1..{count} (the log has {count} motors)")
    return values[:, [m - 1 for m in rotor_map]]


def pwm_to_unit(pwm: np.ndarray, pwm_range: tuple[float, float]) -> np.ndarray:
    """PWM pulse widths (us) -> normalised commands 0-1: ``(pwm - lo) / (hi - lo)``; values
    from ``lo - 0.1 (hi - lo)`` up to ``lo`` (disarmed outputs, e.g. 900 us) become 0; lower
    ones are left as they are so that the range check reports them."""
    lo, hi = pwm_range
    unit = (np.asarray(pwm, dtype=float) - lo) / (hi - lo)
    return np.where((unit < 0) & (unit >= -0.1), 0.0, unit)


def parse_rotor_map(text: str | None) -> tuple[int, ...] | None:
    """``"1,4,2,3"`` -> (1, 4, 2, 3); None/empty -> None."""
    if not text:
        return None
    try:
        return tuple(int(s) for s in text.split(","))
    except ValueError:
        raise field_error("--rotor-map", "value", f"{text!r}: expected comma-separated "
                          "motor numbers such as 1,4,2,3") from None


def columns_from_signals(t: np.ndarray, signals: dict[str, np.ndarray | None]) -> dict:
    """The flight-log column dict (``quadsim.logs.flightlog`` names) from SI signals: keys
    position, velocity, quat, body_rate, accel (N, k), rotor_speed, rotor_command (N, R),
    vbat (N,); None entries are left out. Time starts at 0."""
    t = np.asarray(t, dtype=float)
    columns = {"t": t - t[0]}
    names = {"position": ("x", "y", "z"), "velocity": ("vx", "vy", "vz"),
             "quat": ("qw", "qx", "qy", "qz"), "body_rate": ("wx", "wy", "wz"),
             "accel": ("ax", "ay", "az")}
    for key, group in names.items():
        value = signals.get(key)
        if value is not None:
            for i, name in enumerate(group):
                columns[name] = np.asarray(value[:, i], dtype=float)
    for key, prefix in (("rotor_speed", "rotor"), ("rotor_command", "cmd")):
        value = signals.get(key)
        if value is not None:
            for i in range(value.shape[1]):
                columns[f"{prefix}_{i + 1}"] = np.asarray(value[:, i], dtype=float)
    if signals.get("vbat") is not None:
        columns["vbat"] = np.asarray(signals["vbat"], dtype=float)
    return columns


#: an optional signal finite on less than this fraction of the rows is left out (with a
#: note) instead of trimming the log to its span.
MIN_COVER = 0.5
#: a trim that loses more than this fraction of the rows is stated in a note.
LOSS_NOTE = 0.05
_REQUIRED_KEYS = ("t", "x", "y", "z", "qw", "qx", "qy", "qz")


def _signal_of(name: str) -> str:
    for group, names in (("position", "xyz"), ("velocity", ("vx", "vy", "vz")),
                         ("quat", ("qw", "qx", "qy", "qz")), ("body_rate", ("wx", "wy", "wz")),
                         ("accel", ("ax", "ay", "az"))):
        if name in names:
            return group
    return name.split("_")[0] if "_" in name else name


def common_span(columns: dict, path: Path | str | None = None) -> Columns:
    """The rows from the first to the last where *every* column is finite (the time span
    that all topics cover); NaN inside the span (a gap in one topic) is kept. Time
    restarts at 0. An optional signal finite on fewer than ``MIN_COVER`` of the rows is
    left out instead (with a note naming it), so that one damaged topic cannot trim the
    flight; a trim losing more than ``LOSS_NOTE`` of the rows is stated in a note with the
    span lost."""
    notes = list(getattr(columns, "notes", ()))
    out = Columns(columns, notes=notes, vehicle=getattr(columns, "vehicle", None),
                  rates=getattr(columns, "rates", None))
    n = len(out["t"])
    where = path if path is not None else "log"
    groups: dict[str, list[str]] = {}
    for name in out:
        if name not in _REQUIRED_KEYS:
            groups.setdefault(_signal_of(name), []).append(name)
    for signal, names in groups.items():
        finite = np.all([np.isfinite(out[k]) for k in names], axis=0)
        if finite.mean() < MIN_COVER:
            for k in names:
                del out[k]
            out.notes.append(f"{where}: {signal}: finite on {int(finite.sum())} of {n} rows; "
                             "left out (the other signals keep the whole flight)")
    ok = np.all([np.isfinite(v) for v in out.values()], axis=0)
    if not ok.any():
        return out
    first, last = int(np.argmax(ok)), len(ok) - int(np.argmax(ok[::-1]))
    t = out["t"]
    if (n - (last - first)) > LOSS_NOTE * n:
        lost = [f"{t[0]:.3f}-{t[first]:.3f} s" for _ in [0] if first > 0]
        lost += [f"{t[last - 1]:.3f}-{t[-1]:.3f} s" for _ in [0] if last < n]
        short = [s for s in groups if not np.all(
            [np.isfinite(out[k][:first]).all() and np.isfinite(out[k][last:]).all()
             for k in groups[s] if k in out])]
        out.notes.append(f"{where}: t: lost {n - (last - first)} of {n} rows "
                         f"({' and '.join(lost)} of the attitude time base) where "
                         f"{', '.join(short) or 'a signal'} is missing")
    for k in list(out):
        out[k] = out[k][first:last]
    out["t"] = out["t"] - out["t"][0]
    return out


def increasing(path, field: str, t: np.ndarray, notes: list[str], *,
               required: bool = True) -> np.ndarray | None:
    """Mask (N,) of the samples whose time exceeds every earlier one (a clock that jumps
    back, or equal stamps). Those lost are stated in ``notes``; more than ``LOSS_NOTE`` of
    the samples lost is refused (the time stamps are corrupt, not a few glitches) or, for
    a signal that is not ``required``, returns None (the caller leaves it out; noted)."""
    t = np.asarray(t, dtype=float)
    if len(t) == 0:
        return np.ones(0, bool)
    keep = np.isfinite(t) & np.concatenate(
        [[True], t[1:] > np.maximum.accumulate(np.where(np.isfinite(t), t, -np.inf))[:-1]])
    lost = int((~keep).sum())
    if lost > LOSS_NOTE * len(t) and not required:
        notes.append(f"{path}: {field}: time does not increase in {lost} of {len(t)} "
                     "samples; the signal is left out (lost)")
        return None
    if lost > LOSS_NOTE * len(t):
        k = int(np.argmax(~keep))
        raise field_error(path, field, f"time does not increase at sample {k} "
                          f"({t[k]:.6g} s after {t[k - 1]:.6g} s); {lost} of {len(t)} "
                          "samples out of order: corrupt time stamps")
    if lost:
        notes.append(f"{path}: {field}: lost {lost} of {len(t)} sample(s) whose time does "
                     "not increase (left out)")
    return keep


def check_unit_quat(path, field: str, t: np.ndarray, quat: np.ndarray,
                    tolerance: float = 0.01) -> None:
    """Refuse finite quaternions (N, 4) whose norm is off 1 by more than ``tolerance``,
    before any normalisation (a 2x or an all-zero quaternion is corrupt, not an attitude)."""
    norms = np.linalg.norm(quat, axis=1)
    bad = np.isfinite(norms) & (np.abs(norms - 1.0) > tolerance)
    if bad.any():
        k = int(np.argmax(bad))
        raise field_error(path, field, f"sample {k} (t = {t[k]:.6g} s): quaternion norm "
                          f"{norms[k]:.4g} ({int(bad.sum())} such sample(s)); expected unit "
                          "quaternions")


def check_parameter(path, name: str, value, *, low: float, high: float,
                    integer: bool = False) -> float:
    """A parameter read from a log, validated like user input: finite, in [low, high],
    a whole number when ``integer``. Returns it as float."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise field_error(path, name, f"parameter {value!r} is not a number") from None
    if not np.isfinite(number) or not low <= number <= high or (
            integer and number != round(number)):
        kind = "a whole number" if integer else "a number"
        raise field_error(path, name, f"parameter {number:g}: expected {kind} in "
                          f"{low:g}..{high:g}")
    return number
