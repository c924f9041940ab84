"""Checks of a log before anything is fitted: does the parameter set describe the logged
vehicle; rotor speeds from motor commands alone (a command -> speed model from references that
log both); does the torque balance confirm the log's rotor order; what a log without a pose
(IMU and motors only) can be judged on.

Vehicle check
-------------

Does the parameter set describe the logged vehicle at all? Checked before any fit.

A diagnosis that fits effects to flights of a *different* vehicle finds nonsense with
confidence (CHANGELOG: another vehicle's set named an effect at 99.8 %). Two balances that
hold for any vehicle flying on its own rotors catch it first:

* hover/force balance along body z: ``m f_z = b sum_i Omega_i^2`` (f_z the measured
  specific force) gives the thrust factor the data need, by least squares over all samples;
  its ratio to the model's b must lie in [1/:data:`MAX_RATIO`, :data:`MAX_RATIO`]
  (a payload of 60 % of the mass or a 40 % thrust loss still passes, another vehicle not);
* the logged rotor speeds must be reachable: median speed <= :data:`MAX_SPEED_RATIO` x the
  model's ``max_speed``;
* yaw balance ``I_zz dr/dt ~= d sum_i s_i Omega_i^2`` gives the drag factor the data need
  (reported, not enforced: it is noisy on gentle flights).

:func:`vehicle_check` returns the ratios (for the result's ``checks``) and raises
:class:`~quadsim.core.errors.InputError` with the numbers that disagree.

:func:`check_length` refuses a log shorter than :data:`MIN_LOG_S` = 2 s (the edges cut after
smoothing, the noise window and one scoring block need it) or, with ``window_s``, sampled too
coarsely for the differentiator's window (fewer than 5 samples); :func:`quadsim.gap.prepare`
applies the length check to every log given to the library, the CLI both.

Command-only logs
-----------------

Diagnosis from motor commands alone: a command -> rotor-speed model identified on
reference flights that have both, then rotor speeds synthesised for logs that have only
commands, so that the same gap diagnosis runs on them.

Model (per rotor i; u normalised command 0-1, V battery voltage in V, Omega in rad/s)::

    Omega_ss,i = a_i + b_i u_i + c_i u_i (V - V_ref)          steady state (c_i = 0 without vbat)
    tau dOmega_i/dt = Omega_ss,i - Omega_i                    first-order motor lag, one tau

The voltage term is the first-order effect of a falling battery (a brushed or brushless
motor's no-load speed is proportional to the applied voltage u V); ``V_ref`` is the median
reference voltage. The lag is discretised on the log's median step dt with
``alpha = exp(-dt / tau)`` and the input averaged over the step (no half-sample bias):
``y_k = alpha y_(k-1) + (1 - alpha) (x_k + x_(k-1)) / 2`` (``scipy.signal.lfilter``). Because
the filter is linear, ``a, b, c`` are an ordinary least-squares fit of the filtered features
``[1, u, u (V - V_ref)]`` for each tau; tau is chosen by bounded scalar minimisation of the
pooled squared error (``scipy.optimize.minimize_scalar``, 0.5 ms .. 0.5 s; tau = 0 is tried
too). Samples whose speed, command or voltage is NaN are left out of the fit.

Synthesis (:func:`synthesise_speeds`): the model driven by the log's commands (and vbat;
V_ref where vbat is missing); the synthesised log keeps no commands by default
(``keep_commands=False``) so that the diagnosis does not score a rotor channel that would
compare the model with itself.

Without any log with rotor speeds (a command-only fleet) the model comes from the parameter
set instead (:func:`command_model_from_params`): its ``[motor_map]``, voltage gain and time
constant, as ``python -m quadsim.identify --logs`` writes them from command-only logs (the
command -> thrust map from the accelerometer). ``gap`` synthesises speeds for every
command-only log it is given — positional, ``--holdout`` and ``--reference``
(:func:`synthesise_all`).

What is lost without measured speeds: the rotor channel (measured speed minus the speed the
commands predict) disappears, so effects that act *between* command and speed are fixed to
the reference: ``motor_lag`` cannot be fitted and a change of lag reads as an attitude-
dynamics change (confusable with ``inertia_error``); a rotor that turns slower for the same
command (a weaker motor) is seen only through its thrust, i.e. as
``thrust_mismatch``/``mass_offset`` rather than in the rotor channel. A battery that sags
beyond the references' map is read on the synthesised speeds themselves: ``battery_sag`` as a
rate, its time law scaling them (the states' ``synthesised``,
:func:`quadsim.gap.fitting.upstream_speeds`).

Example::

    >>> from quadsim.gap.logcheck import fit_command_model, synthesise_speeds
    >>> model = fit_command_model(reference_logs)          # logs with rotor_*, cmd_*, vbat
    >>> model.tau, model.rms                               # s, rad/s
    >>> only_cmd = synthesise_speeds(log_without_speeds, model)

Rotor order
-----------

The rotor order behind a verdict: a verdict on a log whose rotor order the torque balance
does not confirm is never stated above ``UNCONFIRMED_MAX_P``, and one whose order is
doubtful is tentative (issue 44).

A log with two rotor columns swapped is read by every explanation as a strange torque
pattern; the evidence then names some effect with high confidence. The checks refuse an
order that another fits far better (:func:`quadsim.logs.checks.check_rotor_order`,
Delta chi^2 > 25), but on real, filtered logs a wrong order is often not that clear: the
status (:func:`quadsim.logs.checks.rotor_order_status`) is *confirmed* (every other order
fits worse by Delta chi^2 > 25), *doubtful* (another order fits better by Delta chi^2 > 4)
or neither (not told apart). Here:

* not confirmed: every probability of the verdict is capped at ``UNCONFIRMED_MAX_P`` = 0.99
  (a wrong order cannot be ruled out at better than the balance's own resolution) and the
  status' note is added;
* doubtful: the verdict, whatever its outcome, is also ``tentative``, with a sentence naming
  the ``--rotor-map`` that fits better.

Example::

    >>> statuses = order_statuses(logs, params)
    >>> verdict = mark(judge(rows, reference, name, cap=probability_cap(statuses)), statuses)

Slow channels
-------------

A rotor speed logged slower than the dynamics it must carry (issue 47). The loaders resample
every channel onto one time base, so a rotor speed logged at 4 Hz (PX4's default
``esc_status`` profile) sits on 500 Hz rows as held or interpolated values; the moment
channels' residual is then the interpolation's error, and any reading that soaks it up
wins. Each channel's native rate is carried with the log (:attr:`quadsim.logs.flightlog.
FlightLog.rates_hz`, :mod:`quadsim.logs.rates`); :func:`slow_rotors` acts on it before any
fit.

Threshold (:func:`needed_rate_hz`): twice the -3 dB frequency of the states' smoothing
(Savitzky-Golay, :data:`quadsim.gap.residual.DEFAULT_WINDOW_S` = 0.1 s, cubic, at the fit's
rate :data:`quadsim.gap.residual.FIT_RATE_HZ` = 100 Hz: 9.9 Hz, so 19.8 Hz): the fit scores
the moments up to that frequency, and a channel sampled below twice it cannot carry them
(Nyquist). A rate is the channel's as logged, no faster than the rows'.

* rotor speeds too slow, commands fast enough: the speeds are synthesised from the commands
  (:func:`fit_slow_map`: the command -> speed model of the module doc, fitted on this log's
  own slow speeds *at the rows where a logged sample shows* (the knots of
  :func:`quadsim.logs.rates.native_rate`), the commands lag-filtered at full rate and read
  at the same rows, so both sides are the same instants; the lag fitted there too: the
  samples are the speed at their instants, so 4 Hz of them time the lag against the full-rate
  commands -- 46-54 ms on the shared Crazyflie flights cut to 4 Hz, whose set says 50 ms; 0.5
  ms on a generated flight, whose commands have none -- where a set's own lag would be wrong
  for a log whose commands are not the set's). The commands are
  then dropped, as for a command-only log (no rotor channel comparing the map with itself),
  ``speeds_synthesised`` is set, and every answer states it as a correction ("rotor speeds
  logged at 4 Hz, too slow for the moments (needs >= 19.8 Hz): speeds synthesised from the
  commands (500 Hz) through a map fitted on them");
* nothing fast enough carries the rotors (the commands slow too, or missing; or commands
  alone and slow): :func:`slow_rotors` alone refuses, with one line naming both rates and
  the need; ``gap`` judges the run in a band instead ("Judged in a band" below).

Judged in a band
----------------

Where a log's rotors are carried only by a slow channel, every log of the run (flights,
hold-outs, references: one band, the slowest log's, :func:`band_of`) is judged below
:data:`BAND_SHARE` = a quarter of that channel's rate: the states' smoothing window is
widened until its -3 dB frequency lies at or below that edge (:func:`band_window_s`: 0.42 s
for 10 Hz). Every wrench channel is compared there alone, both sides smoothed by the one
filter (the model's wrench through the smoothed rotor speeds, the measured one through the
smoothed IMU and attitude). Held channels are drawn through their samples first
(:func:`rejoined`); rotor speeds slower than the commands are synthesised from them as
above, at the band's window (:func:`in_band`). The timing readings are not weighed
(:func:`timing_carried`). Every answer states the band (:meth:`Band.words`). Refused still
(one line): a carrying channel slower than :data:`MIN_BAND_RATE_HZ` = 5 Hz, and a log whose
rows (the motion) are slower than :func:`needed_rate_hz` (no fast side to hold against the
slow one). Why the six channels stay together: every stage (the references' model, the
noise, the evidence, the judge) weighs them together, so the band is applied to all of
them, never to the moments alone.

Logs whose rates are unknown (built in code, ``rates_hz`` empty) are left as they are.

Example::

    >>> log = slow_rotors(load_log("px4_sample.csv.gz"))   # or InputError

Logs without a pose
-------------------

The diagnosis on logs without a pose (IMU and motors only): the body-frame balance alone.

The residual wrench (:mod:`quadsim.gap.residual`) needs no pose: the measured force is the
mass times the accelerometer's specific force and the measured torque comes from the gyro
(``I w_dot + w x I w``), both in the body frame; the model's rotor wrench is body-frame too.
What a pose adds is the effects whose loads read the vehicle's motion in the world: the air
velocity (wind, body and rotor drag, blade flapping, translational lift) and the height
(ground effect). A payload swinging on a cable reads neither: its swing and pull depend on
the effective gravity at its mount, g - a = -R f, which the accelerometer measures, and on
the body's rotation, which the gyro measures; it is integrated in any frame R' = C R
(:func:`posefree_states`: the gyro's own where no attitude is logged).
Each effect declares what it reads (:attr:`quadsim.effects.facts.EffectFacts.needs_pose`);
on a log without a pose those effects are neither shared by the references nor weighed as a
flight's explanation (:func:`needs_pose`), and the answer names them with what would add
them (:func:`missing_words`).

Stand-ins (:func:`posefree_log`): the pose-less log gets position 0, velocity 0 and the
identity attitude, so that the states have the shape every stage expects; no effect weighed
on it reads them (the filter above), and ``FlightStates.pose`` is False. The states' attitude
then becomes the gyro's own frame and ``accel_world`` the accelerometer turned by it
(:func:`posefree_states`), what the cable's swing reads.

With the attitude and no position (the on-board estimate's Euler angles, as most flight
controllers log them; ``FlightLog.has_attitude``): the logged attitude is kept in place of
the identity, and the states' ``accel_world`` is the accelerometer turned to the world by
it, a = R f - g e_z (:func:`posefree_states`; f the specific force at the body origin), the
vehicle's acceleration without differentiating a position. The parts logged
(:func:`logged_parts`) are then the attitude alone: an effect is weighed when every part it
declares is logged (:func:`needs_pose`): the drags, wind and ground effect are not weighed,
a payload swinging on a cable is (as without the attitude; its swing turned by the logged
attitude: :class:`quadsim.gap.fitting.CableSwing`, through
:attr:`quadsim.effects.base.EffectContext.accel_world`), and :func:`missing_words` names
only what is missing.

Example::

    >>> from quadsim.gap.logcheck import missing_words, posefree_log
    >>> log = posefree_log(imu_log)            # FlightLog with stand-in pose
    >>> missing_words()                        # "no velocity, height or attitude logged: ..."
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.signal import freqz, lfilter, savgol_coeffs

from ..core.errors import InputError
from ..core.frames import rotate
from ..effects import EFFECTS
from ..effects.facts import POSE_PARTS, without_pose
from ..logs.checks import SPEED_CORRECTION, RotorOrder, rotor_order_status
from ..logs.common import median_rate
from ..logs.flightlog import FlightLog
from ..logs.rates import native_rate
from ..vehicle.params import VehicleParams
from ..vehicle.rotors import allocation_matrix
from .residual import DEFAULT_WINDOW_S, FIT_RATE_HZ, window_samples

__all__ = ["MAX_RATIO", "MAX_SPEED_RATIO", "MIN_LOG_S", "check_length", "vehicle_check",
           "CommandModel", "MapCommandModel", "command_model_from_params", "fit_command_model",
           "synthesise_all", "synthesise_speeds", "without_speeds", "UNCONFIRMED_MAX_P",
           "cap_decision", "mark", "order_statuses", "probability_cap", "missing_words",
           "needs_pose", "logged_parts", "posefree_log", "posefree_states",
           "synthesised_timing_note", "SYNTHESISED_TIMING_WORDS",
           "confusable", "confusable_note", "SEPARATED",
           "TIMING_WORDS", "fit_slow_map", "needed_rate_hz", "slow_rotors",
           "BAND_SHARE", "MIN_BAND_RATE_HZ", "Band", "band_of", "band_window_s", "carrying_rate",
           "in_band", "rejoined", "timing_carried",
           "smoothing_cutoff_hz"]


#: largest ratio (either way) of the thrust factor the data need to the model's: a payload
#: of 60 % of the mass or a 40 % thrust loss still passes, another vehicle does not
MAX_RATIO = 2.0
#: largest median logged rotor speed over the model's ``max_speed``: a rotor cannot run
#: half again beyond its top speed, a log in other units or of another vehicle does
MAX_SPEED_RATIO = 1.5
#: shortest log the diagnosis can use (s): the 0.2 s edges at both ends, the 0.5 s window
#: of the noise scale and a 1 s scoring block
MIN_LOG_S = 2.0


def check_length(log, window_s: float | None = None, name: str | None = None, *,
                 what: str | None = None) -> None:
    """A log long enough for the diagnosis and, with ``window_s`` (s), sampled finely
    enough for it; raises :class:`InputError` naming the file (``name``, default the log's
    path) and ``t``; ``what``: the window's words (default "--window S s")."""
    name = name or str(log.path)
    duration = float(log.t[-1] - log.t[0]) if len(log.t) else 0.0
    if duration < MIN_LOG_S:
        raise InputError(f"{name}: t: {duration:.3g} s of flight; the diagnosis needs "
                         f"at least {MIN_LOG_S:g} s (edges, noise window, a scoring block)")
    step = float(np.median(np.diff(log.t)))
    if window_s is not None and window_s < 5 * step:
        said = f"--window {window_s:g} s" if what is None else what
        raise InputError(f"{said}: shorter than 5 samples of {name} "
                         f"(median step {step:.4g} s); the differentiator needs 5 or more")


def vehicle_check(states: list, params: VehicleParams) -> dict:
    """Ratios data/model of b, d and rotor speed over ``states`` (FlightStates; module doc):
    ``{"thrust_factor_data": b the data need (N s^2/rad^2), "thrust_factor_ratio": that over
    the model's b, "drag_factor_ratio": d the yaw balance needs over the model's d,
    "median_speed_ratio": median logged speed over ``max_speed`` (None without one)}``.
    Raises InputError when the parameter set cannot be the logged vehicle's (b ratio
    outside [1/:data:`MAX_RATIO`, :data:`MAX_RATIO`] or speed ratio above
    :data:`MAX_SPEED_RATIO`). States without rotor speeds are skipped ({} when none has
    them)."""
    states = [s for s in states if s.rotor_speed is not None]
    if not states:  # command-only logs: nothing to balance against here
        return {}
    speed = np.concatenate([s.rotor_speed for s in states])
    sf = np.concatenate([s.specific_force for s in states])
    rate_dot = np.concatenate([s.body_accel for s in states])
    omega2 = np.square(speed)
    x = omega2.sum(axis=1)
    b_data = float(params.mass * np.dot(sf[:, 2], x) / max(np.dot(x, x), 1e-300))
    b_ratio = b_data / params.thrust_factor
    yaw_row = allocation_matrix(params)[5] / params.drag_factor  # +-1 per rotor (spin)
    xy = omega2 @ yaw_row
    xy = xy - xy.mean()
    mz = rate_dot[:, 2] * params.inertia[2, 2]
    mz = mz - mz.mean()
    d_ratio = float(np.dot(mz, xy) / max(np.dot(xy, xy), 1e-300)) / params.drag_factor
    speed_ratio = float(np.median(speed) / params.max_speed) if params.max_speed else None
    out = {"thrust_factor_data": b_data, "thrust_factor_ratio": float(b_ratio),
           "drag_factor_ratio": d_ratio, "median_speed_ratio": speed_ratio}
    problems = []
    if not 1 / MAX_RATIO <= b_ratio <= MAX_RATIO:
        problems.append(f"the force balance m*f_z = b*sum(Omega^2) with the model's mass "
                        f"{params.mass:.4g} kg needs b = {b_data:.3g} N s^2/rad^2, "
                        f"{b_ratio:.3g}x the model's {params.thrust_factor:.3g} N s^2/rad^2")
    if speed_ratio is not None and speed_ratio > MAX_SPEED_RATIO:
        problems.append(f"the median logged rotor speed {np.median(speed):.4g} rad/s is "
                        f"{speed_ratio:.3g}x the model's max_speed {params.max_speed:.4g} rad/s")
    if problems:
        raise InputError(f"model {params.name!r} does not describe the logged vehicle: "
                         + "; ".join(problems) + f" (yaw balance: d {d_ratio:.3g}x the "
                         "model's); give the parameter set of the vehicle that flew")
    return out


TAU_BOUNDS = (5e-4, 0.5)


@dataclass(frozen=True)
class CommandModel:
    """a, b, c (R,) rad/s; v_ref V (NaN: no voltage term); tau s; rms rad/s of the fit on the
    reference; samples used; source (the reference logs)."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    v_ref: float
    tau: float
    rms: float
    samples: int
    source: str

    @property
    def rotor_count(self) -> int:
        return len(self.a)

    def speeds(self, t: np.ndarray, command: np.ndarray, vbat: np.ndarray | None) -> np.ndarray:
        """Rotor speeds (N, R) rad/s for commands (N, R) and vbat (N,) V or None."""
        features = _features(command, vbat, self.v_ref)
        ss = self.a + self.b * features[1] + self.c * features[2]
        return _lag(ss, _step(t), self.tau)


def _step(t: np.ndarray) -> float:
    return float(np.median(np.diff(t)))


def _features(command, vbat, v_ref):
    u = np.asarray(command, dtype=float)
    if vbat is None or not np.isfinite(v_ref):
        dv = np.zeros(len(u))
    else:
        dv = np.where(np.isfinite(vbat), np.asarray(vbat, float) - v_ref, 0.0)
    return np.ones_like(u), u, u * dv[:, None]


def _lag(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """First-order lag of x (N, ...) along axis 0, starting at rest at x[0]."""
    if tau <= 0:
        return x
    alpha = np.exp(-dt / tau)
    b = [(1 - alpha) / 2, (1 - alpha) / 2]
    # lfilter (direct form II transposed): y0 = b0 x0 + z; z = (1 - b0) x0 starts at rest.
    zi = x[0] - b[0] * x[0]
    y, _ = lfilter(b, [1.0, -alpha], x, axis=0, zi=zi[None] if np.ndim(zi) else [zi])
    return y


def fit_command_model(logs: Sequence[FlightLog]) -> CommandModel:
    """Identify the command -> speed model on logs with rotor speeds and commands (each
    airborne stretch of a log of several take-offs alone: the lag never runs across the
    ground span between them)."""
    usable = [p for g in logs if g.rotor_speed is not None and g.rotor_command is not None
              for p in g.parts()]
    if not usable:
        raise InputError("command model: the reference logs need both rotor_* (speeds) and "
                         "cmd_* (commands)")
    counts = {g.rotor_count for g in usable}
    if len(counts) != 1:
        raise InputError(f"command model: reference logs disagree on the rotor count {counts}")
    with_v = all(g.vbat is not None for g in usable)
    v_ref = float(np.nanmedian(np.concatenate([g.vbat for g in usable]))) if with_v else np.nan
    flights = [(_step(g.t), _features(g.rotor_command, g.vbat if with_v else None, v_ref),
                g.rotor_speed) for g in usable]

    def solve(tau: float):
        rows, targets = [], []
        for dt, feats, speed in flights:
            filt = [_lag(f, dt, tau) for f in feats]
            ok = np.isfinite(speed) & np.all([np.isfinite(f) for f in filt], axis=0)
            rows.append((filt, ok))
            targets.append(speed)
        coef, sse, n = [], 0.0, 0
        for i in range(usable[0].rotor_count):
            a_mat = np.concatenate([np.stack([f[:, i] for f in filt], 1)[ok[:, i]]
                                    for (filt, ok) in rows])
            y = np.concatenate([s[:, i][ok[:, i]] for s, (_, ok) in zip(targets, rows)])
            if not with_v:
                a_mat = a_mat[:, :2]
            sol, *_ = np.linalg.lstsq(a_mat, y, rcond=None)
            sse += float(np.sum((a_mat @ sol - y) ** 2))
            n += len(y)
            coef.append(np.append(sol, 0.0) if not with_v else sol)
        return np.array(coef), sse, n

    best = minimize_scalar(lambda lt: solve(np.exp(lt))[1], bounds=np.log(TAU_BOUNDS),
                           method="bounded", options={"xatol": 0.01})
    tau = float(np.exp(best.x))
    coef, sse, n = solve(tau)
    coef0, sse0, _ = solve(0.0)
    if sse0 <= sse:
        tau, coef, sse = 0.0, coef0, sse0
    names = ", ".join(str(g.path) for g in usable[:3]) + (" ..." if len(usable) > 3 else "")
    return CommandModel(coef[:, 0], coef[:, 1], coef[:, 2], v_ref, tau, float(np.sqrt(sse / n)),
                        n, f"fitted on {len(usable)} reference log(s): {names}")


def synthesise_speeds(log: FlightLog, model: CommandModel, *,
                      keep_commands: bool = False) -> FlightLog:
    """``log`` with rotor speeds from its commands (and vbat) through ``model``; each airborne
    stretch of a log of several take-offs (:attr:`FlightLog.segments`) alone."""
    name = log.path or "log"
    if log.rotor_command is None:
        raise InputError(f"{name}: cmd_1..cmd_N: no commands to synthesise rotor speeds from")
    if log.rotor_count != model.rotor_count:
        raise InputError(f"{name}: cmd_1..cmd_N: {log.rotor_count} commands, the command model "
                         f"has {model.rotor_count} rotors")
    speed = np.concatenate([model.speeds(p.t, p.rotor_command, p.vbat) for p in log.parts()])
    note = (f"{name}: rotor speeds synthesised from commands (tau {model.tau * 1e3:.1f} ms, "
            f"fit rms {model.rms:.3g} rad/s, {model.source})")
    return dataclasses.replace(log, rotor_speed=speed,
                               rotor_command=log.rotor_command if keep_commands else None,
                               notes=log.notes + (note,), speeds_synthesised=True)


@functools.lru_cache(maxsize=256)
def smoothing_cutoff_hz(window_s: float, rate_hz: float, polyorder: int = 3) -> float:
    """The -3 dB frequency (Hz) of a Savitzky-Golay smoother of ``window_s`` (s) and
    ``polyorder`` at sampling rate ``rate_hz`` (the window in samples as the states'
    smoothing takes it, :func:`quadsim.gap.residual.window_samples`): where its gain first
    falls below 1/sqrt(2) on a 4096-point grid up to Nyquist. Kept per arguments (every log
    of a run asks for the same few)."""

    n = window_samples(window_s, 1.0 / rate_hz, polyorder)
    freq, gain = freqz(savgol_coeffs(n, polyorder), worN=4096, fs=rate_hz)
    below = np.flatnonzero(np.abs(gain) < 1.0 / np.sqrt(2.0))
    return float(freq[below[0]]) if len(below) else rate_hz / 2.0


def needed_rate_hz(window_s: float | None = None) -> float:
    """The slowest native rate (Hz) of the channel that carries the rotors (module doc,
    "Slow channels"): twice the -3 dB frequency of the states' smoothing (window
    ``window_s``, default :data:`quadsim.gap.residual.DEFAULT_WINDOW_S`; cubic) at the fit's
    rate :data:`quadsim.gap.residual.FIT_RATE_HZ`; 19.75 Hz by default."""

    window = DEFAULT_WINDOW_S if window_s is None else window_s
    return 2.0 * smoothing_cutoff_hz(window, FIT_RATE_HZ)


def fit_slow_map(log: FlightLog, tau: float | None = None) -> CommandModel:
    """The command -> speed model of the module doc fitted on ``log``'s own rotor speeds
    (rad/s) and commands (0-1) at the rows where a logged speed sample shows
    (:func:`quadsim.logs.rates.native_rate`'s knots; every row where it reads none), each
    airborne stretch alone: the features lag-filtered at the full rate, then read at those
    rows. ``tau`` (s): the lag as given; None: fitted there (bounded, :data:`TAU_BOUNDS`,
    and 0). Raises InputError with fewer than 4 knots per stretch in all."""

    parts = [p for p in log.parts() if len(p.t) >= 5]
    with_v = log.vbat is not None and np.isfinite(log.vbat).any()
    v_ref = float(np.nanmedian(log.vbat)) if with_v else np.nan
    picked = []
    for p in parts:
        rate = native_rate(p.t, p.rotor_speed)
        knots = np.arange(len(p.t)) if rate is None else rate.knots
        picked.append((p, knots, _features(p.rotor_command, p.vbat if with_v else None,
                                           v_ref)))
    if sum(len(k) for _, k, _ in picked) < 4:
        raise InputError(f"{log.path or 'log'}: rotor_1..rotor_N: too few logged speed "
                         "samples to fit the command -> speed map on")

    def solve(tau_s: float):
        coef, sse, n = [], 0.0, 0
        for i in range(log.rotor_count):
            rows, ys = [], []
            for p, knots, feats in picked:
                filt = np.stack([_lag(f[:, i], _step(p.t), tau_s) for f in feats], axis=1)
                a_mat, y = filt[knots], p.rotor_speed[knots, i]
                ok = np.isfinite(y) & np.isfinite(a_mat).all(axis=1)
                rows.append(a_mat[ok])
                ys.append(y[ok])
            a_mat, y = np.concatenate(rows), np.concatenate(ys)
            a_mat = a_mat if with_v else a_mat[:, :2]
            sol, *_ = np.linalg.lstsq(a_mat, y, rcond=None)
            sse += float(np.sum((a_mat @ sol - y) ** 2))
            n += len(y)
            coef.append(sol if with_v else np.append(sol, 0.0))
        return np.array(coef), sse, max(n, 1)

    if tau is None:
        best = minimize_scalar(lambda lt: solve(np.exp(lt))[1], bounds=np.log(TAU_BOUNDS),
                               method="bounded", options={"xatol": 0.01})
        tau = float(np.exp(best.x))
        if solve(0.0)[1] <= solve(tau)[1]:
            tau = 0.0
    coef, sse, n = solve(tau)
    return CommandModel(coef[:, 0], coef[:, 1], coef[:, 2], v_ref, float(tau),
                        float(np.sqrt(sse / n)), n, f"fitted on {log.path or 'the log'}'s own "
                        "slow rotor speeds at their logged samples")


def slow_rotors(log: FlightLog, window_s: float | None = None) -> FlightLog:
    """``log`` as the diagnosis may use it where the channel carrying its rotors is logged
    too slowly (module doc, "Slow channels"): as is where the rotor speeds' native rate
    (:meth:`FlightLog.rate_hz`) is at least :func:`needed_rate_hz` or unknown; the speeds
    synthesised from the commands through :func:`fit_slow_map` (its lag fitted too), the
    commands dropped and the correction stated,
    where the commands are fast enough (or of unknown rate); else InputError, one line
    naming the file, the channel and both rates. A log with commands alone is refused
    where they are too slow."""
    need = needed_rate_hz(window_s)
    name = log.path or "log"
    speed_hz, cmd_hz = log.rate_hz("rotor_speed"), log.rate_hz("rotor_command")
    cmd_ok = log.rotor_command is not None and (cmd_hz is None or cmd_hz >= need)
    if log.rotor_speed is None:
        if log.rotor_command is None or cmd_ok:
            return log
        raise InputError(f"{name}: cmd_1..cmd_N: motor commands logged at {cmd_hz:.3g} Hz and "
                         f"no rotor speeds: too slow for the moments (needs >= {need:.3g} Hz, "
                         "twice the smoothing's -3 dB frequency): the moment channels cannot "
                         "be judged; log the commands or the rotor speeds faster")
    if speed_hz is None or speed_hz >= need:
        return log
    if not cmd_ok:
        cmds = ("no motor commands" if log.rotor_command is None else
                f"motor commands at {cmd_hz:.3g} Hz")
        raise InputError(f"{name}: rotor_1..rotor_N: rotor speeds logged at {speed_hz:.3g} Hz "
                         f"and {cmds}: too slow for the moments (needs >= {need:.3g} Hz, "
                         "twice the smoothing's -3 dB frequency): the moment channels cannot "
                         "be judged; log the rotor speeds or the commands faster")
    model = fit_slow_map(log)
    speed = np.concatenate([model.speeds(p.t, p.rotor_command, p.vbat) for p in log.parts()])
    rows_hz = median_rate(log.t) or np.inf
    said = (f"rotor speeds logged at {speed_hz:.2g} Hz, too slow for the moments (needs >= "
            f"{need:.3g} Hz): speeds synthesised from the commands "
            f"({min(cmd_hz or rows_hz, rows_hz):.3g} Hz) through a map fitted on them")
    rates = tuple((k, v) for k, v in log.rates_hz if k not in ("rotor_speed", "rotor_command"))
    if cmd_hz is not None:
        rates += (("rotor_speed", cmd_hz),)
    return dataclasses.replace(
        log, rotor_speed=speed, rotor_command=None, speeds_synthesised=True,
        corrections=log.corrections + (said,),   # a pulse-count factor kept: the map's scale
        notes=log.notes + (f"{name}: {said} (tau {model.tau * 1e3:.1f} ms, fit rms "
                           f"{model.rms:.3g} rad/s over {model.samples} logged samples)",),
        rates_hz=rates)


#: the band's cut-off as a share of the rate of the channel carrying the rotors (module doc,
#: "Judged in a band"): linear interpolation through samples at rate r passes a sine of
#: frequency f with the gain sinc^2(f / r) (the triangle kernel's transform): 0.81 at r / 4,
#: 0.95 at r / 8; the band's smoothing is down 3 dB at r / 4 and the wrench's content in
#: the band lies mostly well below its edge (the answers' mass, thrust, drag and wind near
#: 0-1 Hz, where the interpolation is faithful to 1-4 % at 10 Hz)
BAND_SHARE = 0.25
#: the slowest carrying rate (Hz) judged in a band: its band (:data:`BAND_SHARE` of it) at
#: 1.25 Hz still passes a hanging payload's swing (0.5-1 Hz for cables of 1-0.25 m,
#: f = sqrt(g / L) / 2 pi) and a manoeuvre's slow part; slower, the flight is refused
MIN_BAND_RATE_HZ = 5.0
#: the band's smoothing windows are searched on this grid (s)
BAND_WINDOW_STEP_S = 0.01


@dataclass(frozen=True)
class Band:
    """The band a run is judged in where no log's rotors are carried fast enough
    (:func:`band_of`): ``rate_hz`` the slowest carrying channel's native rate, ``source``
    its words ("motor commands logged at 10 Hz"), ``name`` the log it is read from,
    ``window_s`` the smoothing window (s) of the band (:func:`band_window_s`), ``cutoff_hz``
    its -3 dB frequency at the fit's rate."""

    rate_hz: float
    source: str
    name: str
    window_s: float
    cutoff_hz: float

    def words(self, name: str | None = None) -> str:
        """The correction every answer of the run states."""
        own = name is not None and str(name) == self.name
        where = "" if own else f" (the run's slowest, {Path(self.name).name}; every log alike)"
        return (f"judged below {self.cutoff_hz:.2g} Hz: {self.source}{where}, too slow for "
                f"the moments at full band (needs >= {needed_rate_hz():.3g} Hz); the forces, "
                f"moments and rotor channel compared only below that band (smoothing "
                f"{self.window_s:.2f} s), timing readings (signal_delay, motor_lag) not weighed")


def band_window_s(rate_hz: float, rows_hz: float | None = None) -> float:
    """The smoothing window (s) of the band of a channel logged at ``rate_hz`` (Hz), for
    states smoothed at ``rows_hz`` (the logs' row rate, at most the fit's
    :data:`quadsim.gap.residual.FIT_RATE_HZ`; default that): the shortest window on the
    :data:`BAND_WINDOW_STEP_S` grid, from :data:`quadsim.gap.residual.DEFAULT_WINDOW_S` up,
    whose -3 dB frequency (:func:`smoothing_cutoff_hz`) is at most :data:`BAND_SHARE` of
    ``rate_hz`` and that spans 5 rows (the differentiator's least): at 100 Hz 0.42 s for
    9.9-10.2 Hz (-3 dB at 2.48 Hz), 0.86 s for 5 Hz (1.23 Hz), 0.22 s for 19 Hz (4.65 Hz); on
    10 Hz rows (ArduPilot's log read on its 10 Hz motor outputs) 0.5 s (2.38 Hz), 0.51 s
    where the rows are a little slower than 10 Hz."""

    rows = FIT_RATE_HZ if rows_hz is None else min(float(rows_hz), FIT_RATE_HZ)
    edge = BAND_SHARE * rate_hz
    window = max(DEFAULT_WINDOW_S, np.ceil(5.0 / rows / BAND_WINDOW_STEP_S)
                 * BAND_WINDOW_STEP_S)
    window = round(float(window), 6)
    while smoothing_cutoff_hz(window, rows) > edge and window < 60.0:
        window = round(window + BAND_WINDOW_STEP_S, 6)
    return window


def carrying_rate(log: FlightLog) -> tuple[float, str] | None:
    """(rate Hz, words) of the slow channel that carries ``log``'s rotors, or None where
    something fast carries them (at the default smoothing: :func:`needed_rate_hz`) or the
    rates are unknown (main's path, :func:`slow_rotors`): the faster of the rotor speeds and
    the commands (the commands synthesise the speeds where they are faster)."""
    need = needed_rate_hz()
    have = [(log.rate_hz(key), words) for key, words, value in (
        ("rotor_speed", "rotor speeds", log.rotor_speed),
        ("rotor_command", "motor commands", log.rotor_command)) if value is not None]
    if not have or any(hz is None or hz >= need for hz, _ in have):
        return None
    hz, words = max(have)
    return hz, f"{words} logged at {hz:.2g} Hz"


def band_of(logs: Sequence[FlightLog]) -> Band | None:
    """The band every log of a run is judged in (module doc, "Judged in a band"): that of
    the log whose carrying channel (:func:`carrying_rate`) is the slowest, None where every
    log's rotors are carried fast (nothing changes). InputError, one line naming the file
    and the rates, where that channel is slower than :data:`MIN_BAND_RATE_HZ`, or where a
    log's rows (its motion: IMU, attitude) are themselves slower than :func:`needed_rate_hz`
    (ArduPilot's DataFlash read on its 10 Hz motor outputs: the measured side is as slow as
    the rotors, so no band holds a fast side against a slow one; CHANGELOG, "Slow rotors
    judged in the band they carry").
    The window is :func:`band_window_s` at the slowest log's row rate (at most the fit's)."""

    slow = [(rate, log) for log in logs if (rate := carrying_rate(log)) is not None]
    if not slow:
        return None
    (hz, words), log = min(slow, key=lambda item: item[0][0])
    name = str(log.path or "log")
    if hz < MIN_BAND_RATE_HZ:
        raise InputError(f"{name}: rotor_1..rotor_N: {words} and nothing faster carrying the "
                         f"rotors: too slow even for a band (needs >= {MIN_BAND_RATE_HZ:g} Hz, "
                         f"whose quarter, {BAND_SHARE * MIN_BAND_RATE_HZ:g} Hz, still carries a "
                         "hanging payload's swing): log the rotor speeds or the commands faster")
    need = needed_rate_hz()
    for g in logs:
        rows = median_rate(g.t) or np.inf
        if rows < need:     # the motion no faster than the rotors: nothing fast to judge by
            raise InputError(f"{g.path or 'log'}: t: rows at {rows:.3g} Hz and {words}: the "
                             f"motion itself is logged too slowly for the moments (needs >= "
                             f"{need:.3g} Hz) and no faster than the rotors, so no band can "
                             "hold a fast side against the slow one: log the IMU, or the "
                             "rows, faster")
    rows = min([FIT_RATE_HZ] + [median_rate(g.t) for g in logs
                                if len(g.t) > 1])
    window = band_window_s(hz, rows)
    return Band(hz, words, name, window, smoothing_cutoff_hz(window, rows))


def rejoined(log: FlightLog) -> FlightLog:
    """``log`` with each rotor channel logged slower than :func:`needed_rate_hz` and held
    (sample and hold: :func:`quadsim.logs.rates.native_rate`'s form "held") drawn again as
    the straight lines through its logged samples (each at the first row that shows it):
    a hold lags its samples by half an interval (50 ms at 10 Hz), which the band would read
    as a signal delay; interpolated channels are left as they are (their lines are these)."""

    need = needed_rate_hz()
    out = {}
    for key in ("rotor_speed", "rotor_command"):
        value = getattr(log, key)
        hz = log.rate_hz(key)
        if value is None or hz is None or hz >= need:
            continue
        rate = native_rate(log.t, value)
        if rate is None or rate.form != "held" or len(rate.knots) < 2:
            continue
        knots = rate.knots if rate.knots[0] == 0 else np.r_[0, rate.knots]
        out[key] = np.stack([np.interp(log.t, log.t[knots], value[knots, j])
                             for j in range(value.shape[1])], axis=1)
    return dataclasses.replace(log, **out) if out else log


def timing_carried(window_s: float) -> bool:
    """Whether states smoothed over ``window_s`` (s) carry the timing readings
    (``signal_delay``, ``motor_lag``: 10-50 ms read from the moments' phase): their -3 dB
    frequency at the fit's rate at least :data:`BAND_SHARE` of :func:`needed_rate_hz`
    (4.94 Hz: windows up to 0.2 s). Every band (:func:`band_window_s`, a carrying channel
    slower than that need) lies below it: there the slow channel's interpolation bends the
    phase near the band's edge as a delay of ~20 ms would (measured: CHANGELOG, "Slow rotors
    judged in the band they carry")."""
    return (smoothing_cutoff_hz(round(float(window_s), 9), FIT_RATE_HZ)
            >= BAND_SHARE * needed_rate_hz())


def in_band(log: FlightLog, band: Band) -> FlightLog:
    """``log`` as a run judged in ``band`` uses it (module doc, "Judged in a band"): its held
    slow rotor channels drawn through their samples (:func:`rejoined`), then
    :func:`slow_rotors` at the band's window (a channel at the band's rate is fast enough
    there; slower rotor speeds are synthesised from commands at it), the band stated as a
    correction in every answer."""
    log = slow_rotors(rejoined(log), band.window_s)
    return dataclasses.replace(log, corrections=log.corrections + (band.words(log.path),))


def without_speeds(log: FlightLog) -> FlightLog:
    """The log with its rotor-speed columns removed (what a command-only log looks like),
    and with them the checks' corrections of the speeds (``FlightLog.corrections``)."""
    return dataclasses.replace(log, rotor_speed=None, speeds_synthesised=False,
                               corrections=tuple(c for c in log.corrections
                                                 if SPEED_CORRECTION not in c))


@dataclass(frozen=True)
class MapCommandModel:
    """The command -> speed model of a parameter set: ``motor_map.speed_at(command, vbat)``
    (piecewise linear per rotor, voltage gain about the reference voltage) through the
    first-order lag ``time_constant`` (tau, s); rms = nan (not fitted here); source."""

    params: object
    tau: float
    source: str
    rms: float = float("nan")

    @property
    def rotor_count(self) -> int:
        return self.params.rotor_count

    def speeds(self, t: np.ndarray, command: np.ndarray, vbat: np.ndarray | None) -> np.ndarray:
        """Rotor speeds (N, R) (rad/s) of the normalised 0-1 commands ``command`` (N, R) (a
        log's ``cmd_i``) at times ``t`` (N,) (s) and battery voltages ``vbat`` (N,) (V; None:
        the map as stated): the commands in the map's own unit (:meth:`MotorMap.to_unit`:
        0-1 spans a PWM table), read by ``MotorMap.speed_at``, through the lag tau."""
        mm = self.params.motor_map
        steady = mm.speed_at(mm.to_unit(np.asarray(command, float)), vbat)
        return _lag(steady, _step(t), self.tau)


def command_model_from_params(params) -> MapCommandModel:
    """The parameter set's motor map as a command model; InputError without one."""
    mm = params.motor_map
    if mm is None:
        raise InputError(f"{params.path or params.name}: motor_map: logs without rotor speeds "
                         "need a command -> speed map: give --command-reference LOG... (logs "
                         "with rotor speeds and commands) or a parameter set with a "
                         "[motor_map] (python -m quadsim.identify --logs ... writes one, also "
                         "from command-only logs)")
    return MapCommandModel(params, float(mm.time_constant),
                           f"the motor map of {params.path or params.name} ({mm.source})")


@dataclass(frozen=True)
class BalancedModel:
    """A command model whose rotors' thrusts are rescaled by ``factors`` (R,) (relative
    thrust per rotor, ``Omega_i -> Omega_i sqrt(factors_i)``): :func:`balance_rotors`."""

    model: object
    factors: np.ndarray

    @property
    def rotor_count(self) -> int:
        return self.model.rotor_count

    @property
    def tau(self) -> float:
        return self.model.tau

    @property
    def rms(self) -> float:
        return self.model.rms

    @property
    def source(self) -> str:
        return (f"{self.model.source}, per-rotor thrust balanced on the references' mean roll "
                f"and pitch torque (x {', '.join(f'{f:.3f}' for f in self.factors)})")

    def speeds(self, t, command, vbat):
        return self.model.speeds(t, command, vbat) * np.sqrt(self.factors)


def balance_rotors(logs: Sequence[FlightLog], model, params) -> BalancedModel:
    """``model`` with per-rotor thrust factors ``1 + delta_i`` that make the reference
    ``logs``' (command-only) mean roll and pitch torque of the rotors equal to what their gyro
    says it was, ``mean(I w_dot + w x I w)`` (w_dot: the rate change over each stretch over its
    duration). ``delta`` moves neither the total thrust nor the yaw torque at the references'
    mean squared speeds (it lies in the null space of those two rows of the allocation
    matrix), so a flight's weight and yaw readings stay the references'.

    Why: the parameter set's command -> speed map is not the fleet's motors rotor by rotor;
    the difference is a roll/pitch torque every flight shares, which the per-flight reference
    model has no shared parameter to hold, so each calm flight was named ``com_offset``
    (tests/test_commands_wind.py). A map identified from commands only is the same for every
    rotor (``identify --logs``), so the fleet's own rotor imbalance is the same case."""
    from ..vehicle.rotors import allocation_matrix

    alloc = allocation_matrix(params)
    inertia = params.inertia
    squares, targets, weights = [], [], []
    for log in logs:
        for part in log.parts():
            if part.body_rate is None or part.rotor_command is None or len(part.t) < 3:
                continue
            w = part.body_rate
            duration = float(part.t[-1] - part.t[0])
            w_dot = (w[-1] - w[0]) / duration
            gyro_torque = inertia @ w_dot + np.mean(np.cross(w, w @ inertia.T), axis=0)
            speed = model.speeds(part.t, part.rotor_command, part.vbat)
            squares.append(np.mean(np.square(speed), axis=0))
            targets.append(gyro_torque[:2])
            weights.append(duration)
    if not squares:
        return BalancedModel(model, np.ones(model.rotor_count))
    weights = np.asarray(weights) / np.sum(weights)
    mean_sq = np.average(squares, axis=0, weights=weights)
    target = np.average(targets, axis=0, weights=weights)
    kept_rows = alloc[[2, 5]] * mean_sq              # thrust and yaw per relative change
    _, _, vt = np.linalg.svd(kept_rows)
    null = vt[2:].T                                  # (R, R - 2): moves neither
    moved = alloc[3:5] * mean_sq                     # roll, pitch torque per relative change
    now = moved.sum(axis=1)
    c, *_ = np.linalg.lstsq(moved @ null, target - now, rcond=None)
    delta = null @ c
    return BalancedModel(model, np.clip(1.0 + delta, 0.5, 1.5))


def derive_command_model(fleet: Sequence[FlightLog] | None, params,
                         reference: Sequence[FlightLog] | None = None):
    """The command -> speed model :func:`synthesise_all` derives from the logs: fitted
    (:func:`fit_command_model`) on the ``reference`` logs that have speeds and commands, else
    the parameter set's motor map (:func:`command_model_from_params`) balanced rotor by rotor
    (:func:`balance_rotors`) on the command-only logs of ``fleet`` (the reference role) when
    there are some."""
    measured = [g for g in (reference or []) if g.rotor_speed is not None
                and g.rotor_command is not None]
    model = fit_command_model(measured) if measured else command_model_from_params(params)
    command_only = [g for g in fleet or [] if g.rotor_speed is None]
    if not measured and command_only:      # a command-only fleet: its own rotor balance
        model = balance_rotors(command_only, model, params)
    return model


def synthesise_all(groups: dict[str, Sequence[FlightLog] | None], params,
                   reference: Sequence[FlightLog] | None = None, *, model=None):
    """Every command-only log in ``groups`` (role -> logs) gets synthesised speeds: the model
    is fitted on ``reference`` logs that have speeds, else the parameter set's motor map,
    balanced rotor by rotor on the command-only logs of the ``"reference"`` role when there
    are some (:func:`balance_rotors`: per flight, the references are the fleet). ``model``
    (a command model, e.g. a stored reference's, :mod:`quadsim.gap.reffile`): used as given
    instead (nothing fitted, nothing balanced). Returns (groups with the same keys, the
    model or None when no log needed one)."""
    needing = [g for logs in groups.values() for g in (logs or []) if g.rotor_speed is None]
    if not needing:
        return groups, None
    if model is None:
        model = derive_command_model(groups.get("reference"), params, reference)
    out = {role: (None if logs is None else
                  [synthesise_speeds(g, model) if g.rotor_speed is None else g for g in logs])
           for role, logs in groups.items()}
    return out, model


#: the highest probability stated on a log whose rotor order is not confirmed ("> 99 %" is
#: not said: the order's own evidence is weaker than that).
UNCONFIRMED_MAX_P = 0.99


def order_statuses(logs, params) -> list[RotorOrder]:
    """:func:`quadsim.logs.checks.rotor_order_status` of each log (FlightLogs, cut)."""
    return [rotor_order_status(log, params) for log in logs]


def probability_cap(statuses) -> float:
    """1 when every log's order is confirmed, else ``UNCONFIRMED_MAX_P``."""
    return 1.0 if all(s.confirmed for s in statuses) else UNCONFIRMED_MAX_P


def mark(verdict, statuses):
    """``verdict`` with the statuses' notes (orders not confirmed) and, where an order is
    doubtful, ``tentative`` and a sentence in its answer naming the map that fits better."""
    notes = tuple(s.note for s in statuses if s.note and s.note not in verdict.notes)
    doubtful = [s for s in statuses if s.doubtful]
    if not notes and not doubtful:
        return verdict
    answer = verdict.answer
    tentative = verdict.tentative
    if doubtful:
        maps = ", ".join(sorted({",".join(str(m + 1) for m in s.rival) for s in doubtful}))
        answer += (f" Tentative: the torque balance fits the rotor columns better in another "
                   f"order (--rotor-map {maps}); a wrong rotor order can produce this reading.")
        tentative = verdict.outcome != "refused"
    return dataclasses.replace(verdict, answer=answer, tentative=tentative,
                               notes=verdict.notes + notes)


def cap_decision(decision, cap: float):
    """A held-out :class:`~quadsim.gap.diagnose.Decision` with every probability capped at
    ``cap`` (the ranking kept)."""
    if cap >= 1.0:
        return decision
    ranked = tuple((k, min(p, cap), w) for k, p, w in decision.ranked)
    rows = tuple(dataclasses.replace(r, probability=min(r.probability, cap))
                 if hasattr(r, "probability") else {**r, "probability": min(r["probability"],
                                                                            cap)}
                 for r in decision.rows)
    return dataclasses.replace(decision, ranked=ranked, rows=rows)


def needs_pose(parts, logged=()) -> bool:
    """Whether any effect of ``parts`` ((effect, fixed, fitted) triples, an explanation's or
    a shared group's) reads a part of the pose (:attr:`~quadsim.effects.facts.EffectFacts.
    needs_pose`) that is not in ``logged`` (:func:`logged_parts`; default none). Names that
    are not library effects (the diagnosis' own fit forms) read none."""
    return any(name in EFFECTS and not set(EFFECTS[name].facts.needs_pose) <= set(logged)
               for name, _, _ in parts)


def logged_parts(log) -> frozenset:
    """The parts of the pose (:data:`quadsim.effects.facts.POSE_PARTS`) that ``log`` (a
    FlightLog or its FlightStates) gives: every part with a pose; the attitude alone for a
    log with its attitude and no position (module doc); none for IMU and motors only."""
    if _has_pose(log):
        return frozenset(POSE_PARTS)
    attitude = getattr(log, "has_attitude", getattr(log, "attitude", False))
    return frozenset({"attitude"}) if attitude else frozenset()


def posefree_log(log):
    """``log`` (a FlightLog without a pose) with the stand-in pose of the module doc:
    position and velocity zero (m, m/s), attitude the identity quaternion where none is
    logged (a logged attitude is kept)."""
    n = len(log.t)
    quat = log.quat if log.quat is not None else np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return dataclasses.replace(log, position=np.zeros((n, 3)), velocity=np.zeros((n, 3)),
                               quat=quat)


#: how long (s) the start of each airborne stretch is averaged over to level the IMU's
#: frame (:func:`posefree_states`): a quarter second of a stretch that starts near hover
#: (the cut of :mod:`quadsim.logs.spans` starts it at the take-off's end), long against
#: the accelerometer's noise, short against the flight's manoeuvres
LEVEL_S = 0.25


def posefree_states(states, attitude: bool, gravity: float):
    """The states of :func:`posefree_log`'s log marked as without a pose (``pose`` False),
    and ``accel_world`` (m/s^2) the smoothed accelerometer turned to the world,
    a = R f - g e_z (f the specific force at the body origin, module doc), for what a
    payload's swing reads. With its ``attitude`` logged, R is the logged attitude; without
    it (IMU and motors only) R is the gyro's own frame: the body rate integrated
    (:func:`quadsim.core.frames.integrate_body_rate`) from the tilt the accelerometer reads
    over the stretch's first :data:`LEVEL_S` (:func:`quadsim.core.frames.levelling_quat`,
    yaw 0), which becomes ``quat``.

    Why the gyro's frame serves a payload's swing: the swing and the cable's pull in the
    body frame depend only on the specific force and the rotation at the mount (the
    effective gravity a swinging mass feels, g - a = -R f, is what the accelerometer
    measures: the equivalence principle), and the swing's equations are unchanged under a
    constant rotation of the frame they are integrated in; R' = C R for a constant C (the
    unknown start yaw, the levelling's error) therefore gives the same pull in the body
    frame as the true attitude. The gyro's bias turns R' slowly away from C R, within the
    body (R' = C R E(t)), which the argument does not cover: a calibrated gyro's bias
    (~0.01 rad/s) moves the pull little, a bias of degrees per second does (measured:
    ``tests/test_imu_swing.py``, docs/logs.md). The stretch's first rows are the take-off's
    end, not a hover: the levelling's error is a constant C too. No other effect the body-frame
    balance weighs reads R (:func:`needs_pose`)."""
    from ..core.frames import integrate_body_rate, levelling_quat

    if not attitude:
        t = np.asarray(states.t, dtype=float)
        first = t <= t[0] + LEVEL_S
        quat = integrate_body_rate(t, states.body_rate,
                                   levelling_quat(np.mean(states.specific_force[first], axis=0)))
        states = dataclasses.replace(states, quat=quat)
    accel = rotate(states.quat, states.specific_force)
    accel[:, 2] -= gravity
    return dataclasses.replace(states, pose=False, attitude=attitude, accel_world=accel)


def missing_words(logged=()) -> str:
    """One sentence: which pose parts are not logged (``logged``: those that are,
    :func:`logged_parts`; default none), the effects not weighed for want of them (from the
    effects' facts), and what would add them."""
    needed = {k: v for k, v in without_pose(EFFECTS).items() if not set(v) <= set(logged)}
    parts = [p for p in POSE_PARTS if p not in logged and any(p in v for v in needed.values())]
    names = ", ".join(name.replace("_", " ") for name in needed)
    used = "the body-frame force and torque balance was used" + (
        ", with the logged attitude" if "attitude" in logged else "")
    return (f"no {_listed(parts)} logged: {names} not weighed ({used}); log the state "
            f"estimate or motion capture (columns "
            f"{'; '.join(POSE_PARTS[p] for p in parts)}) to add them")


def _listed(words: list[str]) -> str:
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " or " + words[-1]


def reference_has_pose(reference) -> bool:
    """Whether a calibrated reference model (:class:`quadsim.gap.calibrate.Reference`) was
    built on logs with a pose: its shared groups include an effect that reads one."""
    return needs_pose(reference.candidate.parts)


def check_same_kind(states, reference, name: str) -> None:
    """InputError when a flight and its references differ in having a pose: the
    references' shared drag and wind would act on the stand-in pose of a flight without
    one, and a flight with one would be weighed on effects the references never shared."""
    from ..core.errors import InputError

    ref_pose = reference_has_pose(reference)
    if bool(getattr(states, "pose", True)) != ref_pose:
        which = ("the reference flights log a pose, this flight does not" if ref_pose else
                 "this flight logs a pose, the reference flights do not")
        raise InputError(f"{name}: x..z, qw..qz: {which}: judge "
                         "logs of one kind together (without a pose: IMU and motors only, "
                         "the body-frame balance; drop the pose columns of the others to "
                         "compare them so)")


#: how an ``unexplained`` answer opens when effects of the library were not weighed (no
#: pose): what stays is beyond the readings weighed, not shown to be outside the library
NOT_WEIGHED_OPENINGS = {"Not in the library:": "Not explained by the readings weighed:",
                        "Unexplained:": "Not explained by the readings weighed:"}


#: how a rotor timing reading (``signal_delay``) opens in every answer: "the rotor speeds are
#: timed 13 ± 1 ms later ..." (:func:`quadsim.gap.words.reading_text`, which imports it from
#: here; :func:`synthesised_timing_note` finds the reading by these words)
TIMING_WORDS = "rotor speeds are timed"

#: what a rotor timing reading (``signal_delay``) means on a log whose rotor speeds were
#: synthesised from its commands (:func:`synthesised_timing_note`)
SYNTHESISED_TIMING_WORDS = (
    "No rotor speeds logged: they are synthesised from the motor commands (the motor map and "
    "its lag), so a rotor timing here is the commands' timing through that map: the "
    "commands logged at another time, or the motors responding at another speed, than on "
    "the reference flights; a logged rotor speed would tell the two apart.")


def synthesised_timing_note(verdict, logs):
    """``verdict`` (:class:`quadsim.gap.result.Verdict`) with
    :data:`SYNTHESISED_TIMING_WORDS` at the end of its answer where one of ``logs``
    (FlightLogs: the judged flight, or a held-out run's training and held-out flights) has
    rotor speeds synthesised from its commands (``FlightLog.speeds_synthesised``) and the
    answer states the rotor timing reading ``signal_delay`` (its words open with
    :data:`TIMING_WORDS`, "the rotor speeds are timed ... later", wherever
    it is stated: as the name, beside it, or as the lead of an unexplained answer): there it
    reads a timing of the commands through the command -> speed model, not of a logged
    signal; else ``verdict`` as is. Outcome and numbers unchanged."""
    if not any(getattr(g, "speeds_synthesised", False) for g in logs):
        return verdict
    if TIMING_WORDS not in verdict.answer:
        return verdict
    return dataclasses.replace(verdict, answer=f"{verdict.answer} {SYNTHESISED_TIMING_WORDS}")


def confusable(a: str, b: str) -> str:
    """How to tell readings ``a`` and ``b`` apart where an effect of either (a pair ``x+y``
    counts each) declares the other among those the data may not separate
    (:attr:`quadsim.effects.facts.EffectFacts.separate_from`); "" where none does."""
    from ..effects import EFFECTS

    for x in a.split("+"):
        for y in b.split("+"):
            for one, other in ((x, y), (y, x)):
                facts = getattr(EFFECTS.get(one), "facts", None)
                hint = dict(getattr(facts, "separate_from", {}) or {}).get(other)
                if hint:
                    return hint
    return ""


def _unseparated_rivals(verdict, within: float = float("inf"), shrink=None) -> list:
    """The readings of ``verdict``'s posterior, not stated beside its name, that the name's
    effect and they declare confusable (:func:`confusable`), with a determined magnitude,
    and (``within``, log-evidence units) a log evidence no more than that below the name's
    (the posterior's highest where no reading bears the name: a lead renamed by the lead
    rule), or no more than that below it with every value of both counted at its prior's
    centre (log evidence + :attr:`~quadsim.gap.result.Reading.prior_pull`: where the priors
    centre a pair's values is no evidence of this flight; a pair that gives the same force
    is then told apart by the data's fit and the Occam volume alone), most probable first:
    [(reading, how to tell them apart)]. ``shrink``: (name, variant) -> the log units a
    reading may owe to the logged speeds' noise on the torque channels
    (:func:`quadsim.gap.judge.torque_shrinkage`), taken off the name's log evidence before
    the margin is read (None: nothing taken off). The name's only: the bound is the most the
    noise can give, so the name may be that much worse than it looks, a rival no better than
    it looks; taking it off a rival would call a pair told apart on the noise's account."""
    stated = set(verdict.readings or ()) | {verdict.name, "no_difference"}
    lead = _lead(verdict)
    if lead is None or not np.isfinite(within):
        floor = flat = -np.inf
    else:
        owed = _owed(lead, shrink)
        floor = lead.log_evidence - owed - within
        flat = lead.log_evidence - owed + getattr(lead, "prior_pull", 0.0) - within
    rivals = [(r, confusable(verdict.name, r.name)) for r in verdict.posterior
              if r.name not in stated and r.magnitude and (
                  r.log_evidence >= floor
                  or r.log_evidence + getattr(r, "prior_pull", 0.0) >= flat)]
    return sorted([(r, hint) for r, hint in rivals if hint],
                  key=lambda x: -x[0].probability)


#: between two readings that their effects declare confusable (:func:`confusable`), the log
#: evidence margin (natural log) the name must exceed for the data to count as telling them
#: apart on a log with a pose: ln 150, "very strong" on Kass & Raftery's scale (1995, J. Am.
#: Stat. Assoc. 90: 2 ln B > 10). Why so high: such a pair gives the same force, and what
#: separates it (the priors' widths, the moments, the rotor channel's command model) is not
#: the change itself; measured margins on real flights with a known change:
#: benchmarks/README.md, "Real flights with a known change written in". The margin is read
#: over the lead's dispersion (:attr:`quadsim.gap.result.Verdict.dispersion`): in the
#: references' noise units where the flight's residual after the name is no larger than
#: theirs, shrunk by that factor where it is (quasi-likelihood).
SEPARATED = float(np.log(150.0))


def _by_priors(verdict, rivals: list, scale: float, owed: float = 0.0) -> bool:
    """Whether a rival of ``rivals`` (:func:`_unseparated_rivals`) lies beyond
    :data:`SEPARATED` times ``scale`` of the name's log evidence less ``owed`` (what it may owe
    to the logged speeds' noise), and so is stated only with every value counted at its
    prior's centre."""
    own = _own_evidence(verdict)
    return own is not None and any(own - owed - r.log_evidence > SEPARATED * scale
                                   for r, _ in rivals)


def _by_noise(verdict, rivals: list, scale: float, owed: float) -> bool:
    """Whether a rival of ``rivals`` lies beyond :data:`SEPARATED` times ``scale`` of the
    name's log evidence and within it of that evidence less ``owed`` > 0: stated only because
    the name may owe that much to the logged speeds' noise."""
    own = _own_evidence(verdict)
    return own is not None and owed > 0 and any(
        own - r.log_evidence > SEPARATED * scale >= own - owed - r.log_evidence
        for r, _ in rivals)


def _lead(verdict):
    """The name's reading in ``verdict``'s posterior: its highest-evidence variant, or the
    posterior's highest where no reading bears the name (a lead renamed by the lead rule);
    None for an empty posterior."""
    own = [r for r in verdict.posterior if r.name == verdict.name] or list(verdict.posterior)
    return max(own, key=lambda r: r.log_evidence) if own else None


def _own_evidence(verdict) -> float | None:
    """The log evidence of :func:`_lead`; None for an empty posterior."""
    lead = _lead(verdict)
    return None if lead is None else float(lead.log_evidence)


def _owed(reading, shrink) -> float:
    """What ``shrink`` ((name, variant) -> log units, or None) says ``reading`` may owe to
    the logged speeds' noise (:func:`quadsim.gap.judge.torque_shrinkage`); 0 where none."""
    return float((shrink or {}).get((reading.name, reading.variant), 0.0))


def _has_pose(log) -> bool:
    """Whether ``log`` (a FlightLog, ``has_pose``, or FlightStates, ``pose``) has a pose."""
    return bool(getattr(log, "has_pose", getattr(log, "pose", True)))


def confusable_note(verdict, log, shrink=None):
    """``verdict`` (:class:`quadsim.gap.result.Verdict`) of a log with a pose (``log``: a
    FlightLog or its FlightStates; one without is :func:`without_pose_note`'s) with each
    declared confusable reading (:func:`confusable`) whose log evidence lies within
    :data:`SEPARATED` of the name's (or within it with every value counted at its prior's
    centre, :func:`_unseparated_rivals`) stated beside it, with its probability and how to
    tell them apart, and the name tentative; else as is. The margin is compared in
    quasi-likelihood units: SEPARATED times ``verdict.dispersion``
    (:func:`quadsim.gap.judge.overdispersion`, 1 where the flight's residual after the name
    lies within the references'), which the words state where it is above 1; the name's
    evidence less what ``shrink`` says it may owe to the logged speeds' noise
    (:func:`_unseparated_rivals`). The outcome and the numbers are unchanged."""
    if not _has_pose(log) or verdict.outcome != "effect":
        return verdict
    # in quasi-likelihood units: the margin over the lead's dispersion (Verdict.dispersion)
    scale = max(1.0, float(getattr(verdict, "dispersion", 1.0)))
    rivals = _unseparated_rivals(verdict, SEPARATED * scale, shrink)
    if not rivals:
        return verdict
    owed = _owed(_lead(verdict), shrink)
    each = "; or ".join(f"{r.name} ({r.magnitude}; {100 * r.probability:.2g} % here; to tell "
                        f"them apart: {hint})" for r, hint in rivals)
    # the name tentative, said once (the judge's words may have said so already)
    opening = "Not told apart" if "Tentative" in verdict.answer else "Tentative: not told apart"
    answer = (f"{verdict.answer} {opening} from {each}: the library names "
              f"{'the pair' if len(rivals) == 1 else 'each pair'} as one the data may not "
              f"separate, and the name's evidence exceeds "
              f"{'it' if len(rivals) == 1 else 'each'} by less than the {SEPARATED:.1f} log "
              "units that very strong evidence needs"
              + (f", times {scale:.2g}: the flight's residual after the name is {scale:.2g}x "
                 "the references' in mean square, which the evidence's noise model does not "
                 "hold" if scale > 1 else "")
              + (f" once the name's evidence is taken as up to {owed:.2g} log units less (what "
                 "its scale of every rotor's torque may owe to the logged rotor speeds' noise: "
                 "errors in variables)" if _by_noise(verdict, rivals, scale, owed) else "")
              + (" once each value is counted at its prior's centre (where the priors centre "
                 "the values is no evidence of this flight)"
                 if _by_priors(verdict, rivals, scale, owed) else "") + ".")
    names = tuple(r.name for r, _ in rivals)
    return dataclasses.replace(
        verdict, answer=answer, tentative=True, readings=tuple(verdict.readings) + names,
        confusable_with=tuple(verdict.confusable_with) + names,
        separate_by={**dict(verdict.separate_by), **{r.name: h for r, h in rivals}})


def without_pose_note(verdict, log):
    """``verdict`` (:class:`quadsim.gap.result.Verdict`) with :func:`missing_words` at the
    end of its answer and in its notes when ``log`` (a FlightLog or its FlightStates) has no
    pose; else as is.
    An ``unexplained`` answer then opens with :data:`NOT_WEIGHED_OPENINGS`' words instead
    of "Not in the library:" / "Unexplained:" and its last sentence says that what stays may
    be one of the effects not weighed: a cable's swing, a drag or a wind leaves exactly such
    a remainder on the body-frame balance (the payload flights of the shared mixed set,
    IMU and commands only: docs/logs.md, "What a log needs"); the outcome is unchanged. A
    name whose effect and a reading not stated beside it are a declared confusable pair
    (:func:`confusable`; e.g. a payload and a thrust per Omega^2: the same weight balance)
    gets that reading stated beside it with how to tell them apart, and is tentative: what
    separates them on such a log (the roll and pitch moments) is where the effects not
    weighed act too (a swinging load slows roll and pitch as a weaker rotor authority would:
    the mixed payload flights cut to IMU and commands, docs/logs.md)."""
    if _has_pose(log) or verdict.outcome == "refused":
        return verdict
    said = missing_words(logged_parts(log))
    answer, tail = verdict.answer, f" Not weighed: {said}."
    rivals = _unseparated_rivals(verdict) if verdict.outcome == "effect" else []
    if rivals:      # declared confusable pairs: not separated without a pose
        each = "; or ".join(f"{r.name} ({r.magnitude}; {100 * r.probability:.2g} % here; to "
                            f"tell them apart: {hint})" for r, hint in rivals)
        answer += (f" Without a pose it is not told from {each}: the library names each pair "
                   "as confusable, and what separates them here (the moments, the fit's "
                   "shape) is where the effects not weighed act too.")
        names = tuple(r.name for r, _ in rivals)
        verdict = dataclasses.replace(
            verdict, tentative=True, readings=tuple(verdict.readings) + names,
            confusable_with=tuple(verdict.confusable_with) + names,
            separate_by={**dict(verdict.separate_by), **{r.name: h for r, h in rivals}})
    if verdict.outcome == "unexplained":
        for old, new in NOT_WEIGHED_OPENINGS.items():
            if answer.startswith(old):
                answer = new + answer[len(old):]
                break
        tail = f" Not weighed: {said}; what stays may be one of them."
    return dataclasses.replace(verdict, answer=answer + tail,
                               notes=tuple(verdict.notes) + (said,))
