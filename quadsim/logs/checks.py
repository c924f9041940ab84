"""Flight-log consistency checks: channels that must agree with each other, not only
plausible magnitudes.

The loader (:mod:`quadsim.logs.flightlog`) refuses values no vehicle produces (rotor speeds
above any motor, rates above any airframe). A gyro in deg/s on a gentle flight, a flipped
axis or an accelerometer in g on a small log passes those limits; here each channel is
checked against another one that measures the same physics:

* **gyro vs attitude** -- the quaternions give the exact rotation over a window:
  ``rotvec(conj(q_k) q_{k+m})`` (body frame, rad) must equal the integrated gyro
  ``int w dt`` over the same window (``WINDOW_S`` = 0.1 s, trapezoid). Per axis, the gain
  ``g_i = <gyro_i, quat_i> / <quat_i, quat_i>`` must lie in [0.3, 3] (gross errors only:
  unit, sign, axis; a calibration error is for the diagnosis to find) and the best
  matching quaternion axis must be the same axis with the same sign. deg/s gives g = 57.3,
  a sign error g = -1, a swapped axis another best match. An axis is judged when either
  the gyro or the quaternions turn by more than ``MIN_ROTATION_RAD`` rms per window, so a
  deg/s gyro on a gentle flight (3 deg/s, below every magnitude limit) is still caught.
* **gyro frame** -- the integrated gyro against the attitude's rotation in the body frame and
  in the world frame, the two hypotheses compared by their residuals at the noise scale
  (:func:`_check_gyro_frame`; checked first, a world-frame gyro also upsets the gains):
  a body rate logged in the world frame is refused at 18 deg of tilt.
* **accelerometer vs velocity** -- the specific force rotated to the world frame and
  averaged over the window must equal ``(v_{k+m} - v_k) / T + g e_z`` (m/s^2). The world-z
  gain (dominated by gravity) must lie in [0.6, 1.6] (in g: 0.10) and the horizontal axes,
  where excited (rms above ``MIN_ACCEL``, net of the noise), likewise: a world-frame log
  rotated again doubles the tilt, gain ~2. Both sides carry sensor noise (a velocity noise
  of 0.03 m/s per sample puts 0.4 m/s^2 on a 0.1 s window's difference), so the gain is an
  errors-in-variables (Deming) fit with each side's noise read from the log
  (:func:`_deming_gain`, :func:`_window_noise`). A sign error on a *body* horizontal axis is
  not visible: a multirotor's specific force lies almost along body z.
* **rotor speeds vs weight** -- ``b sum(Omega^2)`` averaged over the flight against
  ``m g`` (or ``m`` times the logged body-z specific force): the ratio must lie in
  [0.25, 4] (RPM logged as rad/s gives 91, Hz as rad/s 0.025).
* **rotor speeds, rotor by rotor** -- each rotor's median logged speed over the airborne
  samples against the median of the other rotors' (:func:`check_rotor_speeds`): a rotor whose
  speed lies beyond ``ROTOR_SPEED_SPREAD`` = 1.75x of it (a thrust share beyond 3x or below
  1/3 of the others') holds no vehicle level, so its speed sensor is wrong. At a
  whole factor n = 2 .. 8 (or 1/n) within ``PULSE_TOLERANCE`` = 5 %, a tachometer that counts
  n pulses per turn as one or one as n (a pulse-count or pole-pair setting), the speeds are
  read scaled by it, with a note; otherwise the log is refused naming the rotor.
* **rotor order** -- the angular momentum per sample against the mixer's torque integral of
  the rotor columns under every permutation (:func:`check_rotor_order`): an order whose
  Delta chi^2 over the log's own exceeds ``ORDER_CHI2`` = 25 at the noise scale is refused
  with the ``--rotor-map`` that applies it.
* **NaN runs** in any channel: the longest all-finite stretch is kept with a note when it
  holds at least ``MIN_KEPT_FRACTION`` = 50 % of the samples (and at least
  ``MIN_KEPT_S`` = 1 s); otherwise the log is refused. The fitter never sees a NaN.

Every refusal is one :func:`~quadsim.core.errors.field_error` line naming the file, the column
and the numbers. Example::

    >>> from quadsim.logs.checks import check_log
    >>> log, notes = check_log(load_log("flight.csv.gz"), params)
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
from scipy.integrate import cumulative_trapezoid

from ..core.errors import QuadsimWarning, field_error
from ..core.frames import quat_to_rotmat
from ..core.lag import first_order_lag
from .spans import cut_ground, join_airborne, split_airborne

__all__ = ["RotorOrder", "check_log", "check_log_stretches", "check_logs", "check_rotor_speeds",
           "gyro_frame_evidence", "order_reading", "rotor_order_evidence",
           "rotor_order_source", "rotor_order_status", "spin_reversal_evidence"]

WINDOW_S = 0.1
MIN_ROTATION_RAD = 0.005
MIN_ACCEL = 0.3          # m/s^2 rms of a horizontal axis to judge it
GAIN_RANGE = (0.3, 3.0)  # gross errors only (unit, sign, frame); calibration is the diagnosis
THRUST_RANGE = (0.25, 4.0)
ACCEL_GAIN_RANGE = (0.6, 1.6)  # world instead of body frame doubles the horizontal gain
MIN_KEPT_FRACTION = 0.5
#: gyro in the world frame: refused when the world frame's Delta chi^2 over the body frame
#: exceeds FRAME_CHI2 and the world frame leaves under FRAME_GOOD of the gyro unexplained
FRAME_CHI2 = 25.0
FRAME_GOOD = 0.25
#: rotor order refused when another order's Delta chi^2 over the log's own exceeds this
ORDER_CHI2 = 25.0
#: a rival rotor order fitting better than the log's own by this Delta chi^2 (two sigma)
#: makes the order doubtful (verdicts tentative; refused above ORDER_CHI2): on real flights
#: the right order's rivals stay below it, most swaps lie above (CHANGELOG.md: Docstrings as
#: contracts).
DOUBT_CHI2 = 4.0
#: windows of the torque balance (s) whose means are removed: short against a manoeuvre,
#: so that an unmodelled torque does not accumulate
ORDER_WINDOW_S = 0.4
#: a rotor at or above this share of its full command (or of the set's max_speed) is
#: saturated: its logged value no longer says what it turns at (the motor gives what the
#: battery allows), so the torque balance leaves those samples out (issue 47: a flight with
#: 10 % of its samples at the full-command cap was refused at Delta chi^2 72); the same
#: 0.99 as :data:`quadsim.identify.motor_fits.SATURATED`
ORDER_SATURATED = 0.99
MIN_KEPT_S = 1.0
#: a rotor's median airborne speed beyond this factor of the other rotors' median is no rotor
#: of a flying vehicle (:func:`check_rotor_speeds`): its thrust share would be beyond 3x (or
#: below 1/3) the others'. A propeller at the library's weakest (thrust -50 %,
#: :mod:`quadsim.effects.thrust_mismatch`) turns sqrt(2) = 1.41x faster to give its share
#: (measured on a generated flight: 1.415x), a CoM a quarter arm off the centre moves a
#: share by +/-25 % (its speed by +/-12 %): 1.58x at most together; real rotors of one
#: vehicle lie within 1-4 % of each other (the shared Crazyflie flights)
ROTOR_SPEED_SPREAD = 1.75
#: a rotor's speed at n or 1/n (n = 2 .. MAX_PULSE_FACTOR) of the other rotors' within this
#: fraction is read as a tachometer's pulse count (each turn counted as n, or n turns as
#: one) and scaled back; the real case: two shared Crazyflie flights read rotor 3 at
#: 0.502-0.503 of the others' (the others within 1.8 % of each other)
PULSE_TOLERANCE = 0.05
MAX_PULSE_FACTOR = 8
#: rotors of the largest vehicle that cannot hold level with one rotor far off the others'
#: thrust (:func:`check_rotor_speeds`): a quadrotor's roll, pitch and yaw need all four; a
#: hexarotor or octorotor can fly on with one weak or lost, so there a rotor beyond
#: ROTOR_SPEED_SPREAD at no pulse-count factor is kept as logged, with a note
QUAD_ROTORS = 4
#: what each rotor-speed correction in ``FlightLog.corrections`` says after the column name
#: (:func:`check_rotor_speeds`); a log without its speeds drops these
#: (:func:`quadsim.gap.logcheck.without_speeds`)
SPEED_CORRECTION = "'s speeds read x"
_ARRAYS = ("position", "quat", "velocity", "body_rate", "accel", "rotor_speed",
           "rotor_command", "vbat")


def _where(log) -> object:
    return log.path if log.path is not None else "log"


def _finite_rows(log) -> np.ndarray:
    ok = np.isfinite(log.t)
    for name in _ARRAYS:
        value = getattr(log, name)
        if value is not None:
            ok &= np.all(np.isfinite(np.reshape(value, (len(log.t), -1))), axis=1)
    return ok


def cut_nan(log):
    """(log, note or None): keep the longest all-finite stretch, or refuse (see module)."""
    ok = _finite_rows(log)
    if ok.all():
        return log, None
    bad_channels = [name for name in _ARRAYS if getattr(log, name) is not None and not np.all(
        np.isfinite(getattr(log, name)))]
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))
    starts, stops = edges[::2], edges[1::2]
    n = len(log.t)
    if len(starts) == 0:
        raise field_error(_where(log), bad_channels[0], "no sample where every channel is "
                          "finite")
    best = int(np.argmax(stops - starts))
    a, b = int(starts[best]), int(stops[best])
    span = float(log.t[b - 1] - log.t[a]) if b - a > 1 else 0.0
    if (b - a) < MIN_KEPT_FRACTION * n or span < MIN_KEPT_S:
        raise field_error(
            _where(log), bad_channels[0],
            f"NaN/Inf in {100 * (1 - ok.mean()):.1f} % of the samples "
            f"({', '.join(bad_channels)}); the longest clean stretch is {b - a} of {n} samples "
            f"({span:.3g} s), below {100 * MIN_KEPT_FRACTION:.0f} % / {MIN_KEPT_S} s: refused "
            "(the fitter cannot use non-finite data)")
    cut = {name: (None if getattr(log, name) is None else getattr(log, name)[a:b])
           for name in _ARRAYS}
    note = (f"{_where(log)}: {', '.join(bad_channels)}: NaN/Inf in {n - int(ok.sum())} "
            f"samples; kept the clean stretch lines {a + 2}-{b + 1} "
            f"(t {log.t[a]:.3f}-{log.t[b - 1]:.3f} s, {b - a} of {n} samples)")
    new = dataclasses.replace(log, t=log.t[a:b], notes=(*log.notes, note), **cut)
    return new, note


def _windows(t: np.ndarray) -> np.ndarray:
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    m = max(1, round(WINDOW_S / dt)) if dt > 0 else 1
    return np.arange(0, len(t), m)


def _rotvec_between(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Rotation vector (body frame of q0) of conj(q0) * q1, wxyz."""
    w0, v0 = q0[:, :1], -q0[:, 1:]
    w1, v1 = q1[:, :1], q1[:, 1:]
    w = w0 * w1 - np.sum(v0 * v1, axis=1, keepdims=True)
    v = w0 * v1 + w1 * v0 + np.cross(v0, v1)
    v = np.where(w < 0, -v, v)
    w = np.abs(w)
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    angle = 2 * np.arctan2(norm, w)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(norm > 1e-12, angle / norm, 2.0)
    return v * scale


#: the span (s) of the cubic Savitzky-Golay derivative that stands for a velocity a log does
#: not carry (:func:`_position_velocity`): half the check's window, so that the window's
#: velocity difference still carries its manoeuvres
POSITION_SPAN_S = WINDOW_S / 2


def _position_velocity(log) -> np.ndarray:
    """(N, 3) m/s: the velocity of a log that carries its position only: the position
    smoothed by a cubic Savitzky-Golay filter over :data:`POSITION_SPAN_S` at the rows'
    median step (:func:`_position_window`), differentiated on the rows' own times
    (``numpy.gradient``: a logging gap is no jump). Why not the sample-to-sample gradient:
    a motion-capture position held on faster rows (the Crazyflie's 100-175 Hz pose on
    500 Hz rows) steps, and its gradient is a train of spikes whose noise estimate
    (:func:`_window_noise`) swamps the signal (docs/flightlog.md, consistency checks)."""
    from .savgol import savgol

    dt = float(np.median(np.diff(log.t)))
    window = _position_window(dt)
    if len(log.t) <= window:
        return np.gradient(log.position, log.t, axis=0)
    return np.gradient(savgol(np.asarray(log.position, float), window, 3), log.t, axis=0)


def _position_window(dt: float) -> int:
    """The odd sample count of :func:`_position_velocity`'s filter at a row step ``dt`` (s):
    :data:`POSITION_SPAN_S`, at least 5 rows (a cubic fit needs more rows than its 4
    coefficients to smooth anything)."""
    return max(5, int(round(POSITION_SPAN_S / dt)) | 1)


def _window_noise(log, velocity: np.ndarray, span: float) -> tuple[np.ndarray, np.ndarray]:
    """(3,), (3,): the variance that white sensor noise puts into :func:`check_accel`'s
    window means over ``span`` s, per world axis: of the velocity difference over the window,
    2 sigma_v^2 / T^2 (sigma_v per sample, from second differences as the gyro's,
    :func:`_gyro_noise`), and of the accelerometer's window mean, sigma_a^2 dt / T (its
    per-axis noise pooled over the body axes: the rotation to the world mixes them)."""
    dt = float(np.median(np.diff(log.t)))
    sigma_v = _gyro_noise(velocity)
    sigma_a = float(np.sqrt(np.mean(_gyro_noise(log.accel) ** 2)))
    return 2.0 * sigma_v ** 2 / span ** 2, np.full(3, sigma_a ** 2 * dt / span)


def _deming_gain(measured: np.ndarray, reference: np.ndarray, ratio: float) -> float:
    """The gain of ``measured`` on ``reference`` when both carry noise (Deming regression,
    errors in variables): ``ratio`` the measured's noise variance over the reference's
    (inf: the reference is noise-free, the least-squares gain :func:`_gain`). With
    s_xx, s_yy, s_xy the second moments about zero (x the reference, y measured; the windows'
    gravity and manoeuvres are the signal, no intercept),
    beta = (s_yy - r s_xx + sqrt((s_yy - r s_xx)^2 + 4 r s_xy^2)) / (2 s_xy).
    Why not least squares: the velocity side's noise attenuates its gain by
    s_signal^2 / (s_signal^2 + s_noise^2) (docs/flightlog.md, consistency checks)."""
    if not np.isfinite(ratio):
        return _gain(measured, reference)
    sxx = float(np.mean(reference * reference))
    syy = float(np.mean(measured * measured))
    sxy = float(np.mean(measured * reference))
    if sxy == 0.0:
        return 0.0 if sxx > 0 else float("nan")
    d = syy - ratio * sxx
    return (d + np.sqrt(d * d + 4.0 * ratio * sxy * sxy)) / (2.0 * sxy)


def _gain(measured: np.ndarray, reference: np.ndarray) -> float:
    """Least-squares gain of ``measured`` on ``reference``; NaN when the reference is 0."""
    power = float(np.sum(reference * reference))
    return float(np.sum(measured * reference)) / power if power > 0 else float("nan")


def _window_rotations(log):
    """(window edges k, rotation vectors between the quaternions at the edges, the gyro's
    integral over each window) (rad), or None when the log has no gyro, no attitude or too
    few windows."""
    if log.body_rate is None or log.quat is None or len(log.t) < 4:
        return None
    k = _windows(log.t)
    if len(k) < 3:
        return None
    quat_rot = _rotvec_between(log.quat[k[:-1]], log.quat[k[1:]])
    integral = cumulative_trapezoid(log.body_rate, log.t, axis=0, initial=0)
    return k, quat_rot, integral[k[1:]] - integral[k[:-1]]


def _scalar_last_fits(log, k: np.ndarray, gyro_rot: np.ndarray, axis: int) -> bool:
    """Whether the gyro's rotation about ``axis`` over the windows ``k`` follows the
    attitude's once its columns ``qw, qx, qy, qz`` are read as x, y, z, w (a scalar-last
    quaternion written under scalar-first names): correlation above 0.7 on that axis (the
    swap test's own level, :func:`check_gyro`)."""
    q = np.asarray(log.quat, float)[:, [3, 0, 1, 2]]
    rot = _rotvec_between(q[k[:-1]], q[k[1:]])
    if np.std(rot[:, axis]) == 0 or np.std(gyro_rot[:, axis]) == 0:
        return False
    return abs(float(np.corrcoef(gyro_rot[:, axis], rot[:, axis])[0, 1])) > 0.7


def check_gyro(log) -> str | None:
    """Gyro against the quaternions' rotation (see module); raises, or returns a note when
    the flight is too gentle to judge."""
    rotations = _window_rotations(log)
    if rotations is None:
        return None
    k, quat_rot, gyro_rot = rotations
    _check_gyro_frame(log, k, quat_rot, gyro_rot)  # first: a frame error also upsets the gains
    judged = 0
    for i, axis in enumerate("xyz"):
        if max(np.sqrt(np.mean(quat_rot[:, i] ** 2)),
               np.sqrt(np.mean(gyro_rot[:, i] ** 2))) < MIN_ROTATION_RAD:
            continue  # neither turns: nothing to compare
        judged += 1
        gains = [_gain(gyro_rot[:, i], quat_rot[:, j]) for j in range(3)]
        corr = [abs(np.corrcoef(gyro_rot[:, i], quat_rot[:, j])[0, 1])
                if np.std(quat_rot[:, j]) > 0 and np.std(gyro_rot[:, i]) > 0 else 0.0
                for j in range(3)]
        best = int(np.nanargmax(corr))
        gain = gains[i]
        if best != i and corr[best] > 0.7 and corr[best] > corr[i] + 0.2:
            if _scalar_last_fits(log, k, gyro_rot, i):
                raise field_error(_where(log), "qw..qz", "the gyro follows the attitude only "
                                  "with the quaternion columns read as x, y, z, w: written "
                                  "scalar-last? (expected scalar first: qw, qx, qy, qz)")
            raise field_error(_where(log), f"w{axis}",
                              f"gyro w{axis} follows the attitude's {'xyz'[best]} axis "
                              f"(correlation {corr[best]:.2f} vs {corr[i]:.2f} with {axis}) "
                              "over 0.1 s windows: axes swapped?")
        if not np.isfinite(gain):
            raise field_error(_where(log), f"w{axis}",
                              f"the integrated gyro turns "
                              f"{np.sqrt(np.mean(gyro_rot[:, i] ** 2)):.3g} rad rms about "
                              f"{axis} over {WINDOW_S} s windows, the attitude quaternions not "
                              "at all: not the gyro of this flight, or a wrong unit?")
        if not GAIN_RANGE[0] <= gain <= GAIN_RANGE[1]:
            hint = ("deg/s instead of rad/s?" if 40 < gain < 80 else
                    "sign flipped (frame convention)?" if -1.4 < gain < -0.7 else
                    "wrong unit or frame?")
            raise field_error(_where(log), f"w{axis}",
                              f"integrated gyro = {gain:.4g} x the rotation of the attitude "
                              f"quaternions over {WINDOW_S} s windows (expected 1): {hint}")
    if judged == 0:
        return (f"{_where(log)}: wx, wy, wz: too little rotation to check the gyro against the "
                "attitude")
    return None


def _frame_evidence(log, k: np.ndarray, quat_rot: np.ndarray, gyro_rot: np.ndarray
                    ) -> tuple[float, float, bool, float]:
    """(RSS_body, RSS_world (rad^2), whether the world frame explains the gyro, Delta chi^2
    of the world frame over the body frame); see :func:`_check_gyro_frame`."""
    world_rot = np.einsum("nij,nj->ni", quat_to_rotmat(log.quat[k[:-1]]), quat_rot)
    ok = np.isfinite(world_rot).all(axis=1) & np.isfinite(gyro_rot).all(axis=1)
    gyro_rot, quat_rot, world_rot = gyro_rot[ok], quat_rot[ok], world_rot[ok]
    if len(gyro_rot) < 5:
        return 0.0, 0.0, False, 0.0
    body_res, world_res = gyro_rot - quat_rot, gyro_rot - world_rot
    body, world = float(np.sum(body_res ** 2)), float(np.sum(world_res ** 2))
    better = body_res if body < world else world_res
    flat = better.T.ravel()  # window to window, axis after axis
    rho = float(np.corrcoef(flat[1:], flat[:-1])[0, 1]) if np.std(flat) > 0 else 0.0
    effective = float(np.clip((1.0 - rho) / (1.0 + rho), 1e-3, 1.0))
    scale = max(min(body, world) / max(gyro_rot.size - 3, 1), 1e-30)
    good = world <= FRAME_GOOD * float(np.sum(gyro_rot ** 2))
    return body, world, good, effective * (body - world) / scale


def gyro_frame_evidence(log) -> tuple[float, float, bool, float] | None:
    """:func:`_frame_evidence` of a log (None when it has no gyro or is too short)."""
    rotations = _window_rotations(log)
    return None if rotations is None else _frame_evidence(log, *rotations)


def _check_gyro_frame(log, k: np.ndarray, quat_rot: np.ndarray, gyro_rot: np.ndarray) -> None:
    """Body rate logged in the world frame: two hypotheses for the integrated gyro over each
    window, the attitude's rotation in the body frame (``rotvec(conj(q_k) q_{k+m})``) or the
    same rotation in the world frame (turned by R(q_k): the world-frame rotation vector of
    ``q_{k+m} conj(q_k)``), compared by their residual sums of squares RSS_body, RSS_world
    (rad^2). The evidence for the world frame is ``Delta chi^2 = n (RSS_body - RSS_world) /
    s^2``, with the noise scale s^2 = the better hypothesis' RSS per degree of freedom and
    ``n = (1 - rho)/(1 + rho)`` for residuals correlated from window to window (lag-1 rho).
    Refused when Delta chi^2 > ``FRAME_CHI2`` and the world frame explains the gyro
    (RSS_world under ``FRAME_GOOD`` x the gyro's own sum of squares; a gyro of the wrong sign
    or unit matches neither frame and is left to the gain check). The frames differ by the
    tilt and the heading: at 18 deg of tilt (generated figure-8, heading held) a world-frame
    gyro gives Delta chi^2 in the hundreds."""
    body, world, good, evidence = _frame_evidence(log, k, quat_rot, gyro_rot)
    if good and evidence > FRAME_CHI2:
        raise field_error(_where(log), "wx..wz",
                          f"the integrated gyro matches the attitude's rotation in the world "
                          f"frame (residual {world:.3g} rad^2) far better than in the body frame "
                          f"({body:.3g} rad^2; Delta chi^2 {evidence:.3g} > {FRAME_CHI2:g} at the "
                          f"noise scale, {WINDOW_S} s windows): body rate logged in the world "
                          "frame? (expected the body frame, x forward, y left, z up)")


def check_accel(log, gravity: float = 9.81) -> None:
    """Accelerometer against the velocity derivative plus gravity (see module); not judged
    without a pose (the loader's magnitude test still catches g for m/s^2)."""
    if log.accel is None or not log.has_pose or len(log.t) < 4:
        return
    k = _windows(log.t)
    if len(k) < 3:
        return
    velocity = log.velocity if log.velocity is not None else _position_velocity(log)
    world = np.einsum("nij,nj->ni", quat_to_rotmat(log.quat), log.accel)
    integral = cumulative_trapezoid(world, log.t, axis=0, initial=0)
    span = (log.t[k[1:]] - log.t[k[:-1]])[:, None]
    measured = (integral[k[1:]] - integral[k[:-1]]) / span
    expected = (velocity[k[1:]] - velocity[k[:-1]]) / span
    expected[:, 2] += gravity
    noise_x, noise_y = _window_noise(log, velocity, float(np.median(span)))
    for i, axis in enumerate("xyz"):
        # excited: the velocity derivative's own variance above what its noise makes
        if i < 2 and np.mean(expected[:, i] ** 2) - noise_x[i] < MIN_ACCEL ** 2:
            continue
        gain = _deming_gain(measured[:, i], expected[:, i], noise_y[i] / noise_x[i]
                            if noise_x[i] > 0 else np.inf)
        if not ACCEL_GAIN_RANGE[0] <= gain <= ACCEL_GAIN_RANGE[1]:
            hint = ("in g instead of m/s^2?" if 0.07 < gain < 0.14 else
                    "sign or frame (world instead of body?) wrong?")
            raise field_error(_where(log), f"a{axis}",
                              f"accelerometer rotated to the world frame = {gain:.4g} x "
                              f"(velocity derivative + g) on world {axis} over {WINDOW_S} s "
                              f"windows (expected 1): {hint}")


def check_rotor_speeds(log):
    """Each rotor's logged speed against the other rotors' (see module): returns (``log``,
    note) with a rotor read at a whole pulse-count factor scaled back and, for each, a short
    line ("rotor_3's speeds read x 2 (logged at 0.501x the other rotors' speed per command:
    a speed sensor counting one turn in every 2?)") added to the log's
    :attr:`~quadsim.logs.flightlog.FlightLog.corrections` (note None when none is).

    A rotor's level is its median speed over the log's samples where every rotor turns
    (speed above 5 % of the rotors' largest median: the airborne samples, after
    :func:`quadsim.logs.spans.join_airborne`), its ratio that level over the median of the
    other rotors' levels (so one wrong rotor never moves its own yardstick; two of four
    wrong alike are not told from two right). A ratio beyond :data:`ROTOR_SPEED_SPREAD`
    either way is scaled by n (or 1/n) where the rotor's speed per command over the other
    rotors' median (:func:`_speed_per_command`; the speed ratio itself without commands)
    lies within :data:`PULSE_TOLERANCE` of 1/n (or n), n = 2 .. :data:`MAX_PULSE_FACTOR`,
    and otherwise refused (one field_error line naming the rotor column) on a vehicle of at
    most :data:`QUAD_ROTORS` rotors, kept as logged with a note (a failing motor?) on a
    larger one. Logs without rotor speeds, or with fewer than three rotors, pass
    unchanged."""
    speeds = log.rotor_speed
    if speeds is None or speeds.ndim != 2 or speeds.shape[1] < 3 or len(speeds) < 2:
        return log, None
    if not np.all(np.isfinite(speeds)):
        return log, None
    level = np.median(np.abs(speeds), axis=0)
    turning = np.all(np.abs(speeds) > 0.05 * float(np.max(level)), axis=1)
    if np.count_nonzero(turning) < 2:
        return log, None
    level = np.median(np.abs(speeds[turning]), axis=0)
    others = _others_median(level)
    if np.any(others <= 0):
        return log, None
    ratio = level / others
    off = np.flatnonzero(np.abs(np.log(np.maximum(ratio, 1e-12))) > np.log(ROTOR_SPEED_SPREAD))
    if off.size == 0:
        return log, None
    # the factor is read from the speed per command where commands are logged: a pulse count
    # scales it exactly, while the speed itself also carries the rotor's share of holding
    # the vehicle level (0.54x on a real flight whose speed per command reads 0.503x)
    per_command = _speed_per_command(log, turning)
    scale = np.ones(len(ratio))
    said, short, kept = [], [], []
    for i in off:
        r = float(ratio[i] if per_command is None else per_command[i])
        n = round(1.0 / r) if r < 1.0 else round(r)
        factor = float(n) if r < 1.0 else 1.0 / n
        if not 2 <= n <= MAX_PULSE_FACTOR or abs(r * factor - 1.0) > PULSE_TOLERANCE:
            per = "" if per_command is None else f"; its speed per command {r:.3g}x theirs"
            if len(ratio) > QUAD_ROTORS:    # a failing rotor a larger multirotor flies with
                kept.append(f"rotor_{i + 1} kept as logged (its speed {ratio[i]:.3g}x the "
                            f"other rotors' median over the flight{per}: a failing motor, or "
                            f"its speed sensor? a vehicle of {len(ratio)} rotors can hold "
                            "level with one rotor weak)")
                continue
            raise field_error(_where(log), f"rotor_{i + 1}",
                              f"its speed is {ratio[i]:.3g}x the other rotors' median over "
                              f"the flight ({level[i]:.4g} against {others[i]:.4g} rad/s: a thrust "
                              f"share {ratio[i] ** 2:.2g}x the others'{per}), beyond "
                              f"{ROTOR_SPEED_SPREAD:g}x "
                              "either way, which no vehicle flies level with, and at no "
                              "whole pulse-count factor: check that rotor's speed sensor "
                              "and its scale, or leave the rotor_* columns out to judge on "
                              "the commands (cmd_*)")
        scale[i] = factor
        turns = (f"counting one turn in every {n}" if r < 1.0 else
                 f"counting {n} pulses per turn")
        per = "" if per_command is None else f", its speed per command {r:.3g}x theirs"
        short.append(f"rotor_{i + 1}{SPEED_CORRECTION} {factor:.4g} (logged at "
                     f"{r:.3g}x the other rotors' speed{' per command' if per else ''}: a "
                     f"speed sensor {turns}?)")
        said.append(f"rotor_{i + 1} read x {factor:.4g} (its speed {ratio[i]:.3g}x the "
                    f"other rotors' median over the flight, {level[i]:.4g} against "
                    f"{others[i]:.4g} rad/s{per}: a speed sensor {turns}?)")
    parts = ([f"{'; '.join(said)}: a rotor beyond {ROTOR_SPEED_SPREAD:g}x the others' speed "
              f"holds no vehicle level, and {'this lies' if len(said) == 1 else 'these lie'} "
              f"within {PULSE_TOLERANCE:.0%} of a whole pulse-count factor"] if said else [])
    note = f"{_where(log)}: rotor_*: " + "; ".join(parts + kept)
    if not said:
        return log, note
    return dataclasses.replace(log, rotor_speed=speeds * scale,
                               corrections=log.corrections + tuple(short)), note


def _speed_per_command(log, turning: np.ndarray) -> np.ndarray | None:
    """(R,) each rotor's median speed per command over the ``turning`` samples where its
    command is above 5 % of full, over the other rotors' median (None without commands,
    or where a rotor has fewer than 2 such samples)."""
    command = log.rotor_command
    if command is None or command.shape != log.rotor_speed.shape:
        return None
    out = np.empty(command.shape[1])
    for i in range(command.shape[1]):
        use = turning & np.isfinite(command[:, i]) & (command[:, i] > 0.05)
        if np.count_nonzero(use) < 2:
            return None
        out[i] = np.median(np.abs(log.rotor_speed[use, i]) / command[use, i])
    others = _others_median(out)
    return out / others if np.all(others > 0) else None


def _others_median(values: np.ndarray) -> np.ndarray:
    """(R,) the median of the other entries of ``values`` (R,) at each entry: one wrong
    rotor never moves its own yardstick."""
    return np.array([np.median(np.delete(values, i)) for i in range(len(values))])


def check_rotors(log, params) -> None:
    """Rotor speeds against the weight: b sum(Omega^2) vs m g (see module)."""
    if log.rotor_speed is None or params is None or log.rotor_speed.shape[1] == 0:
        return
    thrust = params.thrust_factor * np.sum(np.square(log.rotor_speed), axis=1)
    if log.accel is not None:
        need = params.mass * log.accel[:, 2]
    else:
        need = np.full(len(log.t), params.weight)
    mean_need = float(np.mean(need))
    if mean_need <= 0:
        return
    ratio = float(np.mean(thrust)) / mean_need
    if not THRUST_RANGE[0] <= ratio <= THRUST_RANGE[1]:
        hint = _thrust_hint(log, params, ratio)
        raise field_error(_where(log), "rotor_*",
                          f"b sum(Omega^2) = {float(np.mean(thrust)):.4g} N on average is "
                          f"{ratio:.3g} x the thrust the vehicle needed ({mean_need:.4g} N, "
                          f"mass {params.mass:.4g} kg of {params.path or params.name}): {hint}")


#: a unit slip is named when undoing it puts b sum(Omega^2) within this factor of the thrust
#: needed (the set's own b is right for its vehicle up to ~20 %); a PX4 Iris log against
#: crazyflie21 undone as "Hz" still needs 1.5x: another vehicle, not a unit.
UNIT_RATIO = 1.3


def _thrust_hint(log, params, ratio: float) -> str:
    """What a thrust ratio far from 1 most likely means: a unit (RPM or Hz as rad/s) or a
    log of another vehicle, told by the log's own speeds against the set's ``max_speed``:
    a unit error moves every speed by the same factor (x 60/2 pi, x 1/2 pi), another
    vehicle's speeds lie elsewhere and need another b."""
    peak = float(np.nanpercentile(log.rotor_speed, 99))
    top = getattr(params, "max_speed", None)
    other = (f"a log of another vehicle than {params.path or params.name}? (its rotors "
             f"reach {peak:.4g} rad/s" + (f", the set's max_speed is {top:.4g} rad/s" if top
                                          else "") + "; identify --logs makes its own set)")
    for factor, unit in ((2 * np.pi / 60, "RPM"), (2 * np.pi, "Hz")):
        if top and abs(np.log(peak * factor / top)) < np.log(2.0) and \
                abs(np.log(ratio * factor ** 2)) < np.log(UNIT_RATIO):
            return (f"{unit} logged as rad/s? (x {factor:.4g} puts the speeds at "
                    f"{peak * factor:.4g} rad/s, within the set's max_speed {top:.4g} rad/s)")
    if 40 < ratio < 150 and not top:
        return "RPM logged as rad/s? or " + other
    if 0.015 < ratio < 0.04 and not top:
        return "Hz logged as rad/s? or " + other
    return other


def _window_demean(x: np.ndarray, window: np.ndarray, count: int) -> np.ndarray:
    """``x`` (N, ...) minus its mean over each window (``window`` (N,) the window index)."""
    sums = np.zeros((count, *x.shape[1:]))
    np.add.at(sums, window, x)
    size = np.bincount(window, minlength=count).reshape((count,) + (1,) * (x.ndim - 1))
    return x - (sums / size)[window]


def _gyro_noise(body_rate: np.ndarray) -> np.ndarray:
    """White-noise standard deviation (3,) rad/s of each gyro axis from second differences
    (robust: 1.4826 x median absolute deviation; white noise gives var(d2) = 6 sigma^2 while
    smooth motion adds little at the logging rate)."""
    d2 = np.diff(body_rate, n=2, axis=0)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    return 1.4826 * mad / np.sqrt(6.0)


@dataclasses.dataclass(frozen=True)
class _TorqueBalance:
    """The roll/pitch/yaw momentum balance of one log as Gram matrices of the per-sample
    columns Z = [h (3), S (R), t (1)], window means removed: h = I w + int w x I w dt (N m s),
    S_j = int Omega_j^2 dt (rad^2/s), t (s). ``gram`` = Z^T Z, ``lag`` = the symmetrised
    Z[:-1]^T Z[1:] (sample to next sample); every order is scored from these in O(R^2)."""

    gram: np.ndarray
    lag: np.ndarray
    rotors: int
    dof: int               # samples - windows - 2 fitted
    noise: np.ndarray      # (3,) N m s: I_aa x the gyro's white noise
    #: (R,) per-sample variance (rad^4) of each column's integral that its sensor's white
    #: noise makes, None for commands (:func:`_regressor_noise`)
    column_noise: np.ndarray | None = None
    samples: int = 0
    #: :func:`_order_fit`'s results kept per (torque rows, column order): the best order
    #: (:func:`_best_rss`) and the evidence of each (:func:`rotor_order_evidence`) read the
    #: same fits
    fits: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)


def _saturated(log, params) -> np.ndarray:
    """(N,) whether any rotor of ``log`` is saturated at a sample (:data:`ORDER_SATURATED`:
    its command at the full-command cap, or its logged speed at the set's max_speed)."""
    out = np.zeros(len(log.t), bool)
    if log.rotor_command is not None:
        out |= np.any(log.rotor_command >= ORDER_SATURATED, axis=1)
    top = float(getattr(params, "max_speed", 0.0) or 0.0)
    if log.rotor_speed is not None and top > 0:
        out |= np.any(log.rotor_speed >= ORDER_SATURATED * top, axis=1)
    return out


@dataclasses.dataclass(frozen=True)
class _BalanceFrame:
    """What a log's torque balance (:func:`_torque_balance`) reads of the log alone, the same
    whichever rotor signal stands for its speeds: ``m`` samples per window, ``keep`` (N,)
    the samples kept, ``window`` (kept,) each kept sample's window index (0 .. ``count`` -
    1), ``momentum`` (N, 3) N m s, h = I w + int w x I w dt, and ``noise`` (3,) N m s, I_aa
    times the gyro's white noise (:func:`_gyro_noise`)."""

    m: int
    keep: np.ndarray
    window: np.ndarray
    count: int
    momentum: np.ndarray
    noise: np.ndarray


def _balance_frame(log, params) -> _BalanceFrame | None:
    """:class:`_BalanceFrame` of ``log``; None where fewer than 5 windows remain. Saturated
    samples (:func:`_saturated`) are left out: a window is cut at each of them, so that the
    integrals' error across one stays out of the window means of the samples kept."""
    t = log.t
    m = max(1, round(ORDER_WINDOW_S / float(np.median(np.diff(t)))))
    cut = _saturated(log, params)
    keep = ~cut
    # a new window every m samples and after every saturated stretch
    start = (np.arange(len(t)) % m == 0) | np.concatenate([[True], cut[:-1]])
    window = np.cumsum(start) - 1
    size = np.bincount(window[keep], minlength=int(window[-1]) + 1)
    keep &= size[window] >= 3            # a window of under 3 samples says nothing
    _, window = np.unique(window[keep], return_inverse=True)
    count = int(window.max()) + 1 if window.size else 0
    if count < 5:
        return None
    inertia = np.asarray(params.inertia, dtype=float)
    momentum = log.body_rate @ inertia.T
    momentum = momentum + cumulative_trapezoid(np.cross(log.body_rate, momentum), t,
                                             axis=0, initial=0)
    return _BalanceFrame(m, keep, window, count, momentum,
                         np.diag(inertia) * _gyro_noise(log.body_rate))


def _torque_balance(log, params, speeds: np.ndarray | None = None, *,
                    sensor: bool = False, frame: _BalanceFrame | None = None
                    ) -> _TorqueBalance | None:
    """The balance of ``log`` with ``speeds`` (N, R) rad/s standing for the rotor speeds
    (default the log's), on the log's :class:`_BalanceFrame` ``frame`` (default
    :func:`_balance_frame`: None, and so no balance, where it has under 5 windows).
    ``sensor``: ``speeds`` are a sensor's (their white noise is estimated,
    :func:`_regressor_noise`)."""
    speeds = log.rotor_speed if speeds is None else speeds
    frame = _balance_frame(log, params) if frame is None else frame
    if frame is None:
        return None
    t, keep = log.t, frame.keep
    squares = cumulative_trapezoid(np.square(speeds), t, axis=0, initial=0)
    z = _window_demean(np.hstack([frame.momentum, squares, (t - t[0])[:, None]])[keep],
                       frame.window, frame.count)
    lag = z[:-1].T @ z[1:]
    return _TorqueBalance(z.T @ z, 0.5 * (lag + lag.T), squares.shape[1],
                          int(keep.sum()) - frame.count - 2, frame.noise,
                          _regressor_noise(speeds, t, frame.m) if sensor else None,
                          int(keep.sum()))


def _regressor_noise(speeds: np.ndarray, t: np.ndarray, m: int) -> np.ndarray:
    """(R,) the variance per sample that a speed sensor's white noise sigma_j (from second
    differences, as the gyro's: :func:`_gyro_noise`) puts in column j of the balance: the
    squared speed's noise 2 Omega_j sigma_j, integrated over a window of m samples of dt and
    its mean removed, a random walk of variance (2 Omega_j sigma_j dt)^2 m / 6 on average."""
    dt = float(np.median(np.diff(t)))
    sigma = _gyro_noise(speeds)
    return (2.0 * np.mean(np.abs(speeds), axis=0) * sigma * dt) ** 2 * m / 6.0


#: an axis of the balance tells two column orders apart only where the rotor-speed sensor's
#: noise makes under this share of the variance of either order's torque column: noise as large as
#: the signal halves the fitted gain (errors in variables), and the orders then differ by how
#: that noise meets another torque the flight shares. Generated flights with 10 rad/s of
#: speed noise lie above, the real Crazyflie flights far below (CHANGELOG.md, issue 47 item 7)
ORDER_NOISE_SHARE = 0.5


def _noise_share(balance: _TorqueBalance, torque_rows: np.ndarray, columns) -> np.ndarray:
    """(3,) the share of the variance of the torque column per axis, rotor i from column
    ``columns[i]``, that the sensor's noise makes (0 for a signal without one)."""
    if balance.column_noise is None or balance.samples <= 0:
        return np.zeros(3)
    r = balance.rotors
    g = balance.gram[3:3 + r, 3:3 + r]
    out = np.zeros(3)
    for a in range(3):
        mix = np.zeros(r)
        mix[list(columns)] = torque_rows[a]
        total = float(mix @ g @ mix) / balance.samples
        out[a] = float(mix ** 2 @ balance.column_noise) / total if total > 0 else 1.0
    return out


def _order_fit(balance: _TorqueBalance, torque_rows: np.ndarray,
               columns) -> tuple[np.ndarray, np.ndarray]:
    """(RSS (3,), lag-1 autocorrelation of the residual (3,)) of the momentum per axis
    against the mixer's torque integral of the rotor columns in order ``columns`` (rotor i
    from column ``columns[i]``): gain and a constant torque fitted per axis (a wrong b or d
    is a gain, a CoM offset a constant torque); a gain <= 0 explains nothing (the constant
    torque alone)."""
    key = (torque_rows.tobytes(), tuple(columns))
    if key not in balance.fits:
        balance.fits[key] = _fit_order(balance, torque_rows, columns)
    return balance.fits[key]


def _fit_order(balance: _TorqueBalance, torque_rows: np.ndarray,
               columns) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_order_fit`, computed."""
    r = balance.rotors
    rss, rho = np.zeros(3), np.zeros(3)
    s, t = slice(3, 3 + r), 3 + r
    g = balance.gram
    for a in range(3):
        mix = np.zeros(r)
        mix[list(columns)] = torque_rows[a]            # predicted_a = S @ mix
        design = np.array([[mix @ g[s, s] @ mix, mix @ g[s, t]], [mix @ g[s, t], g[t, t]]])
        target = np.array([mix @ g[s, a], g[t, a]])
        beta = np.linalg.lstsq(design, target, rcond=None)[0]
        if beta[0] <= 0:
            beta = np.array([0.0, g[t, a] / g[t, t] if g[t, t] > 0 else 0.0])
        w = np.zeros(len(g))
        w[a], w[s], w[t] = 1.0, -beta[0] * mix, -beta[1]
        rss[a] = max(float(w @ g @ w), 0.0)
        rho[a] = float(w @ balance.lag @ w) / rss[a] if rss[a] > 0 else 0.0
    return rss, rho


def _order_evidence(balance: _TorqueBalance, own: np.ndarray, rss: np.ndarray,
                    rho: np.ndarray, told: np.ndarray | None = None) -> float:
    """Delta chi^2 of an order over the log's own (see :func:`check_rotor_order`); ``told``
    (3,) bool: the axes that can tell an order (:data:`ORDER_NOISE_SHARE`; default all)."""
    scale = np.maximum(balance.noise ** 2, np.minimum(own, rss) / max(balance.dof, 1))
    effective = np.clip((1.0 - rho) / (1.0 + rho), 1e-3, 1.0)
    per_axis = effective * (own - rss) / scale
    if told is not None:
        per_axis = np.where(told, per_axis, 0.0)
    # worse on an axis it moves: a model error, not an order (see check_rotor_order)
    if per_axis.min() < -(DOUBT_CHI2 if balance.column_noise is None else ORDER_CHI2):
        return float(per_axis.min())
    return float(np.sum(per_axis))


def _order_sources(log, params, commands: bool, lag_s: float = 0.0
                   ) -> list[tuple[str, np.ndarray]]:
    """(name, (N, R) rad/s) of the rotor signals that can stand for the rotor speeds in the
    torque balance: the logged speeds, and the commands where ``commands`` or where the
    speeds are logged too (:func:`_command_speeds`), read through a first-order lag of
    ``lag_s`` (s; :func:`quadsim.core.lag.first_order_lag` on the log's median step; 0: as
    logged)."""
    out = []
    if log.rotor_speed is not None:
        out.append(("rotor speeds", log.rotor_speed))
    if log.rotor_command is not None and params is not None and (commands or out):
        speeds = _command_speeds(log.rotor_command, params)
        if lag_s > 0 and len(log.t) > 1:
            speeds = first_order_lag(speeds, lag_s, float(np.median(np.diff(log.t))))
        out.append(("commands", speeds))
    return out


#: the motor lags (s) the commands are read through where a log's order would otherwise be
#: doubted on them (:func:`commands_lag`): 0 and 5 ms to 120 ms, the first-order time
#: constants of small brushless and brushed rotors (the crazyflie21 set's identified 50 ms,
#: a 0.8 kg X quad's 20-40 ms), with the set's own (``motor_map.time_constant``) added
LAG_GRID_S = (0.0, 0.005, 0.01, 0.02, 0.03, 0.05, 0.08, 0.12)


def commands_lag(log, params) -> float:
    """The first-order lag (s) through which ``log``'s commands best stand for the rotor
    speeds in the torque balance: the one of :data:`LAG_GRID_S` (and the set's own time
    constant) whose commands' balance fits the momentum best under its best column order
    (:func:`_best_rss`, summed over the axes at the balance's noise scale); 0 where the log
    has no commands or cannot be judged.

    Why: a command leads the speed it gives by the motor's lag. Read as logged, that lag is a
    model error of the balance, and a rival column order can fit it better (measured:
    CHANGELOG.md, branch orderlag; ``tests/test_order_lag.py``). The lag is the vehicle's,
    not the order's: taken at the best fit over every order, it favours none."""
    return _lagged_commands(log, params)[0]


def _lagged_commands(log, params) -> tuple[float, _TorqueBalance | None]:
    """(:func:`commands_lag`, the commands' :class:`_TorqueBalance` through it; None where
    the log cannot be judged)."""
    from ..vehicle.rotors import allocation_matrix

    if log.rotor_command is None or params is None:
        return 0.0, None
    rows = allocation_matrix(params)[3:6]
    own = getattr(getattr(params, "motor_map", None), "time_constant", None)
    grid = sorted(set(LAG_GRID_S) | ({float(own)} if own and own > 0 else set()))
    frame = _balance_frame(log, params)
    best, out = np.inf, (0.0, None)
    for lag in grid if frame is not None else ():
        speeds = dict(_order_sources(log, params, True, lag)).get("commands")
        if speeds is None or not np.isfinite(speeds).all():
            return 0.0, None
        balance = _torque_balance(log, params, speeds, sensor=False, frame=frame)
        if balance is None:
            return 0.0, None
        misfit = float(np.sum(_best_rss(balance, rows) / np.maximum(balance.noise ** 2,
                                                                     1e-300)))
        if misfit < best:
            best, out = misfit, (lag, balance)
    return out


def _command_speeds(command: np.ndarray, params) -> np.ndarray:
    """(N, R) rad/s the commands (N, R) (normalised 0-1, clipped at 0) stand for in the
    torque balance: the set's motor map rotor by rotor where it has one of the log's rotor
    count (``MotorMap.speed_of``, at its reference voltage: a voltage scales every rotor
    alike, which the per-axis gain takes), else the command times the set's max_speed (the
    per-axis gain is fitted anyway, so only the shape of Omega(u) matters). Its rotors'
    differences matter: read at ``max_speed`` alone, a crazyflie21 flight generated with the
    map's commands (offsets 57-127 rad/s, gains 3481-3632 rad/s per unit) fitted rotors
    1<->2 and/or 3<->4 swapped better by Delta chi^2 43-136 (CHANGELOG.md, quadsim.fly's
    commands)."""
    command = np.clip(command, 0.0, None)
    mm = params.motor_map
    if mm is None or mm.speed.shape[0] != command.shape[1]:
        return command * float(params.max_speed)
    return mm.speed_of(mm.to_unit(command))


def _best_rss(balance: _TorqueBalance, torque_rows: np.ndarray) -> np.ndarray:
    """(3,) the balance's best residual per axis over every column order (N m s)^2."""
    import itertools

    orders = list(itertools.permutations(range(balance.rotors)))
    _fit_orders(balance, torque_rows, orders)
    return np.min([_order_fit(balance, torque_rows, perm)[0] for perm in orders], axis=0)


def _fit_orders(balance: _TorqueBalance, torque_rows: np.ndarray, orders: list) -> None:
    """:func:`_fit_order` of every column order in ``orders`` at once (arrays over the
    orders and the three axes), kept in ``balance.fits``: the same fits to round-off (the
    2 x 2 least squares by a pseudo-inverse of the same cut-off as ``lstsq``'s) at a
    fraction of the per-order loop's cost (issue 43 item 7; tests/test_order_batch.py)."""
    todo = [o for o in orders if (torque_rows.tobytes(), tuple(o)) not in balance.fits]
    if not todo:
        return
    r, g = balance.rotors, balance.gram
    s, t = slice(3, 3 + r), 3 + r
    mix = np.zeros((len(todo), 3, r))
    for k, columns in enumerate(todo):
        mix[k][:, list(columns)] = torque_rows             # mix[k, a]: axis a's row, reordered
    a11 = np.einsum("kai,ij,kaj->ka", mix, g[s, s], mix)
    a12 = mix @ g[s, t]
    design = np.empty(mix.shape[:2] + (2, 2))
    design[..., 0, 0], design[..., 0, 1], design[..., 1, 0] = a11, a12, a12
    design[..., 1, 1] = g[t, t]
    target = np.stack([np.einsum("kai,ia->ka", mix, g[s, :3]),
                       np.broadcast_to(g[t, :3], a11.shape)], axis=-1)
    beta = np.einsum("kaij,kaj->kai", np.linalg.pinv(design, rcond=2 * np.finfo(float).eps),
                     target)
    flat = beta[..., 0] <= 0                               # a gain <= 0 explains nothing
    beta[..., 0] = np.where(flat, 0.0, beta[..., 0])
    beta[..., 1] = np.where(flat, g[t, :3] / g[t, t] if g[t, t] > 0 else 0.0, beta[..., 1])
    w = np.zeros(mix.shape[:2] + (len(g),))
    w[:, np.arange(3), np.arange(3)] = 1.0
    w[..., s] = -beta[..., :1] * mix
    w[..., t] = -beta[..., 1]
    rss = np.maximum(np.einsum("kai,ij,kaj->ka", w, g, w), 0.0)
    lagged = np.einsum("kai,ij,kaj->ka", w, balance.lag, w)
    rho = np.divide(lagged, rss, out=np.zeros_like(rss), where=rss > 0)
    for k, columns in enumerate(todo):
        balance.fits[(torque_rows.tobytes(), tuple(columns))] = (rss[k], rho[k])


def rotor_order_source(log, params, *, commands: bool = False) -> str:
    """The rotor signals the order test reads (:func:`rotor_order_evidence`): "rotor
    speeds", "commands", "rotor speeds and commands" or "" (none judged)."""
    return _read_order(log, params, commands)[0]


def _order_choice(log, params, commands: bool) -> list:
    """[(source name, its :class:`_TorqueBalance`)] that :func:`rotor_order_evidence`
    reads; [] when the log cannot be judged."""
    if (params is None or log.body_rate is None or len(log.t) < 50
            or params.rotor_count > 6 or not np.isfinite(log.body_rate).all()):
        return []
    from ..vehicle.rotors import allocation_matrix

    torque_rows = allocation_matrix(params)[3:6]
    judged = []
    sources = [(name, speeds) for name, speeds in _order_sources(log, params, commands)
               if speeds.shape[1] == params.rotor_count and np.isfinite(speeds).all()]
    # the log's own part of every balance, read once
    frame = _balance_frame(log, params) if sources else None
    for name, speeds in sources if frame is not None else ():
        balance = _torque_balance(log, params, speeds, sensor=name == "rotor speeds",
                                  frame=frame)
        if balance is not None:
            judged.append((name, balance, _best_rss(balance, torque_rows)))
    if len(judged) < 2:
        return [(name, balance) for name, balance, _ in judged]
    best = min(judged, key=lambda j: float(np.sum(j[2] / np.maximum(j[1].noise ** 2,
                                                                   1e-300))))
    kept = []
    for name, balance, rss in judged:      # measured at the better fit's own misfit scale
        scale = np.maximum(balance.noise ** 2, best[2] / max(balance.dof, 1))
        if float(np.sum((rss - best[2]) / scale)) <= ORDER_CHI2:
            kept.append((name, balance))
    return kept


def rotor_order_evidence(log, params, *, commands: bool = False
                         ) -> dict[tuple[int, ...], float]:
    """Delta chi^2 of every other order of the rotor columns over the log's own (permutation
    -> value; see :func:`check_rotor_order`); {} when the log cannot be judged (no gyro or
    rotor speeds, another rotor count, under 50 samples or 5 windows, more than 6 rotors).
    ``commands``: without rotor speeds, the motor commands stand for them (a nonlinear map
    or the motor lag weakens the evidence).

    Where both speeds and commands are logged, each is read, and a rival order's evidence is
    the larger of the two (the columns must be in the log's order in every signal), except a
    signal whose best column order fits the momentum worse than the other's by more than
    ``ORDER_CHI2`` (per axis at the better fit's scale, as the orders are compared): both
    sides of the balance are the same momentum, so the residuals compare directly, and the
    signal that explains less carries noise of its own that the other does not (a
    rotor-speed sensor's noise, integrated, is noise in the regressor), so its orders' small
    differences are that noise meeting whatever other torque the flight shares (a wind's:
    measured in CHANGELOG.md, issue 47 item 7)."""
    return _read_order(log, params, commands)[1]


def order_reading(log, params, *, commands: bool = False) -> tuple[str, dict]:
    """(:func:`rotor_order_source`, :func:`rotor_order_evidence`) of ``log``, the signals
    chosen once (the same numbers as the two calls)."""
    return _read_order(log, params, commands)[:2]


def _read_order(log, params, commands: bool) -> tuple[str, dict, float | None]:
    """(:func:`rotor_order_source`, :func:`rotor_order_evidence`,
    :func:`spin_reversal_evidence`) of ``log``, the signals chosen and their torque balances
    computed once (the same numbers as the three calls).

    Where the commands are among the signals read and would doubt the log's order or its
    spins (a rival's Delta chi^2 above :data:`DOUBT_CHI2`), their balance is read again
    through the motor lag under which they fit best (:func:`commands_lag`) and those numbers
    stand; the signals read stay those chosen as logged, so that the logged speeds' own
    order is still tested wherever they are read (speed columns in another order than the
    commands': ``scripts/consistency_evidence.py``)."""
    choice = _order_choice(log, params, commands)
    evidence, spins = _evidence_of(choice, params), _spins_of(choice, params)
    doubt = max(list(evidence.values()) + [spins if spins is not None else -np.inf],
                default=-np.inf) > DOUBT_CHI2
    if doubt and any(name == "commands" for name, _ in choice):
        lag, lagged = _lagged_commands(log, params)
        if lag > 0 and lagged is not None:
            choice = [(name, lagged if name == "commands" else balance)
                      for name, balance in choice]
            evidence, spins = _evidence_of(choice, params), _spins_of(choice, params)
    return " and ".join(name for name, _ in choice), evidence, spins


def _evidence_of(choice: list, params) -> dict[tuple[int, ...], float]:
    """:func:`rotor_order_evidence` of the signals ``choice`` (:func:`_order_choice`)."""
    import itertools

    from ..vehicle.rotors import allocation_matrix

    torque_rows = allocation_matrix(params)[3:6] if params is not None else None
    own_order = tuple(range(params.rotor_count)) if params is not None else ()
    evidence: dict = {}
    for _, balance in choice:
        for perm in itertools.permutations(own_order):
            if perm != own_order:    # every signal read must fit the log's order
                value = _against_own(balance, torque_rows, torque_rows, perm)
                evidence[perm] = max(evidence.get(perm, -np.inf), value)
    return evidence


def _against_own(balance: _TorqueBalance, rows: np.ndarray, other_rows: np.ndarray,
                 columns) -> float:
    """Delta chi^2 (:func:`_order_evidence`) of the mixer's torque rows ``other_rows`` with
    the rotor columns in order ``columns`` over the set's ``rows`` in the log's order; an
    axis tells the two apart where either one's column is above the sensor noise
    (:data:`ORDER_NOISE_SHARE`)."""
    own_order = tuple(range(balance.rotors))
    own, _ = _order_fit(balance, rows, own_order)
    told = np.minimum(_noise_share(balance, rows, own_order),
                      _noise_share(balance, other_rows, columns)) < ORDER_NOISE_SHARE
    return _order_evidence(balance, own, *_order_fit(balance, other_rows, columns), told)


def spin_reversal_evidence(log, params, *, commands: bool = False) -> float | None:
    """Delta chi^2 of every rotor's spin reversed over the parameter set's spins, the columns
    in the log's order (:func:`check_rotor_order`'s rule on the yaw torque row of the mixer
    negated; roll and pitch are the same under both): the yaw balance of a set whose ``spin``
    entries are all the wrong way round fits far better reversed. A column order cannot
    stand for it: on an X quadrotor the order that flips every spin (2,3,4,1) also turns the
    roll and pitch rows by 90 deg, and its evidence, near the reversal's on a flight that
    rolls and pitches little, would name a --rotor-map that breaks roll and pitch. The
    largest over the signals read (:func:`_order_choice`, ``commands`` as there); None where
    the log cannot be judged. Where it is above :data:`ORDER_CHI2` (refused) or
    :data:`DOUBT_CHI2` (doubtful) and no order beats it by more than :data:`DOUBT_CHI2`,
    :func:`check_rotor_order` and :func:`rotor_order_status` name the spins, not an order:
    on a flight that rolls and pitches little the two fit alike, and an order would break
    roll and pitch if it is the spins; on one that does, every order is far worse on roll or
    pitch (a model error by the order rule) while the reversal still fits the yaw. With a
    set's right spins it is negative (docs/flightlog.md, "rotor spins")."""
    return _read_order(log, params, commands)[2]


def _spins_of(choice: list, params) -> float | None:
    """:func:`spin_reversal_evidence` of the signals ``choice`` (:func:`_order_choice`)."""
    if not choice:
        return None
    from ..vehicle.rotors import allocation_matrix

    rows = allocation_matrix(params)[3:6]
    flipped = rows.copy()
    flipped[2] = -flipped[2]
    own_order = tuple(range(params.rotor_count))
    return float(max(_against_own(balance, rows, flipped, own_order) for _, balance in choice))


def _spin_words(value: float, params) -> str:
    """The refusal's or note's words for spins that fit reversed (Delta chi^2 ``value``)."""
    return (f"the yaw torque balance fits better with every rotor's spin reversed "
            f"(Delta chi^2 {value:.3g}) than with the spins of {params.path or params.name}: "
            "is each [[rotor]]'s spin (cw/ccw seen from above) the wrong way round?")


@dataclasses.dataclass(frozen=True)
class RotorOrder:
    """Whether a log's torque balance tells its rotor order. ``confirmed``: every other order
    fits worse by more than ``ORDER_CHI2`` (Delta chi^2 below -ORDER_CHI2); ``doubtful``:
    another order fits better by more than ``DOUBT_CHI2`` (a wrong order is likely: every
    verdict on the log tentative; refused above ORDER_CHI2); ``rival``: the
    best other order (column permutation) and ``evidence`` its Delta chi^2 over the log's
    own (None, nan when not judged); ``source``: "rotor speeds", "commands" or "" (not
    judged); ``note``: one line for the answer when the order is not confirmed."""

    confirmed: bool
    doubtful: bool
    rival: tuple[int, ...] | None
    evidence: float
    source: str
    note: str


def rotor_order_status(log, params, *, readings: list | None = None) -> RotorOrder:
    """The log's rotor order as the torque balance sees it (rotor speeds, else commands):
    confirmed, or not told apart from its best rival -- then a wrong order cannot be ruled
    out, and a verdict on the log must say so (issue 44: never stated at > 99 %). A log of
    several airborne stretches (segments): each stretch's Delta chi^2 summed (independent
    samples; the balance's integrals never run across a ground span). ``readings``: each
    stretch's (source, evidence, spin-reversal evidence) with ``commands``
    (:func:`order_reading` and :func:`spin_reversal_evidence` from one set of torque
    balances) where already read (:func:`check_log` with ``orders``), in the order of
    :meth:`~quadsim.logs.flightlog.FlightLog.parts`."""
    evidence: dict = {}
    sources = []
    if readings is not None and any(len(r) == 2 for r in readings):   # before the spins
        warnings.warn("rotor_order_status(readings=) takes (source, evidence, spins) per "
                      "stretch; the (source, evidence) pairs given are read again from the "
                      "log (CHANGELOG.md)", QuadsimWarning, stacklevel=2)
        readings = None
    if readings is None:
        readings = [_read_order(part, params, commands=True) for part in log.parts()]
    for source, part_evidence, _ in readings:
        sources.append(source)
        for perm, value in part_evidence.items():
            evidence[perm] = evidence.get(perm, 0.0) + value
    source = " and ".join(dict.fromkeys(s for s in sources if s)) or (
        "rotor speeds" if log.rotor_speed is not None else "commands")
    where = _where(log)
    if not evidence:
        return RotorOrder(False, False, None, float("nan"), "",
                          f"{where}: rotor_*: rotor order not checked (no gyro, rotor data or "
                          "samples enough for the torque balance): a wrong order cannot be "
                          "ruled out")
    rival = max(evidence, key=evidence.get)
    value = float(evidence[rival])
    # every spin reversed fitting better than the set's (and as well as any column order):
    # the spins are named, not an order (spin_reversal_evidence)
    spins = sum(v for _, _, v in readings if v is not None)
    if spins > DOUBT_CHI2 and spins >= value - DOUBT_CHI2:
        return RotorOrder(False, True, rival, value, source,
                          f"{where}: rotor_*: rotor spins not confirmed by the torque "
                          f"balance of the {source}: {_spin_words(spins, params)}")
    if value < -ORDER_CHI2:
        return RotorOrder(True, False, rival, value, source, "")
    mapping = ",".join(str(m + 1) for m in rival)
    doubtful = value > DOUBT_CHI2
    how = (f"fits better (Delta chi^2 {value:+.3g} over the log's own, above {DOUBT_CHI2:g}): "
           "the rotor columns are likely in another order" if doubtful else
           f"fits about as well (Delta chi^2 {value:+.3g}, not below -{ORDER_CHI2:g}): a wrong "
           "rotor order cannot be ruled out on this log")
    return RotorOrder(False, doubtful, rival, value, source,
                      f"{where}: rotor_*: rotor order not confirmed by the torque balance of "
                      f"the {source}: the order --rotor-map {mapping} {how}")


def check_rotor_order(log, params, *, reading: tuple | None = None,
                      evidence: dict | None = None) -> None:
    """Rotor columns in the parameter set's order, by the torque balance under every
    permutation of the rotor columns.

    Per sample and body axis a, the angular momentum ``h_a = (I w)_a + int (w x I w)_a dt``
    must follow the mixer's torque integral ``int (A_torque Omega^2)_a dt`` of the rotor
    columns (``A_torque``: rows 3-5 of :func:`quadsim.vehicle.rotors.allocation_matrix`),
    with a gain and a constant torque fitted per axis; both sides have their mean removed
    over ``ORDER_WINDOW_S`` windows, so that model errors do not accumulate. Every sample
    counts (a window's end points alone carry ~6/m of the information of its m samples).

    Decision rule: for each permutation P of the columns, the evidence against the log's own
    order is ``Delta chi^2 = sum_a n_a (RSS_own,a - RSS_P,a) / s_a^2``, where ``s_a`` is the
    noise scale of axis a -- the larger of the gyro's white noise times I_aa (from second
    differences, :func:`_gyro_noise`) and the residual scale RSS/dof of the better of the
    two orders -- and ``n_a = (1 - rho)/(1 + rho)`` discounts residuals correlated from sample
    to sample (lag-1 autocorrelation rho of P's residual: a filtered gyro or an unmodelled
    effect; AR(1) effective sample size). A wrong column order is wrong on every axis it
    moves, so a permutation that fits one axis better but another far worse (that axis'
    Delta chi^2 below -``ORDER_CHI2``; below -``DOUBT_CHI2``, two sigma, where the commands
    stand for the speeds: the set's map, the motors' lag and every moment the mixer lacks
    are then taken as exact, and their error meets the rival columns on one axis and not
    on another) is a model error, not a column order: its evidence is that axis' (negative)
    value: otherwise a poor torque model passes for a column order (CHANGELOG.md:
    Docstrings as contracts; tests/test_order_model_error.py). The order with the largest
    Delta chi^2 is refused when it exceeds ``ORDER_CHI2`` = 25 (a five-sigma difference), naming the
    ``--rotor-map`` that applies it; a swap on generated flights and the right order on real
    ones lie far either side of it (``python scripts/consistency_evidence.py``;
    CHANGELOG.md: Docstrings as contracts). Each order
    is scored from the Gram matrices of the per-sample columns (:class:`_TorqueBalance`):
    a hexarotor's 720 orders cost little more than a quadrotor's 24.
    ``reading``: the log's (source, evidence, spin-reversal evidence) with ``commands``
    where already read (``_read_order``: :func:`order_reading` and
    :func:`spin_reversal_evidence` from one set of torque balances). Without it, the
    evidence and the spins are read from one set of torque balances too: with rotor speeds
    logged the signals read do not depend on ``commands`` (:func:`_order_sources`), and
    without them the evidence is empty (nothing checked). ``evidence`` (the keyword before
    ``reading``: :func:`rotor_order_evidence` alone) is read with a warning, the spins then
    read from the log."""
    if evidence is not None and reading is None:
        warnings.warn("check_rotor_order(evidence=) is read as reading=(source, evidence, "
                      "spins) with the spins read from the log; pass reading= (CHANGELOG.md)",
                      QuadsimWarning, stacklevel=2)
        reading = (None, evidence, spin_reversal_evidence(log, params, commands=False))
    if reading is None:
        reading = _read_order(log, params, commands=False)
    _, evidence, spins = reading
    if not evidence:
        return
    best = max(evidence, key=evidence.get)
    if spins is not None and spins > ORDER_CHI2 and spins >= evidence[best] - DOUBT_CHI2:
        raise field_error(_where(log), "rotor_*", f"rotor spins: {_spin_words(spins, params)}"
                          f" (above {ORDER_CHI2:g}; the best column order, --rotor-map "
                          f"{','.join(str(m + 1) for m in best)}, {evidence[best]:.3g}: an "
                          "order would move the roll and pitch columns too)")
    if evidence[best] > ORDER_CHI2:
        mapping = ",".join(str(m + 1) for m in best)
        raise field_error(_where(log), "rotor_*", f"rotor order: the torque balance fits "
                          f"far better with rotor i taken from column m_i = {mapping} than in "
                          f"the log's order (Delta chi^2 {evidence[best]:.3g} > {ORDER_CHI2:g} "
                          f"at the noise scale; convert --rotor-map {mapping}); rotors "
                          f"numbered as in {params.path or params.name}?")


def check_vehicle(log, params) -> None:
    """The log is of a multirotor with the parameter set's rotor count (refused otherwise)."""
    if params is None:
        return
    name = params.path or params.name
    if log.vehicle not in (None, "multirotor"):
        raise field_error(_where(log), "vehicle", f"the log's parameters say a {log.vehicle}, "
                          f"not a multirotor; the parameter set {name} is a "
                          f"{params.rotor_count}-rotor multirotor")
    if log.rotor_count and log.rotor_count != params.rotor_count:
        raise field_error(_where(log), "rotor_*/cmd_*", f"{log.rotor_count} rotors in the log, "
                          f"{params.rotor_count} in the parameter set {name}")


def _channel_checks(log, params, readings: list | None = None) -> list[str]:
    """The checks of channels against each other on one airborne stretch; notes.
    ``readings``: a list that receives the stretch's (source, evidence, spin-reversal
    evidence) with ``commands`` (what :func:`rotor_order_status` reads: ``_read_order``),
    or None where that is not what the check reads (no rotor speeds logged: the check reads
    none, the status the commands)."""
    notes = []
    gyro_note = check_gyro(log)
    if gyro_note:
        notes.append(gyro_note)
    if not log.has_pose:
        checked = ("the gyro is checked against the attitude, the accelerometer by its "
                   "magnitude" if log.has_attitude else
                   "the gyro and accelerometer are checked by their magnitudes")
        notes.append(f"{_where(log)}: {log.without_pose_words}; {checked} and the rotor "
                     "order by the torque balance only")
    check_accel(log, params.gravity if params is not None else 9.81)
    check_rotors(log, params)
    if readings is None:
        check_rotor_order(log, params)
        return notes
    # with rotor speeds logged the check and the status read the same signals (speeds, and
    # commands beside them: _order_sources), so one reading serves both
    reading = _read_order(log, params, commands=True) if log.rotor_speed is not None else None
    check_rotor_order(log, params, reading=reading)
    readings.append(reading)
    return notes


def check_log(log, params=None, *, joined: bool = False, orders: list | None = None,
              slow=None):
    """All checks on one log; returns (log with NaN runs and ground/idle spans cut, notes).
    The longest airborne stretch is kept (:func:`check_log_stretches` keeps every one as its
    own log); ``joined``: every airborne stretch kept as a segment of the one log
    (:func:`quadsim.logs.spans.join_airborne`; ``gap`` and ``view``), the channels checked
    on each stretch alone. ``orders``: a list that receives the cut log's
    :func:`rotor_order_status` read from the rotor-order check's own torque balances (the
    same status), or None where the check did not read what the status reads (a log
    without rotor speeds). ``slow``: a function (FlightLog -> FlightLog) applied to the cut
    log before the channels are checked against each other: what to do with a rotor channel
    logged too slowly for them (the diagnosis' :func:`quadsim.gap.logcheck.slow_rotors`);
    the notes it adds to the log are returned with the others."""
    check_vehicle(log, params)
    log, note = cut_nan(log)
    notes = [note] if note else []
    # ground, idle and landing spans (quadsim.logs.spans)
    log, note = join_airborne(log) if joined else cut_ground(log)
    notes += [note] if note else []
    log, note = check_rotor_speeds(log)
    notes += [note] if note else []
    if slow is not None:
        before = len(log.notes)
        log = slow(log)
        notes += list(log.notes[before:])
    readings = None if orders is None or params is None else []
    for part in log.parts():
        notes += [n for n in _channel_checks(part, params, readings) if n not in notes]
    if orders is not None:
        orders.append(None if readings is None or None in readings
                      else rotor_order_status(log, params, readings=readings))
    return log, notes


def check_log_stretches(log, params=None):
    """:func:`check_log` keeping every airborne stretch (:func:`quadsim.logs.spans.
    split_airborne`): (logs, one per stretch in time order, notes). For the stages that
    pool samples (``identify --logs``): several take-offs in one log all count."""
    check_vehicle(log, params)
    log, note = cut_nan(log)
    notes = [note] if note else []
    logs, note = split_airborne(log)
    notes += [note] if note else []
    checked = []
    for part in logs:
        part, note = check_rotor_speeds(part)
        checked.append(part)
        notes += [note] if note and note not in notes else []
    logs = checked
    for part in logs:
        notes += [n for n in _channel_checks(part, params) if n not in notes]
    return logs, notes


def check_logs(logs, params=None, *, orders: list | None = None, slow=None):
    """:func:`check_log` on each, every airborne stretch a segment (``joined``); returns
    (logs, notes). The diagnosis (``gap``) is its caller; a log without a pose is checked
    like the others and diagnosed on the body-frame balance (:mod:`quadsim.gap.logcheck`).
    ``orders``: a list that receives each log's rotor-order status (:func:`check_log`);
    ``slow``: as :func:`check_log`'s."""
    out, notes = [], []
    for log in logs:
        log, n = check_log(log, params, joined=True, orders=orders, slow=slow)
        out.append(log)
        notes.extend(n)
    return out, notes
