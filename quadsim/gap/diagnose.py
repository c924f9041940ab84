"""Held-out mode and the shared preparation: prepare the logs, split by flight, judge.

:func:`prepare` turns logs into :class:`Flight` (smoothed states at the log's rate, the
decimated fit view, signal delays); :func:`diagnose` splits the flights (``holdout`` or
every third flight; one flight: its two halves), takes the parameter set as the reference
model (:func:`nominal_reference`), weighs every explanation
(:func:`weigh`, :func:`decide`), judges
(:func:`quadsim.gap.judge.judge_heldout`) and says where the gap lies (:mod:`.where`). It
returns a :class:`quadsim.gap.result.Diagnosis` (``mode`` ``"held-out"``; its ``to_json()``
is the ``quadsim.gap/3`` JSON, :mod:`.report`).

The held-out judgment
---------------------
Held-out mode by evidence: candidates fitted on the training flights, weighed by their
evidence there, then checked on the held-out flights.

``python -m quadsim.gap TRAIN... --holdout HELD...`` (:func:`quadsim.gap.diagnose.diagnose`)
judges the parameter set against flights that all may share the gap, so there are no
reference flights: the reference model is the parameter set itself (with the training
flights' static command -> speed map), and the same evidence machinery as the per-flight mode
(:mod:`.evidence`, :mod:`.judge`) weighs every explanation of how the flights differ from it.

Stages (each a named type)
--------------------------
1. :func:`nominal_reference` -> :class:`quadsim.gap.calibrate.Reference`: the nominal model,
   every shared group of :data:`quadsim.gap.calibrate.SHARED` at its "off" value with zero
   spread (nothing is marginalised: the gap is what the flights do that the parameter set
   does not), and the **noise model from what the gap does not contain**: per channel
   sigma_c = robust scatter of the *fast* part of the nominal residual on the training
   flights (residual minus its moving average over :data:`NOISE_WINDOW_S` = 0.5 s,
   :func:`quadsim.gap.fitting.noise_scale`), and tau_c its correlation time (samples). A gap
   that acts slower than 0.5 s (every effect of the library at flight speeds: a payload, a
   weak rotor, drag, a lag seen over the 0.12 s rotor horizon) is left out of sigma, so
   "the floor contains the gap" cannot happen. (The per-flight mode's sigma is the RMS of
   the calibrated model over the reference flights instead: there the references show what
   a right model leaves.)
2. :func:`heldout_explanations`: :func:`quadsim.gap.explanations.explanations_for` on that
   reference (every effect, every shared group at a value of its own) plus what the nominal
   model lacks and the per-flight references carry: ``wind`` fitted with the rotor-drag
   coefficient (wind acts only through drag, and the nominal model has none), ``motor_lag``
   (with commands), ``battery_sag`` as a full voltage (with a vbat log), and
   ``nominal_refit`` (b and d re-identified; b prior as thrust_factor, d prior spread 0.5:
   the drag-torque factor of a small propeller is known to a factor of ~2 unless measured
   on a stand -- the Crazyflie's 0.006 m x b from the literature against 0.0013 m x b in its
   logs, docs/gap.md).
3. :func:`weigh`: :func:`quadsim.gap.evidence.evaluate` on the stacked training flights
   (Laplace evidence: likelihood over all channels under the noise model, priors with
   sources, Occam factor), then each explanation's MAP values predict the held-out flights:
   its log-likelihood there is added (the posterior of the explanation given all flights,
   with the held-out part as a plug-in predictive check). :func:`quadsim.gap.judge.posterior`
   gives the probability per reading, "no difference" included, exactly as per flight.
4. :func:`decide`: the ranking (:func:`quadsim.gap.judge.rank`), a second effect when the
   lead leaves a systematic remainder or does not carry over (:func:`pair`: the lead refitted
   with each other effect; the pair's prior is the lead's split evenly among its partners,
   and every part of it must be determined and plausible,
   :func:`quadsim.gap.judge.every_part_stands`), and the consistency check of the lead
   (:mod:`.where`) -> :class:`Decision`, which :func:`quadsim.gap.judge.judge_heldout`
   turns into the verdict.

Example::

    >>> result = diagnose(train_logs, params, holdout=held_logs)
    >>> result.verdict.name, result.verdict.probability
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..core.errors import InputError, ModelError, refuse_moved
from ..logs.delays import align_signal_delays, delay_notes
from ..logs.flightlog import FlightLog
from ..vehicle.params import VehicleParams
from . import order
from .calibrate import Reference, shared_candidate
from .checks import check_length, vehicle_check
from .discrepancy import centre_term, columns, fit_discrepancy
from .evidence import Evidence, Explanation, evaluate, explanations_for
from .fitmodels import build_effect
from .fitting import (
    BASELINE,  # noqa: F401  (re-exported: quadsim.identify, tests)
    Candidate,
    correlation_time,
    effect_class,
    fit_motor_map,
    noise_floor,
    noise_scale,
    residuals,
    stack_states,
)
from .judge import (
    SLOW_WINDOW_S,
    carry_over,
    channel_names,
    every_part_stands,
    judge_heldout,
    plausible,
    rank,
    reading_text,
    remainder,
    slow_part,
)
from .posefree import needs_pose, posefree_log, without_pose_note
from .residual import DEFAULT_WINDOW_S, FlightStates, flight_states
from .result import Diagnosis, Reading, Series
from .segments import joined_states
from .selfcheck import SelfCheck, Spread, negligible, readings, spreads
from .where import check as consistency_check
from .where import scaled_residuals, where
from .words import nominal_words

__all__ = [
    "D_PRIOR_SD",
    "EDGE_S",
    "NOISE_WINDOW_S",
    "SCHEMA",
    "Decision",
    "Flight",
    "Weighed",
    "decide",
    "diagnose",
    "effects_of",
    "entry_of",
    "heldout_explanations",
    "interior",
    "noise_model",
    "nominal_reference",
    "pair",
    "prepare",
    "readings_of",
    "slow_part",
    "weigh",
]

SCHEMA = "quadsim.gap/3"
FIT_RATE_HZ = 100.0
#: long flights are decimated further so that one flight costs at most this many samples.
MAX_FIT_SAMPLES_PER_FLIGHT = 20000
#: the fit view's anti-alias cut-off, a fraction of its Nyquist frequency (:func:`decimated`):
#: at a 100 Hz fit rate 40 Hz, where the 4th-order Butterworth, run forward and back, is down
#: 6 dB; at 20 Hz 0.03 dB and at 5 Hz 1e-6 dB: flat over the flight dynamics the diagnosis
#: fits (a few Hz)
ANTI_ALIAS = 0.8
#: samples closer than this (s) to either end of a log are neither fitted nor scored (see
#: :func:`prepare`); at most :data:`MAX_EDGE_SHARE` of a flight's duration per end.
EDGE_S = 0.2
MAX_EDGE_SHARE = 0.1


#: ``MIN_GAIN`` (the benchmarks' threshold) moved out: refused with exactly what to change
__getattr__ = refuse_moved(__name__, {
    "MIN_GAIN": "moved to benchmarks.observe.MIN_GAIN (in the repository, not the wheel): "
                "write `from benchmarks.observe import MIN_GAIN` and run from a checkout"})


@dataclass
class Flight:
    """One prepared flight: full-rate states, the decimated view used for fitting."""

    name: str
    states: FlightStates
    fit: FlightStates
    delays_ms: dict = field(default_factory=dict)   # signal delays vs motion capture (ms)
    delay_notes: tuple = ()                         # why a delay was not estimated


def interior(t: np.ndarray, edge_s: float | None = None) -> np.ndarray:
    """Indices of the samples of ``t`` (s) at least ``edge_s`` (default :data:`EDGE_S`) from
    both ends (at most :data:`MAX_EDGE_SHARE` of the duration per end)."""
    edge_s = EDGE_S if edge_s is None else edge_s
    margin = min(edge_s, MAX_EDGE_SHARE * (t[-1] - t[0]))
    return np.nonzero((t >= t[0] + margin) & (t <= t[-1] - margin))[0]


def prepare(logs: Sequence[FlightLog], params: VehicleParams, *,
            window_s: float = DEFAULT_WINDOW_S) -> list[Flight]:
    """Check each log against the model and smooth it (:func:`quadsim.gap.residual.flight_states`).

    The first and last :data:`EDGE_S` = 0.2 s of each log (at most :data:`MAX_EDGE_SHARE`
    = 10 % of its duration per end) are dropped after smoothing: there the derived signals
    are not valid (one-sided Savitzky–Golay derivatives, filter transients; 0.2 s covers the
    smoothing window twice over and a zero-phase low-pass down to 5 Hz, whose transient
    decays to 1 % in ~1.04 / f_c; docs/gap.md, method).

    Raises :class:`InputError` for a rotor-count mismatch, logs without rotor speeds or
    shorter than :data:`quadsim.gap.checks.MIN_LOG_S` (2 s)."""
    out = []
    for log in logs:
        name = str(log.path) if log.path is not None else f"log{len(out)}"
        if log.rotor_speed is None:
            what = "commands only" if log.rotor_command is not None else "neither"
            raise InputError(f"{name}: rotor_1..rotor_N: the diagnosis needs measured rotor "
                             f"speeds (this log has {what}); the residual wrench compares the "
                             "motion with the thrust of the measured rotors (with commands: "
                             "--command-reference LOG... synthesises speeds, quadsim.gap.commands)")
        if log.rotor_count != params.rotor_count:
            raise InputError(f"{name}: rotor_1..rotor_N: {log.rotor_count} rotors in the log, "
                             f"the model {params.name!r} has {params.rotor_count}")
        check_length(log, name=name)              # >= MIN_LOG_S, else one line naming t
        # each airborne stretch alone (quadsim.gap.segments); delays: the longest stretch's
        parts = [align_signal_delays(p) for p in log.parts()]   # quadsim.logs.delays
        delays = max(parts, key=lambda part: len(part[0].t))[1]
        step = None if len(parts) == 1 else float(np.median(np.diff(log.t)))
        pieces = [flight_states(p if p.has_pose else posefree_log(p), window_s=window_s,
                                gravity=params.gravity, dt=step) for p, _ in parts]
        if not log.has_pose:     # IMU and motors only: the stand-in pose (quadsim.gap.posefree)
            pieces = [dataclasses.replace(s, pose=False) for s in pieces]
        pieces = [s.take(interior(s.t)) for s in pieces]
        states = joined_states(pieces)
        dt = float(states.t[1] - states.t[0])
        stride = max(1, round(1.0 / (FIT_RATE_HZ * dt)),
                     int(np.ceil(len(states.t) / MAX_FIT_SAMPLES_PER_FLIGHT)))
        fit = joined_states([decimated(s, stride) for s in pieces])
        out.append(Flight(name, states, fit, delays.ms(), delays.notes))
    return out


def decimated(states: FlightStates, stride: int) -> FlightStates:
    """Every ``stride``-th sample of ``states`` (the fit view), low-passed first below the
    new Nyquist frequency: a zero-phase 4th-order Butterworth at :data:`ANTI_ALIAS` of it on
    every signal but the quaternion (already smooth; a filtered one would leave the unit
    sphere). Why: picking samples folds what lies above the fit rate's Nyquist frequency
    into its band (a rotor-speed ripple becomes a ripple at the fit's Nyquist frequency).
    """
    if stride <= 1:
        return states
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, ANTI_ALIAS / stride, output="sos")

    def low(x):
        return None if x is None else sosfiltfilt(sos, x, axis=0)

    low_passed = FlightStates(states.t, low(states.position), low(states.velocity),
                              low(states.accel_world), states.quat, low(states.body_rate),
                              low(states.body_accel), low(states.specific_force),
                              low(states.rotor_speed), low(states.rotor_accel),
                              low(states.command), low(states.vbat), states.accel_source,
                              states.window_s, states.polyorder, states.name, states.pose)
    return low_passed.take(np.arange(0, len(states.t), stride))


def _split(flights: list[Flight], holdout: list[Flight] | None, notes: list[str]):
    """(training, held-out) flights: ``holdout`` when given, else every third flight held
    out; a single flight is cut in two halves (a note says so)."""
    if holdout:
        return flights, holdout
    if len(flights) >= 2:
        held = [f for i, f in enumerate(flights) if i % 3 == 2] or [flights[-1]]
        return [f for f in flights if f not in held], held
    notes.append("single flight: no held-out flight to score on; the second half of the same "
                 "flight is used instead (weaker evidence, give more flights or --holdout)")
    f = flights[0]
    half = len(f.states.t) // 2
    parts = []
    for sl in (slice(0, half), slice(half, None)):
        states = f.states.take(np.arange(len(f.states.t))[sl])
        fit_idx = np.nonzero((f.fit.t >= states.t[0]) & (f.fit.t <= states.t[-1]))[0]
        parts.append(Flight(f.name, states, f.fit.take(fit_idx)))
    return [parts[0]], [parts[1]]


def diagnose(logs: Sequence[FlightLog], params: VehicleParams, *,
             holdout: Sequence[FlightLog] | None = None, effects: Sequence[str] | None = None,
             max_combination: int = 2, progress: Callable | None = None,
             window_s: float = DEFAULT_WINDOW_S, kstep: bool = True,
             map_fn: Callable = map, base_effects: Sequence = ()) -> Diagnosis:
    """Diagnose the gap between ``params`` and ``logs`` (see :mod:`quadsim.gap`): a
    :class:`~quadsim.gap.result.Diagnosis` (``mode`` ``"held-out"``).

    ``holdout``: the held-out logs (default: every third of ``logs``); ``effects``: restrict
    the candidate effects (unknown names: :class:`InputError`); ``max_combination`` >= 2
    lets a second effect join the lead; ``progress(name)`` is called per fit;
    ``window_s`` (s): the smoothing window; ``kstep=False`` skips the k-step prediction
    errors (the slowest part of "where"); ``map_fn(fn, items)`` runs the candidate fits
    (e.g. a :mod:`quadsim.core.executor` executor). ``base_effects``: effects already in
    the model (an effect file, :mod:`quadsim.effects.effectfile`): the "before" gap is
    theirs, every candidate is fitted on top of them, and they are never refitted."""
    notes: list[str] = []
    flights = prepare(logs, params, window_s=window_s)
    held_in = prepare(holdout, params, window_s=window_s) if holdout else None
    checks = vehicle_check([f.fit for f in flights + (held_in or [])], params)
    notes.extend(delay_notes(flights + (held_in or [])))
    train, held = _split(flights, held_in, notes)
    base = tuple(base_effects)
    rotor = all(f.fit.command is not None for f in train + held)
    if rotor and not params_have_data_map(params):
        params = fit_motor_map([f.fit for f in train], params)
    fit_on, held_on = [f.fit for f in train], [f.fit for f in held]
    reference = nominal_reference(fit_on, params, rotor, base)
    weighed = _weigh(fit_on, held_on, reference, effects=effects, map_fn=map_fn,
                     tick=progress or (lambda *_: None))
    sigma = reference.sigma
    before = [_beyond(b * sigma - centre_term(h, reference.discrepancy, len(sigma)), h,
                      reference)[0] / sigma for b, h in
              zip(scaled_residuals(held_on, params, list(base), sigma, rotor=rotor), held_on)]
    decision = decide(weighed, train=fit_on, held=held_on, reference=reference,
                              before=before, max_combination=max_combination,
                              tick=progress or (lambda *_: None))
    lead = decision.lead
    effects_after = list(base) + (effects_of(lead.train)
                                  if decision.lead_name != "no_difference" else [])
    after = [r / sigma for r in lead.held_residuals] if effects_after else before
    dt = float(fit_on[0].t[1] - fit_on[0].t[0])
    statuses = order.order_statuses(list(logs) + list(holdout or []), params)
    decision = order.cap_decision(decision, order.probability_cap(statuses))
    verdict, more = judge_heldout(decision, reference, before=before, after=after, dt=dt)
    verdict = order.mark(verdict, statuses)
    posefree = next((g for g in logs if not g.has_pose), None)
    if posefree is not None:                  # what a pose would add (quadsim.gap.posefree)
        verdict = without_pose_note(verdict, posefree)
    names = channel_names(reference)
    combination = None
    if decision.combination is not None and decision.lead_name == decision.combination.name:
        combination = decision.entry(decision.lead_name)
    held_series = tuple(Series(h.t, b * sigma, a * sigma, tuple(names), f.name, h, params,
                               tuple(effects_after))
                        for h, b, a, f in zip(held_on, before, after, held))
    return Diagnosis(
        SCHEMA, params.name, "held-out", verdict=verdict,
        train=tuple(f.name for f in train), holdout=tuple(f.name for f in held),
        where=where(held_on, params, names=names, sigma=sigma, before=before, after=after,
                    effects_after=effects_after, base=list(base), kstep=kstep),
        effects=decision.entries, baseline=decision.entry("nominal_refit") or {},
        combination=combination,
        noise_model={"sigma": dict(zip(names, map(float, sigma))),
                     "correlation_samples": dict(zip(names, map(float, reference.tau))),
                     "window_s": NOISE_WINDOW_S},
        checks=checks, notes=tuple(notes) + more,
        base_effects=tuple({"name": e.name, "params": {
            p.name: float(getattr(e, p.name)) for p in e.parameters}} for e in base),
        series=held_series[0],
        held_series=held_series)


def params_have_data_map(params: VehicleParams) -> bool:
    """True when the motor map was already fitted from data by the diagnosis."""
    return params.motor_map is not None and "quadsim.gap" in params.motor_map.source


def _weigh(train: list, held: list, reference, *, effects, map_fn, tick) -> list:
    """Every explanation of how the training flights differ from ``reference`` (restricted
    to ``effects`` plus "no difference" and ``nominal_refit``), weighed on the split
    (:func:`weigh`): one call in this process, one task per
    explanation on workers."""
    vbat = None
    if reference.rotor and all(s.vbat is not None and np.all(np.isfinite(s.vbat))
                               for s in train):
        vbat = max(float(np.max(s.vbat)) for s in train)
    expl = heldout_explanations(reference, stack_states(train), vbat=vbat)
    if effects is not None:
        known = {e.name for e in expl} - {"no_difference"}
        unknown = set(effects) - known
        if unknown:
            raise InputError(f"--effects: unknown or unusable effect(s) {sorted(unknown)}; "
                             f"valid: {', '.join(sorted(known))}")
        expl = [e for e in expl if e.name in set(effects) | {"no_difference", "nominal_refit"}]
    weighed = []
    batches = [expl] if map_fn is map else [[e] for e in expl]
    for ws in map_fn(partial(weigh, train, held, reference), batches):
        for w in ws:
            weighed.append(w)
            tick(w.name)
    return weighed


# --- the held-out judgment (module doc) ---------------------------------------------------------

#: the noise model's window (s): the residual's moving average over it is its slow part.
#: 0.5 s: five times the 0.1 s smoothing window (its noise decorrelates within it), shorter
#: than a flight manoeuvre (a figure-8 lap is 4-8 s), so a library effect acting through the
#: flight state is slow against it. The same window as :func:`quadsim.gap.fitting.noise_scale`
#: and :data:`quadsim.gap.judge.SLOW_WINDOW_S`.
NOISE_WINDOW_S = SLOW_WINDOW_S
#: prior spread of the relative drag-torque factor error (module doc, stage 2).
D_PRIOR_SD = 0.5
#: prior spread of the relative thrust factor error: :mod:`.priors` -15 .. +5 %, half the
#: larger end (the rule of :func:`quadsim.gap.explanations.prior_spreads`).
B_PRIOR_SD = 0.075
#: prior spread (V) of a battery's full voltage: +-10 % of a cell's 4.2 V (charge state),
#: as :mod:`.evidence`.
VFULL_PRIOR_SD = 0.42
#: prior spread (s) of a motor time constant: micro motors 10-60 ms (Foerster, ETH 2015:
#: Crazyflie 2.0 ~ 15 ms), as :mod:`.evidence`.
LAG_PRIOR_SD = 0.03

#: groups of the nominal reference: SHARED less motor_lag (time constant 0 is "off" but the
#: Jacobian's forward step would integrate a 0.03 ms lag with 2.5 ms steps), the battery and
#: the thrust curve (the parameter set's b is the hover thrust there; a curve is a reading).
_NOT_SHARED = {"motor_lag", "battery_sag", "thrust_curve"}


def noise_model(nominal: list[np.ndarray], dt: float, floor: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(sigma, tau) per channel from the nominal residuals (N_j, C) of the training flights:
    the robust scatter of their fast part (:func:`quadsim.gap.fitting.noise_scale`, at least
    ``floor``) and the fast part's integrated correlation time (samples)."""
    sigma = noise_scale(np.concatenate(nominal), dt, window_s=NOISE_WINDOW_S, floor=floor)
    fast = [r - slow_part(r, dt) for r in nominal]
    tau = np.array([np.mean([correlation_time(f[:, [c]] / sigma[c]) for f in fast])
                    for c in range(len(sigma))])
    return sigma, tau


def nominal_reference(train: list, params: VehicleParams, rotor: bool,
                      base: tuple = ()) -> Reference:
    """The parameter set as the reference model (module doc, stage 1); ``train``: decimated
    states of the training flights; ``params`` already carries their motor map; ``base``:
    effects already in the model (``--effects-file``), part of every explanation's model
    (carried as the shared candidate's ``base``) and never refitted."""
    dt = float(train[0].t[1] - train[0].t[0])
    nominal = [residuals(s, params, list(base), rotor_channel=rotor) for s in train]
    discrepancy = fit_discrepancy(nominal, train)
    nominal = [r - centre_term(s, discrepancy, r.shape[1]) for r, s in zip(nominal, train)]
    sigma, tau = noise_model(nominal, dt, noise_floor(params, rotor))
    full = shared_candidate(rotor, False, pose=all(s.pose for s in train))
    cand = dataclasses.replace(full, parts=tuple(p for p in full.parts
                                                 if p[0] not in _NOT_SHARED), base=tuple(base))
    off = []
    for name, _, fitted in cand.parts:
        specs = {p.name: p for p in effect_class(name).parameters}
        off += [specs[p].off for p in fitted]
    theta = np.asarray(off, float)
    zeros = np.zeros_like(theta)
    ref = Reference(params, rotor, cand, theta, zeros, zeros.copy(), sigma, tau,
                    np.zeros_like(sigma), 1.0, 1, {}, [], {})
    return dataclasses.replace(ref, discrepancy=discrepancy)


def heldout_explanations(reference: Reference, train_states, names=None,
                         vbat: float | None = None) -> list[Explanation]:
    """Every explanation of how the training flights differ from the parameter set (module
    doc, stage 2). ``vbat``: the highest logged battery voltage (V) when every training
    flight logs one (the full-voltage prior is centred there); ``names``: restrict."""
    from .explanations import prior_spreads

    sd = prior_spreads(reference.params)
    out = [e for e in explanations_for(reference, train_states) if e.name != "wind"]
    # a propeller change with the speed per command held: the reference's static command ->
    # speed map is fitted on these same flights, so it already carries the lighter load's
    # faster spin (the speed exponent alpha would count it twice)
    out = [Explanation("thrust_factor", "", (("thrust_factor", {"alpha": 0.0}, ("change",)),),
                       (0.0,), (sd["thrust_factor.change"],))
           if e.name == "thrust_factor" else e for e in out]
    out.append(Explanation("wind", "", (("wind", {}, ("vx", "vy")),
                                        ("rotor_drag", {}, ("coefficient",))),
                           (0.0, 0.0, 0.0), (sd["wind"], sd["wind"], sd["rotor_drag"]),
                           replaces=("wind", "rotor_drag")))
    out.append(Explanation("nominal_refit", "", (("nominal_refit", {}, ("thrust", "drag")),),
                           (0.0, 0.0), (B_PRIOR_SD, D_PRIOR_SD), replaces=("nominal_refit",)))
    if reference.rotor:
        out.append(Explanation("motor_lag", "", (("motor_lag", {}, ("time_constant",)),),
                               (0.0,), (LAG_PRIOR_SD,)))
        if vbat is not None:
            out = [e for e in out if e.name != "battery_sag"]
            out.append(Explanation("battery_sag", "",
                                   (("battery_sag", {}, ("full_voltage",)),),
                                   (float(vbat),), (VFULL_PRIOR_SD,)))
    if names is not None:     # the parameter set's own b and d always stand
        keep = set(names) | {"no_difference", "nominal_refit"}
        out = [e for e in out if e.name in keep]
    if not getattr(train_states, "pose", True):         # IMU and motors only (.posefree)
        out = [e for e in out if not needs_pose(e.parts)]
    return out


def effects_of(ev: Evidence) -> list:
    """The effects of an explanation at its MAP values."""
    return [build_effect(name, {**fixed, **{p: ev.values[f"{name}.{p}"] for p in fitted}})
            for name, fixed, fitted in ev.explanation.parts]


@dataclass(frozen=True)
class Weighed:
    """One explanation on the split: its training evidence (``train``, an
    :class:`~quadsim.gap.evidence.Evidence`), the same with the held-out log-likelihood added
    (``total``: what the posterior weighs), its residuals (unscaled, (N_j, C) per flight) on
    the training and held-out flights, and its held-out log-likelihood."""

    train: Evidence
    total: Evidence
    train_residuals: list
    held_residuals: list
    held_loglik: float

    @property
    def name(self) -> str:
        return self.train.name


def _beyond(r: np.ndarray, states, reference: Reference) -> tuple[np.ndarray, float]:
    """(residual, log-likelihood) of one flight's residual ``r`` (N, C; the discrepancy's
    centre already off) with the flight's own discrepancy coefficients marginalised, exactly
    (linear-Gaussian: the columns X of :func:`quadsim.gap.discrepancy.columns`, unit prior):
    log L = -1/2 r_wᵀ r_w + 1/2 bᵀ (I + XᵀX)^-1 b - 1/2 log det(I + XᵀX), b = Xᵀ r_w, r_w the
    residual times sqrt(:attr:`Reference.weights`). The residual returned is ``r`` less the
    coefficients' posterior mean X (I + XᵀX)^-1 b (back in channel units): what the flight
    shows beyond its references, the same on training and held-out flights, so that the
    carry-over test compares like with like. Without a discrepancy: ``r`` and
    -1/2 r_wᵀ r_w."""
    root = np.sqrt(reference.weights)
    rw = (r * root).ravel()
    ll = -0.5 * float(rw @ rw)
    if reference.discrepancy is None:
        return r, ll
    x = columns(states, reference.discrepancy, reference.weights)
    a = np.eye(x.shape[1]) + x.T @ x
    b = x.T @ rw
    z = np.linalg.solve(a, b)
    ll += 0.5 * float(b @ z) - 0.5 * float(np.linalg.slogdet(a)[1])
    return r - (x @ z).reshape(r.shape) / root, ll


def weigh(train: list, held: list, reference: Reference, expl: list[Explanation]
          ) -> list[Weighed]:
    """Stage 3 (module doc): training evidence of every explanation, plus its held-out
    log-likelihood at the training MAP. ``train``/``held``: decimated states."""
    # every explanation fully fitted (no screen): its result must not depend on which others
    # share its batch, so that workers and one process give the same bytes
    rows = evaluate(stack_states(train), reference, expl, full=True)
    out = []
    for ev in rows:
        try:
            out.append(check(ev, train, held, reference))
        except ModelError:      # its values make no rigid vehicle: not a reading
            continue
    return out


def check(ev: Evidence, train: list, held: list, reference: Reference) -> Weighed:
    """One explanation's residuals on both sets and its held-out log-likelihood, each
    flight's own discrepancy marginalised (:func:`_beyond`)."""
    effects = list(reference.candidate.base) + effects_of(ev)

    def res(states):
        r = residuals(states, reference.params, effects, rotor_channel=reference.rotor)
        return _beyond(r - centre_term(states, reference.discrepancy, r.shape[1]), states,
                       reference)

    held_res = [res(s) for s in held]
    ll = sum(h[1] for h in held_res)
    return Weighed(ev, dataclasses.replace(ev, log_z=ev.log_z + ll),
                   [res(s)[0] for s in train], [h[0] for h in held_res], ll)


def pair(lead: Weighed, other: Weighed, *, partners: int, train: list, held: list,
         reference: Reference) -> Weighed:
    """The lead fitted together with ``other`` (module doc, stage 4): its prior is the
    lead's with the partner's, less log(partners) (a second simultaneous effect is a priori
    no likelier than the first alone)."""
    a, b = lead.train.explanation, other.train.explanation
    expl = Explanation(f"{a.name}+{b.name}", " ".join(v for v in (a.variant, b.variant) if v),
                       a.parts + b.parts, a.mean + b.mean, a.sd + b.sd,
                       tuple(dict.fromkeys(a.replaces + b.replaces)), None,
                       a.log_prior + b.log_prior - float(np.log(max(1, partners))))
    ev = evaluate(stack_states(list(train)), reference, [expl])[0]
    return check(ev, train, held, reference)


def readings_of(ranked: list, reference: Reference) -> list[Reading]:
    """The posterior as :class:`~quadsim.gap.result.Reading` rows, in held-out words."""
    out = []
    for k, p, w in ranked:
        ev = w.train
        det = [q for q, ok in ev.determined.items() if ok]
        out.append(Reading(k, p, nominal_words(reading_text(ev, reference), k == ev.name),
                           w.total.log_z, {q: ev.values[q] for q in det},
                           {q: 1.96 * ev.post_sd[q] for q in det},
                           tuple(q for q, ok in ev.determined.items() if not ok),
                           ev.explanation.fixed_values, ev.explanation.variant))
    return out


def entry_of(w: Weighed, probability: float, before: list, reference: Reference) -> dict:
    """One ranked explanation as an ``effects`` JSON entry (:mod:`.schema` ``_EFFECT``):
    only determined parameters get values (``undetermined`` names the others); the held-out
    gap (mean squared residual over sigma^2) before (``before``: scaled nominal residuals)
    and after, and its ``reduction`` (gap_before - gap_after) / gap_before."""
    ev = w.train
    sigma = reference.sigma
    gap_before = float(np.mean(np.concatenate(before) ** 2))
    after = [r / sigma for r in w.held_residuals]
    gap_after = float(np.mean(np.concatenate(after) ** 2))
    det = {q for q, ok in ev.determined.items() if ok}
    names = channel_names(reference)
    rms = np.sqrt(np.mean(np.concatenate(w.held_residuals) ** 2, axis=0))
    entry = {"name": ev.name, "probability": probability, "log_evidence": w.total.log_z,
             "params": {q: ev.values[q] for q in ev.values if q in det},
             "ci": {q: 1.96 * ev.post_sd[q] for q in ev.values if q in det},
             "fixed": ev.explanation.fixed_values,
             "identifiable": {q: q in det for q in ev.values},
             "significant": {q: bool(abs(ev.values[q]) > 1.96 * ev.post_sd[q])
                             for q in ev.values},
             "undetermined": sorted(set(ev.values) - det),
             "heldout_gap_before": gap_before, "heldout_gap_after": gap_after,
             "reduction": (gap_before - gap_after) / gap_before if gap_before > 0 else 0.0,
             "heldout_rms_after": dict(zip(names, map(float, rms)))}
    if entry["undetermined"]:
        entry["warning"] = ("too little excitation to fit " + ", ".join(entry["undetermined"])
                            + " on these flights (posterior spread above half the prior's)")
    return entry


def consistent(w: Weighed, entry: dict, flights: list, reference: Reference) -> dict:
    """The consistency check (:func:`quadsim.gap.where.check`) of the reading ``w``
    (its ``effects`` ``entry``) on ``flights`` (decimated states); the propeller's speed
    exponent is held at its value (the library's thrust_factor has none)."""
    ev = w.train
    parts, theta = [], []
    for name, fixed, fitted in ev.explanation.parts:
        keep = tuple(p for p in fitted if not (name == "thrust_factor" and p == "alpha"))
        parts.append((name, dict(fixed), keep))
        theta += [ev.values[f"{name}.{p}"] for p in keep]
    cand = Candidate(ev.name, tuple(parts), reference.candidate.base)
    judged = [q for q in entry["params"] if not q.endswith(".alpha")
              and entry["significant"].get(q)]
    return consistency_check(cand, np.asarray(theta, float), judged, flights,
                             params=reference.params, sigma=reference.sigma,
                             rotor=reference.rotor)


#: how many leads in turn :class:`Practical` measures on the training flights one by one
#: before the ranking stands (each a fit per training flight of one explanation)
PRACTICAL_ROUNDS = 3


class Practical:
    """Held-out practical significance (:mod:`quadsim.gap.selfcheck`, the per-flight rule
    with the training flights as the references): a reading is a difference only when, on
    one of its own determined parameters, its 95 % interval lies beyond
    :data:`quadsim.gap.selfcheck.PRACTICAL_Z` between-flight standard deviations of the same
    reading fitted on each training flight alone, from the no-difference value (the prior's
    centre): ``|v - centre| - 1.96 sd_post > 2 sd_between``. The training flights share the
    gap, so the scale is their spread about no difference, not about their mean. Measured
    lazily (:meth:`rank`): only for the readings that lead, at most
    :data:`PRACTICAL_ROUNDS` of them; none below 3 training flights (no spread to speak
    of: the statistical rule alone)."""

    def __init__(self, train: list, reference: Reference):
        self.train, self.reference = train, reference
        self.spreads: dict = {}

    def negligible(self, ev) -> bool:
        """Whether reading ``ev`` (an Evidence) is within the training flights' spread."""
        return negligible(ev, SelfCheck((), (), (), self.spreads))

    def rank(self, weighed: list) -> list:
        """:func:`quadsim.gap.judge.rank` with practical significance: the lead's spread
        over the training flights measured, then ranked again, until the lead is one
        measured or "no difference"."""
        ranked = rank(weighed, self.negligible)
        for _ in range(PRACTICAL_ROUNDS):
            name, _, lead = ranked[0]
            key = (lead.name, lead.train.explanation.variant)
            if name == "no_difference" or key in self.spreads or len(self.train) < 3:
                break
            self.spreads[key] = self.spread_of(lead)
            ranked = rank(weighed, self.negligible)
        return ranked

    def spread_of(self, w: Weighed) -> dict:
        """Parameter -> :class:`~quadsim.gap.selfcheck.Spread` (centre: the prior's; sd: the
        between-flight SD) of ``w``'s explanation fitted on each training flight alone."""
        expl = w.train.explanation
        per = []
        for states in self.train:
            try:
                per.append(readings(evaluate(states, self.reference, [expl], full=True)))
            except (ModelError, ValueError, np.linalg.LinAlgError):
                continue
        centre = dict(zip(expl.parameter_names, expl.mean))
        out = {}
        for key, s in spreads(per).get((w.name, expl.variant), {}).items():
            out[key] = Spread(float(centre.get(key, 0.0)), s.sd, s.count)
        return out


@dataclass(frozen=True)
class Decision:
    """The weighed explanations of a split, ranked (:func:`decide`): ``ranked`` (reading,
    probability, Weighed), most probable first; ``rows`` its :class:`Reading` rows;
    ``entries`` every explanation as an ``effects`` JSON entry (most probable first);
    ``lead`` and ``lead_name`` the most probable reading; ``null`` the "no difference"
    Weighed; ``combination`` the pair kept as the lead (or None); ``consistency`` the lead's
    check (None for "no difference"); ``implausible`` (name, magnitude, prior) of the
    explanations given no weight."""

    ranked: tuple
    rows: tuple
    entries: tuple
    lead: Weighed
    lead_name: str
    null: Weighed | None
    combination: Weighed | None
    consistency: dict | None
    implausible: tuple

    @property
    def probability(self) -> dict:
        """Reading -> posterior probability."""
        return {k: p for k, p, _ in self.ranked}

    def entry(self, name: str) -> dict | None:
        """The ``effects`` entry of ``name`` (None for "no difference" or one not fitted)."""
        return next((e for e in self.entries if e["name"] == name), None)


def decide(weighed: list[Weighed], *, train: list, held: list, reference: Reference,
           before: list, max_combination: int = 2, tick=None) -> Decision:
    """Rank the weighed explanations; try the lead with a second effect when it leaves a
    systematic remainder or does not carry over (module doc, stage 4); check the lead's
    consistency. ``train``/``held``: decimated states; ``before``: the held-out residuals
    over sigma under the nominal model; ``tick(name)``: progress per pair fitted."""
    params = reference.params
    tick = tick or (lambda *_: None)
    dt = float(train[0].t[1] - train[0].t[0])
    # a value outside its documented plausible range has no prior probability (:mod:`.priors`)
    implausible = []
    for w in weighed:
        ok, text = plausible({q: v for q, v in w.train.values.items()
                              if w.train.determined.get(q)}, params)
        if not ok:
            implausible.append((w, text))
    dropped = {id(w) for w, _ in implausible}
    kept = [w for w in weighed if id(w) not in dropped]
    scale = Practical(train, reference)
    ranked = scale.rank(kept)
    lead_name, _, lead = ranked[0]
    null = next((w for w in weighed if w.name == "no_difference"), None)
    combination = checked = None
    if lead_name != "no_difference":
        checked = consistent(lead, entry_of(lead, 1.0, before, reference), train + held,
                             reference)
    if lead_name != "no_difference" and max_combination >= 2 and checked["consistent"] \
            and (remainder(lead.train_residuals + lead.held_residuals, reference, dt)
                 or carry_over(lead, reference, null)):
        others = [w for k, _, w in ranked if k not in ("no_difference", lead_name)
                  and w.name == k]
        trials = []
        for other in others:
            trials.append(pair(lead, other, partners=len(others), train=train, held=held,
                               reference=reference))
            tick(trials[-1].name)
        best = max(trials, key=lambda w: w.total.log_z, default=None)
        if best is not None:
            stands = every_part_stands(entry_of(best, 0.0, before, reference), params)
            with_pair = scale.rank(weighed + [best])
            if stands and with_pair[0][2] is best:
                ranked, combination = with_pair, best
                lead_name, _, lead = ranked[0]
                checked = consistent(lead, entry_of(lead, 1.0, before, reference),
                                     train + held, reference)
    entries = [entry_of(w, p, before, reference) for k, p, w in ranked if k == w.name
               and k != "no_difference"]
    seen = {e["name"] for e in entries}
    entries += [entry_of(w, 0.0, before, reference) for w in weighed
                if w.name not in seen and w.name != "no_difference" and not seen.add(w.name)]
    entries.sort(key=lambda e: (-e["probability"], -e["log_evidence"], e["name"]))
    return Decision(tuple(ranked), tuple(readings_of(ranked, reference)), tuple(entries),
                    lead, lead_name, null, combination, checked,
                    tuple((w.name, reading_text(w.train, reference), text)
                          for w, text in implausible))
