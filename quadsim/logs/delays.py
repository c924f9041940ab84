"""Signal delays: time offsets of the IMU and rotor-speed signals against motion capture.

Real logs carry 5-50 ms between their sources (motion-capture latency, IMU filtering, ESC
telemetry of the rotor speeds). The residual wrench compares the motion with the thrust at
the same instant, so an offset shows as a gap that no physical effect explains. This module
estimates each offset from the log itself, reports it in ms, and shifts the signals so that
they line up with motion capture (the reference clock) before anything is fitted.

Method: motion capture is the reference clock. Each signal is compared with a partner whose
timing is already known, through a relation that holds at every instant, using fast signals
on both sides (smoothed by the same zero-phase Savitzky–Golay filter, so filtering adds no
lag)::

    gyro   w_gyro(t)            vs  w from the motion-capture quaternions, 2 vec(q* dq/dt)
    rotor  int Omega_i^2 dt     vs  w_gyro       (torque = I dw/dt is linear in Omega_i^2;
                                                  integrated, both high-passed over 1 s;
                                                  int w dt also a regressor: rate damping)
    accel  a_imu,z(t)           vs  Omega_i^2    (thrust / mass = body-z specific force)

and the offsets are chained: d_rotor = d_gyro + (rotor behind gyro), d_accel = d_rotor -
(rotor behind accel). The gyro pair uses the normalised cross-correlation summed over the
axes; the other two a per-lag linear regression (target on the lagged regressors plus a
constant: no geometry or b needed) scored by R^2. The best lag is refined to a fraction of a
sample by a parabola through the peak and its two neighbours, k* = k + (c[k-1] - c[k+1]) /
(2 (c[k-1] - 2 c[k] + c[k+1])) (standard time-delay estimation: Knapp & Carter, "The
generalized correlation method for estimation of time delay", IEEE Trans. ASSP 24(4),
1976). Lags are searched up to ``MAX_LAG_S`` on a fixed window (no overlap bias). A positive
delay d (s) means the signal lags motion capture: sig(t) = ref(t - d). An estimate is
refused (``None``, with a note) when its peak is below ``MIN_PEAK``, at the end of the lag
window, or its partner's delay is unknown. Directly differentiating the positions twice
(accelerometer vs p'') was tried and rejected: at 500 Hz with 0.5 mm motion-capture noise it
is too noisy to locate a lag within a sample.

:func:`align_log` shifts each signal earlier by its delay (linear interpolation,
sig_aligned(t) = sig(t + d)) and trims the ends where a shifted signal has no data; only
delays of at least one sample whose peak reaches ``ALIGN_PEAK`` are applied, so a log without
offsets is left as it is. Rotor
commands are not shifted (their delay to the rotor speed is the motor's dynamics).

Example::

    >>> from quadsim.logs.flightlog import load_log
    >>> from quadsim.logs.delays import estimate_delays, align_log
    >>> log = load_log("flight_00.csv.gz")
    >>> est = estimate_delays(log)
    >>> est.ms()                                   # {'gyro': -5.6, 'accel': 0.1, 'rotor': -12.1}
    >>> aligned, est = align_log(log)              # shifted log and the estimate used
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft

from .flightlog import FlightLog, body_rate_from_quat
from .savgol import savgol

__all__ = ["DelayEstimate", "cross_correlation_delay", "estimate_delays", "align_log",
           "align_signal_delays", "delay_notes", "regression_delay", "MIN_PEAK",
           "ALIGN_PEAK", "MAX_LAG_S", "SMOOTH_S"]

#: lag window searched (s): real logs carry 5-50 ms.
MAX_LAG_S = 0.1
#: Savitzky–Golay window (s) applied to both members of each pair.
SMOOTH_S = 0.04
#: peak (correlation or R^2) from which :func:`align_log` applies an estimated delay.
ALIGN_PEAK = 0.8
#: high-pass window (s) of the integrated rotor-speed pair.
HIGHPASS_S = 1.0
#: normalised correlation peak below which a delay is not estimated.
MIN_PEAK = 0.3
#: repeatability: the estimates on the two halves of a log must agree within this (s), or
#: two samples if that is more; otherwise the delay is "not resolvable from this log".
REPEAT_TOL_S = 0.003
SIGNALS = ("gyro", "accel", "rotor")


@dataclass(frozen=True)
class DelayEstimate:
    """Delays (s) of each signal against motion capture (None: absent or not estimable),
    the normalised correlation peak of each pair, the sample step dt (s) and notes."""

    delays: dict[str, float | None]
    peaks: dict[str, float | None]
    dt: float
    notes: tuple[str, ...] = field(default=())

    def ms(self) -> dict[str, float | None]:
        """Delays in ms (rounded to 0.1 ms), None where not estimated."""
        return {k: (None if v is None else round(1e3 * v, 1)) for k, v in self.delays.items()}

    def summary(self) -> str:
        parts = [f"{k} {v:+.1f} ms" for k, v in self.ms().items() if v is not None]
        return ("signal delays vs motion capture: " + ", ".join(parts)) if parts else ""


def cross_correlation_delay(reference: np.ndarray, signal: np.ndarray, dt: float,
                            max_lag_s: float = MAX_LAG_S) -> tuple[float, float, bool]:
    """Delay (s) of ``signal`` behind ``reference`` ((N,) or (N, C), same uniform grid dt),
    the normalised correlation peak (1 = identical shapes) and whether the peak lies inside
    the lag window (False: at its edge, the true delay may be larger)."""
    ref = np.asarray(reference, dtype=float).reshape(len(reference), -1)
    sig = np.asarray(signal, dtype=float).reshape(len(signal), -1)
    ok = np.all(np.isfinite(ref), 1) & np.all(np.isfinite(sig), 1)
    if ok.all():    # numpy's mean and std: the nan-functions' sums and quotients, without
        # their masked copies (the same numbers, ~60 % of the cost)
        ref = (ref - ref.mean(0)) / np.maximum(ref.std(0), 1e-300)
        sig = (sig - sig.mean(0)) / np.maximum(sig.std(0), 1e-300)
    else:
        ref, sig = ref.copy(), sig.copy()
        ref[~ok], sig[~ok] = np.nan, np.nan
        ref = (ref - np.nanmean(ref, 0)) / np.maximum(np.nanstd(ref, 0), 1e-300)
        sig = (sig - np.nanmean(sig, 0)) / np.maximum(np.nanstd(sig, 0), 1e-300)
    ref, sig = np.nan_to_num(ref), np.nan_to_num(sig)
    n = len(ref)
    k_max = max(1, min(int(round(max_lag_s / dt)), n // 4))
    lags = np.arange(-k_max, k_max + 1)
    a = ref[k_max:n - k_max]                      # fixed window: no overlap bias
    m = len(a)
    # per lag k (index j = k + k_max): sum(a * sig[j:j + m]) and sum(sig[j:j + m]^2), as one
    # correlation per column and a running sum of squares
    dot = sum(np.correlate(sig[:, c], a[:, c], mode="valid") for c in range(a.shape[1]))
    energy = np.concatenate([[0.0], np.cumsum(np.sum(sig * sig, axis=1))])
    b_b = energy[m:m + len(lags)] - energy[:len(lags)]
    corr = dot / np.sqrt(np.sum(a * a) * b_b + 1e-300)
    return _peak(lags, corr, dt)


def _pair_delay(kind, ref, sig, fixed, dt, max_lag_s) -> tuple[float, float, bool]:
    if kind == "correlation":
        return cross_correlation_delay(ref, sig, dt, max_lag_s)
    # the regressors are the later signal: their delay behind the target is
    # d(sig) - d(target); for "accel" the target (accelerometer) is the one sought
    return regression_delay(ref, sig, dt, max_lag_s, fixed)


def _peak(lags: np.ndarray, score: np.ndarray, dt: float) -> tuple[float, float, bool]:
    i = int(np.argmax(score))
    inside = 0 < i < len(lags) - 1
    shift = 0.0
    if inside:
        den = score[i - 1] - 2 * score[i] + score[i + 1]
        shift = 0.5 * (score[i - 1] - score[i + 1]) / den if den < 0 else 0.0
    return float((lags[i] + shift) * dt), float(score[i]), inside


def regression_delay(target: np.ndarray, regressors: np.ndarray, dt: float,
                     max_lag_s: float = MAX_LAG_S, fixed: np.ndarray | None = None
                     ) -> tuple[float, float, bool]:
    """Delay (s) of ``regressors`` (N, R) behind ``target`` (N, C): the lag at which a linear
    map (plus constant) from the lagged regressors explains most of the target's variance
    (R^2, sub-sample by a parabola). Needs no geometry: e.g. body angular acceleration
    against the squared rotor speeds. ``fixed`` (N, F): further regressors at the target's
    own time (not lagged), e.g. terms of physical effects that would otherwise look like a
    lag. Returns (delay, R^2 at the peak, peak inside window)."""
    y = np.asarray(target, dtype=float).reshape(len(target), -1)
    x = np.asarray(regressors, dtype=float).reshape(len(regressors), -1)
    n = len(y)
    x = (x - x.mean(0)) / np.maximum(x.std(0), 1e-300)
    k_max = max(1, min(int(round(max_lag_s / dt)), n // 4))
    lags = np.arange(-k_max, k_max + 1)
    a = y[k_max:n - k_max]                        # fixed window: no overlap bias
    extra = [np.ones((len(a), 1))]
    if fixed is not None:
        f = np.asarray(fixed, dtype=float).reshape(n, -1)[k_max:n - k_max]
        extra.append((f - f.mean(0)) / np.maximum(f.std(0), 1e-300))
    # Least squares per lag through its normal equations (residual sum of squares
    # |a|^2 - c^T coef, minimum-norm coef where the Gram matrix is singular): the same R^2 as
    # a QR/SVD solve per lag to ~1e-10 (the regressors are standardised). Every lag's
    # products at once: the lagged columns' own products x_p x_q summed over the sliding
    # window as differences of one running sum, their products with the unlagged columns
    # (constant, fixed, target) as cross-correlations through one FFT of length >= N (no
    # wrap-around: lag + window <= N). Both differ from a per-lag product by round-off: on
    # the 58 real logs of ../shared/data (Crazyflie mixed, nominal, nano-drone training
    # runs) R^2 by up to 4e-12 and the delays by up to 3e-12 s, against the 0.1 ms to which
    # they are reported and used (DelayEstimate.ms; tests/test_delay_regression.py).
    extra = np.concatenate(extra, 1)
    m, r_cols, e_cols = len(a), x.shape[1], extra.shape[1]
    rhs = np.concatenate([extra, a], 1)
    count = len(lags)                       # lag k = j - k_max: x[k_max + k:...] = x[j:j + m]
    gram = np.empty((count, r_cols + e_cols, r_cols + e_cols))
    cross = np.empty((count, r_cols + e_cols, a.shape[1]))
    gram[:, r_cols:, r_cols:] = extra.T @ extra
    cross[:, r_cols:] = extra.T @ a
    p, q = np.triu_indices(r_cols)             # each product x_p x_q once (symmetric)
    running = np.zeros((n + 1, len(p)))
    np.cumsum(x[:, p] * x[:, q], axis=0, out=running[1:])
    gram[:, p, q] = gram[:, q, p] = running[m:m + count] - running[:count]
    length = next_fast_len(n, real=True)
    spectra = rfft(x.T, length)[:, None, :] * np.conj(rfft(rhs.T, length))[None, :, :]
    products = np.moveaxis(irfft(spectra, length)[..., :count], -1, 0)   # (count, r, e + a)
    gram[:, :r_cols, r_cols:] = products[:, :, :e_cols]
    gram[:, r_cols:, :r_cols] = np.swapaxes(products[:, :, :e_cols], 1, 2)
    cross[:, :r_cols] = products[:, :, e_cols:]
    coef = _pseudo_solve(gram) @ cross
    total = np.sum((a - a.mean(0))**2)
    rss = np.maximum(np.sum(a * a) - np.sum(cross * coef, axis=(1, 2)), 0.0)
    return _peak(lags, 1.0 - rss / total, dt)


#: 1-norm condition number of a lag's Gram matrix up to which its plain inverse is used
#: (:func:`_pseudo_solve`): far below pinv's cut (1 / (eps size) ~ 5e14 in the 2-norm, which
#: is within a factor ``size`` of the 1-norm's), so both give the same coefficients to
#: round-off (~ condition x eps); the real logs' Gram matrices reach ~7e3.
PLAIN_INVERSE_COND = 1e8


def _pseudo_solve(gram: np.ndarray) -> np.ndarray:
    """Pseudo-inverses of the stacked symmetric (count, S, S) ``gram``: ``np.linalg.pinv``
    with ``rcond`` = eps S (minimum-norm solutions where a Gram matrix is singular), as the
    plain inverse where every matrix is well conditioned (1-norm condition below
    :data:`PLAIN_INVERSE_COND`: then pinv cuts no singular value, and the inverse costs a
    tenth of pinv's SVDs)."""
    def norm1(m):
        return np.abs(m).sum(axis=-2).max(axis=-1)

    try:
        inverse = np.linalg.inv(gram)
        if np.all(norm1(gram) * norm1(inverse) < PLAIN_INVERSE_COND):
            return inverse
    except np.linalg.LinAlgError:         # exactly singular: pinv's minimum-norm solution
        pass
    return np.linalg.pinv(gram, rcond=np.finfo(float).eps * gram.shape[-1])


def _uniform(log: FlightLog):
    dt = float(np.median(np.diff(log.t)))
    t = log.t[0] + dt * np.arange(int(np.floor((log.t[-1] - log.t[0]) / dt)) + 1)

    def interp(x):
        if x is None:
            return None
        x = np.asarray(x, dtype=float)
        return np.stack([np.interp(t, log.t, x[:, j]) for j in range(x.shape[1])], 1)

    quat = interp(log.quat)
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    return t, dt, interp(log.position), quat, interp(log.body_rate), interp(log.accel), \
        interp(log.rotor_speed)


def _integral(x: np.ndarray, dt: float) -> np.ndarray:
    """Trapezoidal running integral (a plain cumulative sum would lead by half a sample)."""
    x = x - x.mean(0)
    return (np.cumsum(x, axis=0) - 0.5 * (x + x[0])) * dt


def _highpass(x: np.ndarray, dt: float, window_s: float = HIGHPASS_S) -> np.ndarray:
    """x minus its zero-phase running quadratic fit over ``window_s`` (removes drift)."""
    window = min(len(x) - (1 - len(x) % 2), max(5, int(round(window_s / dt)) | 1))
    return x - savgol(x, window, 2, fft=True)


def estimate_delays(log: FlightLog, *, gravity: float = 9.81, max_lag_s: float = MAX_LAG_S,
                    smooth_s: float = SMOOTH_S) -> DelayEstimate:
    """Delays of the gyro, accelerometer and rotor-speed signals of ``log`` against its
    motion capture (position and attitude), see the module docstring. A log without a pose
    has no motion capture to time against: nothing is estimated (said in the notes)."""
    if not log.has_pose:
        dt = float(np.median(np.diff(log.t))) if len(log.t) > 1 else 0.0
        return DelayEstimate(dict.fromkeys(SIGNALS), dict.fromkeys(SIGNALS), dt,
                             (("no pose in the log: signal delays against motion capture "
                               "not estimated"),))
    t, dt, position, quat, gyro, accel, rotor = _uniform(log)
    window = max(5, int(round(smooth_s / dt)) | 1)
    delays: dict[str, float | None] = dict.fromkeys(SIGNALS)
    peaks: dict[str, float | None] = dict.fromkeys(SIGNALS)
    notes = []
    if len(t) < 4 * window:
        return DelayEstimate(delays, peaks, dt, ("log too short to estimate signal delays",))

    def smooth(x):
        return savgol(x, window, 3)

    # gyro against motion capture; the rotor speeds against the gyro (torque ~ angular
    # acceleration) and the accelerometer against the rotor speeds (thrust ~ specific force):
    # fast signals with little noise on both sides, chained back to motion capture.
    pairs = {}
    if gyro is not None:
        rate = smooth(gyro)        # both relations read the smoothed gyro: smoothed once
        pairs["gyro"] = ("correlation", smooth(body_rate_from_quat(t, quat)), rate, None, None)
        if rotor is not None:
            # integrated form: rate vs the integral of Omega^2 (torque impulse), both
            # high-passed; the gyro's vibration noise is not differentiated
            # (the integrated rate is a fixed regressor: linear rate damping, I w = int tau -
            # k int w, would otherwise look like a lag of the rate behind the rotors)
            impulse, turned = _integral(rotor**2, dt), _integral(gyro, dt)
            pairs["rotor"] = ("regression", _highpass(rate, dt),
                              _highpass(smooth(impulse), dt), "gyro",
                              _highpass(smooth(turned), dt))
    if rotor is not None and accel is not None:
        pairs["accel"] = ("regression", smooth(accel[:, 2:3]), smooth(rotor**2), "rotor", None)
    half = len(t) // 2
    for name in ("gyro", "rotor", "accel"):
        if name not in pairs:
            continue
        kind, ref, sig, base, fixed = pairs[name]
        delay, peak, inside = _pair_delay(kind, ref, sig, fixed, dt, max_lag_s)
        peaks[name] = peak
        # repeatability: the same relation on each half of the log must give the same delay
        halves = [_pair_delay(kind, ref[part], sig[part], None if fixed is None else fixed[part],
                              dt, max_lag_s)
                  for part in (slice(0, half), slice(half, None))] if half >= 8 * window else []
        spread = abs(halves[0][0] - halves[1][0]) if halves else 0.0
        tol = max(REPEAT_TOL_S, 2 * dt)
        if base is not None and delays.get(base) is None:
            notes.append(f"{name}: delay not estimated ({base} delay unknown)")
        elif peak < MIN_PEAK:
            notes.append(f"{name}: delay not estimated (fit to its partner signal "
                         f"{peak:.2f} < {MIN_PEAK}; too little excitation or a noisy signal)")
        elif not inside:
            notes.append(f"{name}: delay not estimated (beyond the {1e3 * max_lag_s:.0f} ms "
                         "searched)")
        elif spread > tol:
            notes.append(f"{name}: delay not resolvable from this log (the two halves give "
                         f"{1e3 * halves[0][0]:+.1f} and {1e3 * halves[1][0]:+.1f} ms, "
                         f"more than {1e3 * tol:.0f} ms apart: filtered or delayed beyond "
                         "what its partner signal can time)")
        elif name == "rotor":
            delays[name] = delays["gyro"] + delay
        elif name == "accel":
            delays[name] = delays["rotor"] - delay
        else:
            delays[name] = delay
    return DelayEstimate(delays, peaks, dt, tuple(notes))


def _shift(t: np.ndarray, x: np.ndarray | None, delay: float | None) -> np.ndarray | None:
    if x is None or delay is None:
        return x
    return np.stack([np.interp(t + delay, t, x[:, j]) for j in range(x.shape[1])], 1)


def align_log(log: FlightLog, estimate: DelayEstimate | None = None, *,
              min_samples: float = 1.0, min_peak: float = ALIGN_PEAK,
              signals: tuple[str, ...] = SIGNALS) -> tuple[FlightLog, DelayEstimate]:
    """``log`` with each signal shifted earlier by its delay (``estimate``, default
    :func:`estimate_delays`), ends trimmed; delays shorter than ``min_samples`` samples or
    with a peak below ``min_peak``, and signals not in ``signals``, are not applied. Returns
    the aligned log and the estimate."""
    estimate = estimate_delays(log) if estimate is None else estimate
    applied = {k: (v if v is not None and abs(v) >= min_samples * estimate.dt
                   and estimate.peaks[k] >= min_peak and k in signals else None)
               for k, v in estimate.delays.items()}
    used = [v for v in applied.values() if v is not None]
    if not used:
        return log, estimate
    keep = (log.t + min(0.0, min(used)) >= log.t[0]) & (log.t + max(0.0, max(used)) <= log.t[-1])
    t = log.t

    def cut(x):
        return None if x is None else x[keep]

    aligned = replace(
        log, t=t[keep], position=log.position[keep], quat=log.quat[keep],
        velocity=cut(log.velocity), body_rate=cut(_shift(t, log.body_rate, applied["gyro"])),
        accel=cut(_shift(t, log.accel, applied["accel"])),
        rotor_speed=cut(_shift(t, log.rotor_speed, applied["rotor"])),
        rotor_command=cut(log.rotor_command), vbat=cut(log.vbat),
        notes=log.notes + (estimate.summary() + "; shifted to align: "
                           + ", ".join(k for k, v in applied.items() if v is not None),))
    return aligned, estimate


def align_signal_delays(log: FlightLog) -> tuple[FlightLog, DelayEstimate]:
    """The gap diagnosis' hook: estimate all delays and return them in ms; shift only the
    gyro, by delays of 1.5 samples or more. The rotor and accelerometer offsets are reported,
    not shifted: their partner relations are changed by the very effects the diagnosis looks
    for (on generated 5 s Crazyflie logs without any delay, the rotor estimate reads 1-3 ms,
    and 8 ms with rotor gyroscopic/spin-up torques; drag and battery sag move the
    accelerometer estimate by up to 10 ms), while the gyro estimate stays within 0.2 ms."""
    return align_log(log, min_samples=1.5, signals=("gyro",))


def delay_notes(flights) -> list[str]:
    """One note per flight (objects with ``name``, ``delays_ms`` and ``delay_notes``) that
    has a delay or a delay that could not be resolved. A flight whose rotor speeds were
    synthesised from its commands (``speeds_synthesised``) has its "rotor" delay named so:
    it times the commands through the command -> speed model, not a logged signal."""
    out = []
    for f in flights:
        synthesised = getattr(f, "speeds_synthesised", False)
        parts = [f"{'rotor (synthesised from the commands)' if k == 'rotor' and synthesised else k}"
                 f" {v:+.1f} ms" for k, v in getattr(f, "delays_ms", {}).items()
                 if v is not None]
        if parts:
            out.append(f"{f.name}: signal delays vs motion capture: {', '.join(parts)} "
                       "(estimated; a gyro delay of 1.5 samples or more is shifted out before "
                       "fitting, the others are reported only)")
        unresolved = [n for n in getattr(f, "delay_notes", ()) if "not resolvable" in n]
        if unresolved:
            out.append(f"{f.name}: " + "; ".join(unresolved))
    return out
