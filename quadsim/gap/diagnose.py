"""Both modes' entry points: prepare logs into flights; held-out mode (calibrate on the
training flights, judge the held-out ones) and per-flight mode (each flight judged on its own
against the reference flights), both through the one judgment of :mod:`quadsim.gap.judge`.

Preparation and held-out mode
-----------------------------

Held-out mode and the shared preparation: prepare the logs, split by flight, judge.

:func:`prepare` turns logs into :class:`Flight` (smoothed states at the log's rate, the
decimated fit view, signal delays); :func:`diagnose` splits the flights (``holdout`` or
every third flight; one flight: its two halves), takes the parameter set as the reference
model (:func:`nominal_reference`), weighs every explanation
(:func:`weigh`, :func:`decide`), judges
(:func:`quadsim.gap.judge.judge_heldout`) and says where the gap lies (:mod:`.judge`). It
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
Where the flights were flown at different charges (:func:`map_voltage`) that map is read in
command x battery voltage, the law a DC motor follows, so that it transfers to a held-out
flight at another charge; the voltage is then the reference's, and ``battery_sag`` is only a
sag rate beyond it.

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
   (with commands), ``battery_sag`` as a full voltage (with a vbat log and a map in the
   command alone), and
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
   (:mod:`.judge`) -> :class:`Decision`, which :func:`quadsim.gap.judge.judge_heldout`
   turns into the verdict. A reading whose values lie outside their documented plausible
   range is weighed like any other, in both modes: as lead it is named with the caveat of
   :func:`quadsim.gap.judge.lead_caveat` and is tentative, never a confident name (the
   plausible range is a documented prior band, not a zero-probability region: dropping such
   a reading hands its evidence to a worse one). A pair is the one place the range still
   admits or refuses: a pair is a second search, tried only held out, and two effects that
   need implausible sizes usually cancel each other rather than describe the vehicle. So a
   pair is built on the most probable plausible reading (the lead, or the first below an
   implausible lead) with the other plausible readings, and leads where it ranks first.
   Practical significance held out (:class:`Practical`): a reading within the training
   flights' between-flight spread, or one that removes at most
   :data:`quadsim.gap.judge.FORM_ERROR` of the held-out gap, counts as "no difference";
   the verdict states beside the lead every reading the held-out flights do not separate
   from it (:func:`quadsim.gap.judge.unseparated`).

Example::

    >>> result = diagnose(train_logs, params, holdout=held_logs)
    >>> result.verdict.name, result.verdict.probability

Held out against nominal references
-----------------------------------
``diagnose(train, params, holdout=held, reference=nominal)`` (``python -m quadsim.gap TRAIN...
--holdout HELD... --reference NOMINAL...``) asks "what do the training flights share that my
nominal flights do not, and does it carry over to the held-out flights?". "Normal" is then
what the references share, as per flight, not the bare parameter set (which lacks whatever
every flight of the vehicle shares): the reference model is the per-flight one
(:func:`_reference_stage`: calibration, noise model, discrepancy term, self-check; ``store``
keeps it between runs); the training and held-out flights are aligned to its rotor timing,
checked to be of the references' kind and placed on their envelope at the stacked training
flights' place (each training flight also at its own, where its lack of fit against the
references is judged as per flight, :func:`quadsim.gap.judge.against_reference`); the drag
law is chosen on the stacked training flights; the explanations are the per-flight ones
(:class:`Against`). Each is fitted on the stacked training flights
(:func:`quadsim.gap.evidence.evaluate`), then read on every flight at its training MAP
under the per-flight likelihood (the shared parameters it keeps and the flight's own
discrepancy marginalised, :func:`_read`; a reading that fits the rotor timing at each flight's
own delay, that nuisance's prior paid as per flight, :meth:`Against.check`); the held-out
flights' log-likelihood joins its evidence as above. Practical significance is the per-flight
rule: a reading within the references' between-flight spread of it is no difference
(:func:`quadsim.gap.calibrate.negligible` with their self-check; :class:`Practical` takes it
from the reference; ``signal_delay`` is not sized by the held-out gap where "no difference"
took it with each held-out flight's own delay, :meth:`Against.timing_taken`). Beyond the
references' reach (a flight outside their envelope along a coordinate in which they do not
measure how their model's lack of fit grows) the reference model's own error there is weighed
beside each name before the lead is chosen, as per flight (:meth:`Against.split`;
:mod:`.judge`, 1c). Ranking, pairs, consistency (on top of the references' model) and the verdict
(:func:`quadsim.gap.judge.judge_heldout`) are the held-out ones; "before" is the
held-out flights' residual under "no difference" against the references. With fewer than 3
references there is no self-check: the training flights' spread is the scale, as without
references, and the answer says the references could not be checked.

Per-flight mode
---------------

Per-flight mode: each flight judged on its own against nominal reference flights, by
evidence.

Used as ``python -m quadsim.gap --per-flight LOG... --reference NOMINAL...`` or::

    >>> from quadsim.gap import diagnose_per_flight
    >>> result = diagnose_per_flight(flights, nominal_flights, load_params("crazyflie21"))
    >>> [(f.file, f.name, f.probability) for f in result.flights]

Stages (each a named type, each testable alone):

1. ``prepare`` (:mod:`.diagnose`): smoothed states, the decimated view, signal delays.
2. :func:`quadsim.gap.calibrate.calibrate`: the reference model -- nominal parameters plus
   every effect the reference flights share (b, d, motor map, motor lag, rotor drag,
   inertia, rate damping), their uncertainty and between-flight scatter, and the residual
   noise model per channel (RMS, correlation time).
3. :func:`quadsim.gap.evidence.evaluate`: every explanation of how a flight differs (an
   effect, a shared parameter at a value of its own, a signal delay, or none), fitted on the
   whole flight, with its Laplace evidence.
4. :func:`quadsim.gap.judge.judge`: posterior probability per reading, a lack-of-fit test
   against the reference flights ("not in the library"), the answer with magnitudes and what
   separates the leaders -> :class:`quadsim.gap.result.Verdict`.

The result is a :class:`quadsim.gap.result.Diagnosis` (``mode`` ``"per-flight"``).

A flight that cannot be judged (a log the checks refuse, too short to smooth, a rotor count
that is not the model's) gets ``outcome: refused`` with its reason in its own entry; the
others are judged and the summary counts the refusals (the batch goes on).
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache, partial

import numpy as np

from ..core.errors import InputError, ModelError, QuadsimWarning, refuse_moved
from ..logs.delays import align_signal_delays, delay_notes
from ..logs.flightlog import FlightLog
from ..vehicle.params import VehicleParams
from . import evidence, logcheck
from .calibrate import (
    PRACTICAL_Z,
    VBAT_TESTED,
    Calibrated,
    Reference,
    SelfCheck,
    Spread,
    calibrate,
    inverse_information,
    leave_one_out,
    negligible,
    odd_references,
    readings,
    reference_key,
    settled_self_check,
    shared_candidate,
    spreads,
)
from .calibrate import placed as placed_check
from .evidence import Evidence, Explanation, evaluate, explanations_for
from .explanations import TIMING_READINGS, prior_spreads
from .fitting import (
    BASELINE,  # noqa: F401  (re-exported: quadsim.identify, tests)
    START_SWING,
    CableSwing,
    Candidate,
    build_effect,
    correlation_time,
    effect_class,
    noise_floor,
    noise_scale,
    plausible_values,
    residuals,
    stack_states,
)
from .judge import (
    FORM_ERROR,
    SLOW_WINDOW_S,
    as_stated,
    beyond_reach,
    carry_over,
    channel_names,
    every_part_stands,
    form_words,
    heldout_bias,
    heldout_share,
    judge,
    judge_heldout,
    placed_slow,
    plausible,
    rank,
    reading_name,
    reading_text,
    remainder,
    rows_at_reference_voltage,
    scaled_residuals,
    slow_part,
    torque_shrinkage,
    unvouched,
    where,
)
from .judge import check as consistency_check
from .logcheck import (
    check_length,
    check_same_kind,
    confusable_note,
    logged_parts,
    needs_pose,
    posefree_log,
    posefree_states,
    synthesised_timing_note,
    timing_carried,
    vehicle_check,
    without_pose_note,
)
from .page import flight_series
from .reference import centre_term, columns, envelope_summary, fit_discrepancy, local_reference
from .reference import position as envelope_position
from .residual import (
    DEFAULT_WINDOW_S,
    FIT_RATE_HZ,
    FlightStates,
    fit_command_map,
    flight_states,
    joined_states,
    proportional_rotors,
)
from .result import Diagnosis, Reading, Series, Verdict
from .words import (
    across_sessions,
    batch_answer,
    bound_words,
    left_out_words,
    nominal_words,
    refit_words,
    total_mass,
)

__all__ = ["Calibrated", "D_PRIOR_SD", "EDGE_S", "NOISE_WINDOW_S", "SCHEMA", "Decision",
           "Flight", "Weighed",
           "decide", "diagnose", "effects_of", "entry_of", "heldout_explanations", "interior",
           "noise_model", "nominal_reference", "pair", "prepare", "readings_of", "simulable",
           "slow_part",
           "weigh", "MIN_REFERENCE", "WeighedFlight", "diagnose_per_flight", "judge_one",
           "ToJudge",
           "reference_self_check", "reference_summary", "refused_entry", "verdict_of",
           "weigh_flight", "aligned", "OWN_STARTS_FLIGHTS", "fit_own_starts", "joins",
           "own_starts"]


SCHEMA = "quadsim.gap/3"
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
    #: the log's rotor speeds synthesised from its commands (FlightLog.speeds_synthesised)
    speeds_synthesised: bool = False
    #: what the log checks changed in a channel (FlightLog.corrections): in every answer
    corrections: tuple = ()


def interior(t: np.ndarray, edge_s: float | None = None) -> np.ndarray:
    """Indices of the samples of ``t`` (s) at least ``edge_s`` (default :data:`EDGE_S`) from
    both ends (at most :data:`MAX_EDGE_SHARE` of the duration per end)."""
    edge_s = EDGE_S if edge_s is None else edge_s
    margin = min(edge_s, MAX_EDGE_SHARE * (t[-1] - t[0]))
    return np.nonzero((t >= t[0] + margin) & (t <= t[-1] - margin))[0]


def prepare(logs: Sequence[FlightLog], params: VehicleParams, *,
            window_s: float = DEFAULT_WINDOW_S) -> list[Flight]:
    """Check each log against the model and smooth it (:func:`quadsim.gap.residual.flight_states`).

    The first and last :data:`EDGE_S` = 0.2 s of each log (scaled by ``window_s`` over
    :data:`DEFAULT_WINDOW_S` where that is wider: 0.84 s for a band's 0.42 s,
    :func:`quadsim.gap.logcheck.band_of`; at most
    :data:`MAX_EDGE_SHARE` = 10 % of its duration per end) are dropped after smoothing:
    there the derived signals are not valid (one-sided Savitzky–Golay derivatives, filter
    transients; 0.2 s covers the smoothing window twice over and a zero-phase low-pass down
    to 5 Hz, whose transient decays to 1 % in ~1.04 / f_c).

    Raises :class:`InputError` for a rotor-count mismatch, logs without rotor speeds or
    shorter than :data:`quadsim.gap.logcheck.MIN_LOG_S` (2 s)."""
    out = []
    for log in logs:
        name = str(log.path) if log.path is not None else f"log{len(out)}"
        if log.rotor_speed is None:
            what = "commands only" if log.rotor_command is not None else "neither"
            raise InputError(f"{name}: rotor_1..rotor_N: the diagnosis needs measured rotor "
                             f"speeds (this log has {what}); the residual wrench compares the "
                             "motion with the thrust of the measured rotors (with commands: "
                             "--command-reference LOG... synthesises speeds, quadsim.gap.logcheck)")
        if log.rotor_count != params.rotor_count:
            raise InputError(f"{name}: rotor_1..rotor_N: {log.rotor_count} rotors in the log, "
                             f"the model {params.name!r} has {params.rotor_count}")
        check_length(log, name=name)              # >= MIN_LOG_S, else one line naming t
        # each airborne stretch alone (quadsim.gap.residual); delays: the longest stretch's
        parts = [align_signal_delays(p) for p in log.parts()]   # quadsim.logs.delays
        delays = max(parts, key=lambda part: len(part[0].t))[1]
        step = None if len(parts) == 1 else float(np.median(np.diff(log.t)))
        pieces = [flight_states(p if p.has_pose else posefree_log(p), window_s=window_s,
                                gravity=params.gravity, dt=step) for p, _ in parts]
        if not log.has_pose:     # IMU and motors only: the stand-in pose (quadsim.gap.logcheck)
            pieces = [posefree_states(s, log.has_attitude, params.gravity) for s in pieces]
        # a band's wider window (quadsim.gap.logcheck.band_of) widens the edges alike
        pieces = [s.take(interior(s.t, EDGE_S * max(1.0, window_s / DEFAULT_WINDOW_S)))
                  for s in pieces]
        if log.speeds_synthesised:      # model speeds: an upstream effect acts on them
            pieces = [dataclasses.replace(s, synthesised=True) for s in pieces]
        states = joined_states(pieces)
        dt = float(states.t[1] - states.t[0])
        stride = max(1, round(1.0 / (FIT_RATE_HZ * dt)),
                     int(np.ceil(len(states.t) / MAX_FIT_SAMPLES_PER_FLIGHT)))
        fit = joined_states([decimated(s, stride) for s in pieces])
        out.append(Flight(name, states, fit, delays.ms(), delays.notes,
                          speeds_synthesised=log.speeds_synthesised,
                          corrections=log.corrections))
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
    from ..logs.zerophase import sosfiltfilt0  # scipy's sosfiltfilt, its zi kept

    signals = [(name, np.asarray(value)) for name in _LOW_PASSED
               if (value := getattr(states, name)) is not None]
    # every signal's columns filtered side by side in one call: sosfiltfilt0 filters each
    # column on its own, so the same numbers as one call per signal, at one call's overhead
    widths = [value.reshape(len(value), -1).shape[1] for _, value in signals]
    low = sosfiltfilt0(_anti_alias_sos(stride),
                       np.hstack([value.reshape(len(value), -1) for _, value in signals]))
    ends = np.cumsum(widths)
    low_passed = dataclasses.replace(states, **{
        name: low[:, end - width:end].reshape(value.shape)
        for (name, value), width, end in zip(signals, widths, ends)})
    return low_passed.take(np.arange(0, len(states.t), stride))


#: the signals :func:`decimated` low-passes (every one but ``t`` and the quaternion)
_LOW_PASSED = ("position", "velocity", "accel_world", "body_rate", "body_accel",
               "specific_force", "rotor_speed", "rotor_accel", "command", "vbat")


@lru_cache(maxsize=16)
def _anti_alias_sos(stride: int) -> np.ndarray:
    """:func:`decimated`'s filter for ``stride`` (>= 2): the second-order sections of
    ``scipy.signal.butter(4, ANTI_ALIAS / stride, output="sos")``, read-only; designed once
    per stride (the same numbers each call)."""
    from scipy.signal import butter

    sos = butter(4, ANTI_ALIAS / stride, output="sos")
    sos.setflags(write=False)
    return sos


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


@dataclass(frozen=True)
class _Weighing:
    """Held-out mode's weighed split (:func:`diagnose`): the parameter set as used (with
    the training flights' command map, or the references'), the reference model, the
    training and held-out fit states, every explanation :class:`Weighed`, the held-out
    residuals over sigma under the reference model (``before``), the references' side
    (:class:`Against`, or None for the bare set) and the notes the stage adds."""

    params: VehicleParams
    reference: Reference
    train: tuple
    held: tuple
    weighed: tuple
    before: list
    against: object = None
    notes: tuple = ()


def _weighed_against(train, held, reference_logs, params: VehicleParams, *, effects,
                     window_s: float, base: tuple, store, map_fn, progress) -> _Weighing:
    """The split weighed against nominal reference flights (module doc, "Held out against
    nominal references"): their per-flight stage (``store`` keeps it), the flights aligned
    and placed on it, every explanation weighed on the training flights and read on all."""
    stage = calibrated_stage(reference_logs, params, effects=effects, window_s=window_s,
                             base=base, store=store, map_fn=map_fn)
    if progress is not None:
        progress("reference")
    against = against_references(train, held, stage.reference, effects=effects)
    ref = against.reference
    weighed = _weigh_against(against, map_fn=map_fn, tick=progress or (lambda *_: None))
    null = next(w for w in weighed if w.name == "no_difference")
    return _Weighing(stage.reference.params, ref, tuple(against.train), tuple(against.held),
                     tuple(weighed), [r / ref.sigma for r in null.held_residuals], against,
                     tuple(_stage_notes(stage)))


def _weighed_bare(train, held, params: VehicleParams, rotor: bool, *, effects, base: tuple,
                  map_fn, progress) -> _Weighing:
    """The split weighed against the parameter set itself (module doc, stage 1-3), its
    command map fitted on the training flights (in command x voltage where they were flown
    at different charges, :func:`map_voltage`; in the set's own shape where the set has a
    map, :func:`training_map`)."""
    notes = []
    if rotor and not params_have_data_map(params):
        volts = map_voltage([f.fit for f in train], [f.fit for f in held])
        params = training_map([f.fit for f in train], params, duty_voltage=volts)
        if volts is not None and not declares_voltage_law(params):
            notes.append(f"command map in command x battery voltage (read at {volts:.3f} V, "
                         "the training flights' mean; the flights were flown at different "
                         "charges): a DC motor's speed follows duty x voltage")
    fit_on, held_on = [f.fit for f in train], [f.fit for f in held]
    reference = nominal_reference(fit_on, params, rotor, base)
    weighed = _weigh(fit_on, held_on, reference, effects=effects, map_fn=map_fn,
                     tick=progress or (lambda *_: None))
    sigma = reference.sigma
    before = [_beyond(b * sigma - centre_term(h, reference.discrepancy, len(sigma)), h,
                      reference)[0] / sigma for b, h in
              zip(scaled_residuals(held_on, params, list(base), sigma, rotor=rotor), held_on)]
    return _Weighing(params, reference, tuple(fit_on), tuple(held_on), tuple(weighed), before,
                     None, tuple(notes))


def diagnose(logs: Sequence[FlightLog], params: VehicleParams, *,
             holdout: Sequence[FlightLog] | None = None, effects: Sequence[str] | None = None,
             max_combination: int = 2, progress: Callable | None = None,
             window_s: float = DEFAULT_WINDOW_S, kstep: bool = True,
             map_fn: Callable = map, base_effects: Sequence = (),
             reference: Sequence[FlightLog] | None = None, store=None) -> Diagnosis:
    """Diagnose the gap between ``params`` and ``logs`` (see :mod:`quadsim.gap`): a
    :class:`~quadsim.gap.result.Diagnosis` (``mode`` ``"held-out"``).

    ``holdout``: the held-out logs (default: every third of ``logs``); ``effects``: restrict
    the candidate effects (unknown names: :class:`InputError`); ``max_combination`` >= 2
    lets a second effect join the lead; ``progress(name)`` is called per fit;
    ``window_s`` (s): the smoothing window; ``kstep=False`` skips the k-step prediction
    errors (the slowest part of "where"); ``map_fn(fn, items)`` runs the candidate fits
    (e.g. a :mod:`quadsim.core.executor` executor). ``base_effects``: effects already in
    the model (an effect file, :mod:`quadsim.effects.effectfile`): the "before" gap is
    theirs, every candidate is fitted on top of them, and they are never refitted.
    ``reference``: nominal reference flights (module doc, "Held out against nominal
    references"): the reference model is theirs, calibrated as per flight
    (``store``: keeps that stage between runs, as :func:`diagnose_per_flight`'s), and the
    question is what the training flights share that the references do not, and whether it
    carries over to the held-out flights; None: the parameter set is the reference; a
    :class:`Calibrated`: that stage, already computed (the CLI's cache)."""
    notes: list[str] = []
    flights = prepare(logs, params, window_s=window_s)
    held_in = prepare(holdout, params, window_s=window_s) if holdout else None
    checks = vehicle_check([f.fit for f in flights + (held_in or [])], params)
    notes.extend(delay_notes(flights + (held_in or [])))
    notes.extend(f"{f.name}: {c}" for f in flights + (held_in or []) for c in f.corrections)
    train, held = _split(flights, held_in, notes)
    base = tuple(base_effects)
    rotor = all(f.fit.command is not None for f in train + held)
    if reference is not None:
        w = _weighed_against(train, held, reference, params, effects=effects,
                             window_s=window_s, base=base, store=store, map_fn=map_fn,
                             progress=progress)
    else:
        w = _weighed_bare(train, held, params, rotor, effects=effects, base=base,
                          map_fn=map_fn, progress=progress)
    params, reference, against = w.params, w.reference, w.against
    fit_on, held_on, weighed, before = list(w.train), list(w.held), list(w.weighed), w.before
    notes += list(w.notes)
    sigma = reference.sigma
    decision = decide(weighed, train=fit_on, held=held_on, reference=reference,
                      before=before, max_combination=max_combination,
                      tick=progress or (lambda *_: None), against=against)
    lead = decision.lead
    model = list(base) if against is None else against.model(None)
    effects_after = (model if against is None else against.model(lead.train.explanation)) + (
        effects_of(lead.train) if decision.lead_name != "no_difference" else [])
    after = [r / sigma for r in lead.held_residuals] if effects_after else before
    dt = float(fit_on[0].t[1] - fit_on[0].t[0])
    statuses = logcheck.order_statuses(list(logs) + list(holdout or []), params)
    decision = logcheck.cap_decision(decision, logcheck.probability_cap(statuses))
    verdict, more = judge_heldout(decision, reference, before=before, after=after, dt=dt,
                                  references=against is not None,
                                  placed=() if against is None else against.placed,
                                  flown=() if against is None else against.flown)
    verdict = logcheck.mark(verdict, statuses)
    if against is not None:
        verdict = dataclasses.replace(verdict, answer=verdict.answer + against.words())
    posefree = next((g for g in logs if not g.has_pose), None)
    if posefree is not None:                  # what a pose would add (quadsim.gap.logcheck)
        verdict = without_pose_note(verdict, posefree)
    else:                                     # a declared pair the data do not separate
        verdict = confusable_note(verdict, (list(logs) + list(holdout or []))[0])
    verdict = synthesised_timing_note(verdict, list(logs) + list(holdout or []))
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
                    effects_after=simulable(effects_after), base=simulable(model),
                    kstep=kstep),
        effects=decision.entries, baseline=decision.entry("nominal_refit") or {},
        combination=combination,
        noise_model={"sigma": dict(zip(names, map(float, sigma))),
                     "correlation_samples": dict(zip(names, map(float, reference.tau))),
                     "window_s": NOISE_WINDOW_S},
        checks=checks, notes=tuple(notes) + more,
        base_effects=base_json(base),
        series=held_series[0],
        held_series=held_series,
        **({} if against is None else {
            "reference": tuple(against.reference.names),
            "reference_model": reference_summary(against.calibrated)}))


# --- held out against nominal references (module doc) --------------------------------------

#: the gap (s) between two training flights' time axes when they are stacked against
#: references (:func:`against_references`): their time axis then only rises, so a rotor
#: timing read later (:func:`quadsim.gap.reference.read_later`, by interpolation on a
#: non-uniform base) stays within one flight but within one step of a join, as with the
#: airborne stretches of one log (:mod:`quadsim.gap.residual`)
STACK_GAP_S = 1.0


def _stacked(states: list):
    """The training flights as one sample set on a rising time axis (:data:`STACK_GAP_S`
    between flights; :func:`quadsim.gap.fitting.stack_states`)."""
    moved, end = [], None
    for s in states:
        shift = 0.0 if end is None else end + STACK_GAP_S - float(s.t[0])
        moved.append(s if shift == 0.0 else dataclasses.replace(s, t=s.t + shift))
        end = float(moved[-1].t[-1])
    return stack_states(moved)


def joins(states: Sequence) -> tuple[int, ...]:
    """The index of each later flight's first sample when ``states`` (one flight's fit
    states each) are stacked (:func:`_stacked`, :func:`quadsim.gap.fitting.stack_states`:
    both keep every sample, in order); empty for one flight."""
    return tuple(int(k) for k in np.cumsum([len(s.t) for s in states])[:-1])


#: most training flights whose stacked fit starts each at its own cable swing
#: (:func:`fit_own_starts`); with more, the later ones start hanging still (one start, the
#: first flight's). Each later flight adds 4 columns to every cable fit's finite-difference
#: Jacobian, each an evaluation of the residual over all the stacked flights, so the cost
#: grows as the square of their number: on two real training flights the cable
#: explanations' fits and reads took 2x; on 14 (the shipped set's 20 nominal flights held
#: out) the whole run took 184 s CPU against 52 s (benchmarks/README.md, "Payload
#: under-read"). 4: a payload campaign's few training flights, the Jacobian at most 2.5x.
OWN_STARTS_FLIGHTS = 4


def own_starts(expl: Explanation, flights: int) -> bool:
    """Whether the stacked fit of ``expl`` on ``flights`` training flights starts each at its
    own cable swing (:func:`fit_own_starts`): a cable payload fitted with its start swing,
    on 2 to :data:`OWN_STARTS_FLIGHTS` flights."""
    return bool(_start_groups(expl)) and 1 < flights <= OWN_STARTS_FLIGHTS


def _start_groups(expl: Explanation) -> list[list[int]]:
    """Per ``cable_payload`` part of ``expl`` that fits its whole start swing
    (:data:`START_SWING`), the indices of those four parameters (in that order)."""
    out, k = [], 0
    for name, _, fitted in expl.parts:
        if name == "cable_payload" and set(START_SWING) <= set(fitted):
            out.append([k + list(fitted).index(p) for p in START_SWING])
        k += len(fitted)
    return out


def fit_own_starts(inputs, expl: Explanation, start_delay_s: float, *,
                   at: tuple) -> Evidence:
    """:func:`quadsim.gap.evidence.full_fit` of ``expl`` on stacked flights (``inputs``;
    ``at``: each later flight's first sample, :func:`joins`), a cable payload's swing at
    each later flight's first sample that flight's own (:data:`START_SWING`; the
    explanation's own start is the first flight's): 4 nuisance parameters per later flight
    and cable, each with the explanation's prior of its start (:data:`START_PRIOR`, bounds
    and centre alike), fitted jointly with the explanation by the same trust-region least
    squares (:data:`quadsim.gap.evidence.FULL_FIT_EVALUATIONS`, step
    :data:`~quadsim.gap.evidence.FULL_FIT_STEP`) on the same cost, the starts' z appended
    (:meth:`quadsim.gap.evidence.Problem.stacked`). The evidence integrates them out
    (Laplace): the explanation's posterior precision is the Schur complement
    H_pp - H_ps H_ss^-1 H_sp of the joint one, and log Z gains -1/2 log det H_ss (with the
    rest: -1/2 log det H of the joint precision); a value at a bound counts as in
    :func:`quadsim.gap.evidence.laplace`; a fit that met the wall of values that make no
    vehicle takes its joint Jacobian again with no difference across the wall, as the
    full fit does (:func:`quadsim.gap.evidence.fitted_jacobian`). The Evidence names the
    explanation's parameters only. Without a start swing, a later flight, or with more than
    :data:`OWN_STARTS_FLIGHTS` flights (:func:`own_starts`): ``full_fit`` unchanged. Joint, not
    profiled: a start fitted inside each outer evaluation would cost its own fit (tens of
    evaluations) per evaluation of the outer fit, and its finite-difference Jacobian would
    differentiate an inner fit's tolerance; jointly each later flight adds 4 columns to the
    outer fit's Jacobian (4 evaluations of the stacked residual per step)."""
    from scipy.optimize import least_squares

    from .evidence import FULL_FIT_EVALUATIONS, FULL_FIT_STEP, Problem, fitted_jacobian, laplace

    if not own_starts(expl, len(at) + 1):
        return off_the_wall(inputs, expl, evidence.full_fit(inputs, expl, start_delay_s))
    prob = Problem(inputs.states, inputs.reference, expl, inputs.jac, inputs.s_all)
    joint = OwnStarts(prob, at)
    n = len(prob.mean)
    z0 = np.concatenate([prob.start(start_delay_s),
                         np.clip(np.zeros(len(joint.z_lo) - n), joint.z_lo[n:] + 1e-6,
                                 joint.z_hi[n:] - 1e-6)])
    fit = least_squares(joint.stacked, z0, bounds=(joint.z_lo, joint.z_hi),
                        diff_step=FULL_FIT_STEP, max_nfev=FULL_FIT_EVALUATIONS, method="trf")
    # the wall of values that make no vehicle: no difference across it (as full_fit's)
    vec, jac, at_bound = fitted_jacobian(joint, fit, FULL_FIT_STEP)
    h = jac.T @ jac
    h_ss = h[n:, n:]
    sign, logdet_ss = np.linalg.slogdet(h_ss)
    if sign > 0:
        h_own = h[:n, :n] - h[:n, n:] @ np.linalg.solve(h_ss, h[n:, :n])
    else:           # the fit ended on the wall (a zero Jacobian): no evidence
        h_own, logdet_ss = h[:n, :n], np.inf
    ev = laplace(prob, fit.x[:n], vec, h_own, at_bound)
    return dataclasses.replace(ev, log_z=ev.log_z - 0.5 * logdet_ss)


class OwnStarts:
    """The joint fit of :func:`fit_own_starts`: ``prob``'s explanation (z, P values) and a
    cable payload's start swing at each later flight's first sample (``at``, :func:`joins`),
    4 per cable part and later flight (:data:`START_SWING`, each with the explanation's
    prior of its start: centre, spread and bounds), appended in the order (cable, later
    flight, START_SWING). ``stacked(zz)``: (profiled residual, marginalised shifts, zz),
    :meth:`quadsim.gap.evidence.Problem.stacked` with the starts; 1e3 per entry where the
    values make no vehicle (ModelError), counted in ``walls``; ``z_lo``, ``z_hi``: the
    bounds of zz. The fields :func:`quadsim.gap.evidence.fitted_jacobian` reads."""

    def __init__(self, prob, at: tuple):
        self.prob, self.at = prob, tuple(at)
        self.groups = _start_groups(prob.expl)
        self.idx = [k for g in self.groups for _ in self.at for k in g]
        # which of the explanation's own effects (one per part) are the groups' cables
        self.starting = [name == "cable_payload" and set(START_SWING) <= set(fitted)
                         for name, _, fitted in prob.expl.parts]
        self.z_lo = np.concatenate([prob.z_lo, prob.z_lo[self.idx]])
        self.z_hi = np.concatenate([prob.z_hi, prob.z_hi[self.idx]])
        self.walls = 0

    def effects(self, zz: np.ndarray) -> tuple[np.ndarray, list]:
        """(the explanation's values theta (SI), its own effects with each cable's
        restarts) at ``zz``; raises ModelError where they make no vehicle."""
        from .explanations import own_effects
        from .fitting import Restart

        prob, idx, n = self.prob, self.idx, len(self.prob.mean)
        theta = np.clip(prob.mean + prob.sd * zz[:n], prob.lower, prob.upper)
        starts = np.clip(prob.mean[idx] + prob.sd[idx] * zz[n:], prob.lower[idx],
                         prob.upper[idx]).reshape(len(self.groups), len(self.at), 4)
        cables = iter(tuple(Restart(a, (float(v[0]), float(v[1])), (float(v[2]), float(v[3])))
                            for a, v in zip(self.at, rows)) for rows in starts)
        own = [CableSwing(restarts=next(cables), **e.values()) if mine else e
               for e, mine in zip(own_effects(prob.expl, theta), self.starting)]
        return theta, own

    def stacked(self, zz: np.ndarray) -> np.ndarray:
        """The joint fit's vector at ``zz`` (its squared norm the cost; class doc)."""
        from .evidence import flight_residual

        prob, n = self.prob, len(self.prob.mean)
        try:
            theta, own = self.effects(zz)
            flight = prob.shifted(float(theta[n - 1])) if prob.expl.shift else prob.states
            r = flight_residual(flight, prob.reference, prob.shared + own, prob.memo)
        except ModelError:
            self.walls += 1
            return np.full(prob.size + len(self.idx), 1e3)
        aug, du = prob.marg.profile(r)
        return np.concatenate([aug, du, zz])


def turned_jacobian(stacked: Callable, z: np.ndarray, *, bounds: tuple, crosses: Callable,
                    step: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """(the stacked vector at ``z``, its forward-difference Jacobian (len, P), whether ``z``
    lies within one step of a wall): column k by a step of ``step`` max(1, |z_k|) (the full
    fit's ``diff_step``, relative, as the trust-region solver takes it), forward, turned
    back where it would leave the box ``bounds`` (lower, upper; each (P,)) or where
    ``crosses(k, h)`` says the step h on z_k crosses a wall of values that make no vehicle;
    "near" where a step either way would cross it. A difference taken across such a wall
    meets its constant penalty (:meth:`quadsim.gap.evidence.Problem.stacked`) and gives a
    column of ~1e3 / step."""
    lower, upper = bounds
    base = stacked(z)
    jac = np.empty((base.size, len(z)))
    near = False
    for k in range(len(z)):
        h = step * max(1.0, abs(float(z[k])))
        near = near or crosses(k, h) or crosses(k, -h)
        if z[k] + h > upper[k] or crosses(k, h):
            h = -h
        at = z.copy()
        at[k] += h
        jac[:, k] = (stacked(at) - base) / h
    return base, jac, near


def off_the_wall(inputs, expl: Explanation, ev: Evidence) -> Evidence:
    """``ev`` (:func:`quadsim.gap.evidence.full_fit` of ``expl`` on ``inputs``) with its
    Laplace evidence taken again where its MAP lies within one finite-difference step of
    the inertia's triangle inequality (:class:`quadsim.gap.evidence.InertiaWall`): the
    Jacobian by :func:`turned_jacobian` (no step across the wall) and the wall counted as
    a bound (half the Laplace volume), as the screen's refined fit counts it
    (:func:`quadsim.gap.evidence.linear_step`). ``ev`` itself where no inertia error is fitted
    or no step reaches the wall. Why: the solver's own differences at such a MAP cross the
    wall (a relative step of a negative value goes down), so every spread it gave was the
    wall's, not the data's."""
    from .evidence import FULL_FIT_STEP, Problem, inertia_wall, laplace

    prob = Problem(inputs.states, inputs.reference, expl, inputs.jac, inputs.s_all)
    if not len(prob.mean):
        return ev
    theta = np.array([ev.values[k] for k in expl.parameter_names], float)
    z = (theta - prob.mean) / prob.sd
    wall = inertia_wall(prob, z)
    if wall is None:
        return ev

    def crosses(k: int, h: float) -> bool:
        return wall.crossed(wall.g0 + wall.g[:, k] * h)

    steps = FULL_FIT_STEP * np.maximum(1.0, np.abs(z))
    if not any(crosses(k, h) or crosses(k, -h) for k, h in enumerate(steps)):
        return ev           # (checked before any residual is evaluated: most fits)
    vec, jac, _ = turned_jacobian(prob.stacked, z, bounds=(prob.z_lo, prob.z_hi),
                                  crosses=crosses, step=FULL_FIT_STEP)
    box = int(np.count_nonzero((z <= prob.z_lo + 1e-9) | (z >= prob.z_hi - 1e-9)))
    return laplace(prob, z, vec, jac.T @ jac, box + 1)


def _problem(states, reference: Reference, expl: Explanation, memo: dict):
    """``expl``'s :class:`quadsim.gap.evidence.Problem` on one flight against ``reference``,
    the flight's Jacobian in the shared parameters kept in ``memo`` (as
    :func:`quadsim.gap.evidence.evaluate` keeps it)."""
    from .evidence import FitInputs
    from .explanations import marginal_sd
    from .reference import jacobian

    kept = memo.get("evidence.jacobian")
    if kept is None or kept[0] is not states or kept[1] is not reference:
        names = reference.candidate.parameter_names
        kept = memo["evidence.jacobian"] = (states, reference, jacobian(
            states, reference, list(range(len(names))), reference.candidate.effects,
            memo=memo))
    return FitInputs(states, reference, kept[2], marginal_sd(reference), memo).problem(expl)


def _read(prob, theta: np.ndarray) -> tuple[np.ndarray, float]:
    """(residual (N, C) in channel units, log-likelihood) of one flight at an explanation's
    values ``theta`` (its SI units), the per-flight likelihood: the shared parameters it
    keeps and the flight's own discrepancy coefficients marginalised (linear-Gaussian,
    :class:`quadsim.gap.evidence.Marginal`): log L = -1/2 (|r + j du|^2 + |du|^2)
    - 1/2 log det A at the profiled shift du, r the weighted residual. The residual is
    r + j du back in channel units (what the flight shows beyond its references, as
    :func:`quadsim.page.flight_series` draws it)."""
    z = (np.asarray(theta, float) - prob.mean) / prob.sd
    aug, du = prob.marg.profile(prob.residual(z))
    ll = -0.5 * float(aug @ aug + du @ du) - 0.5 * prob.marg.logdet
    weights = prob.reference.weights
    return aug.reshape(-1, len(weights)) / np.sqrt(weights), ll


#: most residual evaluations of one flight's start-swing fit (:func:`_read_own_start`):
#: 4 parameters, a 2-point Jacobian (5 per step); from hanging still it took 4-11 on
#: generated flights (tests/test_heldout_references.py), so 40 is about 8 steps
START_FIT_EVALS = 40


def start_swing_index(expl: Explanation) -> list[int]:
    """Indices in ``expl``'s parameters of a cable payload's start swing
    (:data:`START_SWING`, in the order of :func:`quadsim.gap.explanations.own_effects`);
    empty for an explanation without one."""
    out, k = [], 0
    for name, _, fitted in expl.parts:
        for p in fitted:
            if name == "cable_payload" and p in START_SWING:
                out.append(k)
            k += 1
    return out


def _read_own_start(prob, theta: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`_read` of one flight at ``theta``, a cable payload's swing at the flight's
    first sample (:data:`START_SWING`) that flight's own: fitted on it as a nuisance, every
    other value held at ``theta`` (mass, length, damping: the reading's), by least squares
    on the fit's cost (:meth:`quadsim.gap.evidence.Problem.stacked`: the profiled residual,
    the marginalised shifts and the prior in z, the start's spread
    :data:`quadsim.gap.fitting.START_PRIOR`) from hanging still (z = 0). The stacked fit's
    starts (:func:`fit_own_starts`) are integrated out there, not kept, and a held-out
    flight has none: each flight's own is fitted here alike. The log-likelihood adds the
    start's prior -1/2 |z_start|^2 (a penalised profile: the start is not marginalised).
    Without a start swing: :func:`_read` unchanged."""
    idx = start_swing_index(prob.expl)
    if not idx:
        return _read(prob, theta)
    from scipy.optimize import least_squares

    z_all = (np.asarray(theta, float) - prob.mean) / prob.sd
    lo, hi = prob.z_lo[idx] + 1e-6, prob.z_hi[idx] - 1e-6

    def cost(zs):
        z = z_all.copy()
        z[idx] = zs
        return prob.stacked(z)

    got = least_squares(cost, np.clip(np.zeros(len(idx)), lo, hi), bounds=(lo, hi),
                        max_nfev=START_FIT_EVALS)
    at = np.array(theta, float)
    at[idx] = prob.mean[idx] + prob.sd[idx] * got.x
    resid, ll = _read(prob, at)
    return resid, ll - 0.5 * float(got.x @ got.x)


@dataclass(frozen=True)
class Against:
    """Held out against nominal references (:func:`against_references`): ``calibrated``
    the references' model (:func:`quadsim.gap.calibrate.calibrate`, with its self-check);
    ``reference`` the same at the training flights' place
    (:func:`quadsim.gap.reference.local_reference`); ``train``/``held`` the flights' fit
    states aligned to the references' rotor timing; ``stacked`` the training states as
    one (:func:`_stacked`); ``start`` (s) the training flights' mean rotor delay against the
    references' (where the delay fits start); ``delays`` (s, per flight, training then
    held out; None without a timing reading) each flight's own rotor delay under "no
    difference" (:func:`quadsim.gap.evidence.delay_starts`): where every reading but
    ``signal_delay`` reads that flight; ``law`` the drag law the training flights show
    (None: the references'); ``place`` their envelope position; ``explanations`` the
    per-flight explanations under that law; ``memos`` the residual parts kept per flight
    (the stacked training flights' last); ``placed`` each training flight's reference model
    at its own place (:func:`quadsim.gap.reference.local_reference`, as per flight: the
    lack of fit against the references, :func:`quadsim.gap.judge.against_reference`),
    ``flown`` each training flight in words (its name, and its place outside the
    references' envelope) and ``reaches`` each flight's (training, then held out)
    :class:`quadsim.gap.reference.Reach` in ``reference``'s noise scale (None within reach:
    :func:`quadsim.gap.judge.heldout_share`)."""

    calibrated: Reference
    reference: Reference
    train: tuple
    held: tuple
    stacked: object
    start: float
    delays: tuple
    law: object
    place: object
    explanations: tuple
    memos: tuple = field(compare=False, repr=False)
    placed: tuple = field(default=(), compare=False, repr=False)
    flown: tuple = ()
    reaches: tuple = field(default=(), compare=False, repr=False)

    @property
    def reach(self):
        """The flights' :class:`quadsim.gap.reference.Reach` lying furthest beyond the
        references (the answer's words, :func:`quadsim.gap.words.reach_words`); None where
        every flight is within reach."""
        return max((r for r in self.reaches if r is not None), key=lambda r: r.excess,
                   default=None)

    def split(self, ranked: list) -> tuple[list, dict]:
        """:func:`quadsim.gap.judge.beyond_reach` of the held-out posterior ``ranked``
        ((reading, p, Weighed)): beyond the references' reach a reading's weight counts the
        reference model's own error there as no difference, over every flight its evidence
        counts (:func:`quadsim.gap.judge.heldout_share`), as per flight."""
        return beyond_reach(ranked, self.reach, share=partial(
            heldout_share, reaches=self.reaches, sigma=self.reference.sigma))

    def bias(self, w: Weighed, null: Weighed | None) -> float:
        """The bias bound (standard errors) the reading ``w``'s stated intervals include
        beyond the references' reach (:func:`quadsim.gap.judge.heldout_bias`: what each
        flight, training and held out at its own allowance, earns against "no difference"
        ``null``, as :meth:`split` weighs it; 0 within reach)."""
        return heldout_bias(w, null, reaches=self.reaches, sigma=self.reference.sigma)

    def weigh(self, expl: list, null: Explanation | None = None) -> list[Weighed]:
        """Each of ``expl`` fitted on the stacked training flights (every one fully,
        :func:`quadsim.gap.evidence.evaluate`; a cable payload with each flight's own start
        swing, :func:`fit_own_starts`), then read on every flight
        (:meth:`check`); a fit that ends where no rigid vehicle is gives no reading.
        ``null``: "no difference", fitted first and dropped: the rotor delay's fits start
        where the evaluation reads them from it, on the grid of the whole
        :attr:`explanations` (its "signal_delay"'s wide spread, whether or not ``expl``
        holds it: :func:`quadsim.gap.evidence.evaluate`'s ``signal_sd``), so that one
        explanation per worker gives the numbers of the whole list in one call."""
        first = [] if null is None else [null]
        wide = next((e for e in self.explanations if e.name == "signal_delay"), None)
        rows = evaluate(self.stacked, self.reference, first + list(expl),
                        start_delay_s=self.start, full=True, memo=self.memos[-1],
                        fit=partial(fit_own_starts, at=joins(self.train)),
                        signal_sd=float(wide.sd[-1]) if wide is not None else 0.0)[len(first):]
        out = []
        for ev in rows:
            if not np.isfinite(ev.log_z):
                continue
            try:
                out.append(self.check(ev))
            except ModelError:
                continue
        return out

    def check(self, ev: Evidence) -> Weighed:
        """One explanation read on each flight at its training MAP (:func:`_read`): its
        residuals beyond the references on the training and held-out flights, and the
        held-out flights' log-likelihood. A reading that fits the rotor timing reads each
        flight at that flight's own delay (:attr:`delays`; the timing is a nuisance, as
        per flight), its log-likelihood less the nuisance's prior -1/2 ((d - mu) / s)^2
        (mu, s: the delay's prior, the references' timing and spread; a penalised profile,
        as the per-flight fit pays it: a flight's own delay far outside the references'
        spread is the difference ``signal_delay`` names, not free timing);
        ``signal_delay`` at its own value (its delay is the reading, its prior paid in the
        training evidence); a cable payload at each flight's own start swing
        (:func:`_read_own_start`)."""
        expl = ev.explanation
        theta = np.array([ev.values[k] for k in expl.parameter_names], float)
        own = bool(expl.shift) and expl.name != "signal_delay"
        read = []
        for states, memo, delay in zip(self.train + self.held, self.memos, self.delays):
            at = theta.copy()
            timed = own and delay is not None
            if timed:
                at[-1] = delay
            resid, ll = _read_own_start(_problem(states, self.reference, expl, memo), at)
            if timed:
                ll -= 0.5 * float((delay - expl.mean[-1]) / expl.sd[-1]) ** 2
            read.append((resid, ll))
        held = read[len(self.train):]
        ll = sum(h[1] for h in held)
        return Weighed(ev, dataclasses.replace(ev, log_z=ev.log_z + ll),
                       [r for r, _ in read[:len(self.train)]], [r for r, _ in held], ll)

    def timing_taken(self, null: Explanation) -> bool:
        """Whether every held-out flight's own rotor delay (:attr:`delays`) lies beyond
        :data:`quadsim.gap.calibrate.PRACTICAL_Z` of the delay's prior spreads (the
        references' timing spread) from its centre: a timing difference by the per-flight
        rule of practical significance, which "no difference" (``null``, the explanation
        the delays were read under) takes with each flight's own delay
        (:class:`Practical`). False without a timing reading."""
        own = self.delays[len(self.train):]
        if not null.shift or not own or any(d is None for d in own):
            return False
        mu, sd = float(null.mean[-1]), float(null.sd[-1])
        return all(abs(d - mu) > PRACTICAL_Z * sd for d in own)

    def model(self, expl: Explanation | None) -> list:
        """The reference model's effects an explanation keeps (every one for None): the
        base of its fits (:func:`consistent`) and of the answer's residual."""
        from .evidence import shared_effects

        return list(shared_effects(self.reference, () if expl is None else expl.replaces)[0])

    def words(self) -> str:
        """What the answer adds: the references it was judged against, the drag law and
        place, as per flight; why the references cannot vouch for a name, where they
        cannot (:func:`quadsim.gap.judge.unvouched`)."""
        n = len(self.calibrated.names)
        words = (f" Judged against {n} nominal reference flights: a difference is what the "
                 "training flights share that the references do not, checked on the "
                 "held-out flights.")
        if self.law is not None:
            words += f" Judged with {self.law.variant} (the law the training flights show)."
        if self.place is not None and self.place.distance > 0:
            words += f" Flown {self.place.text}."
        doubt = unvouched(self.calibrated.self_check, self.calibrated)
        return words + (" " + doubt if doubt else "")


def against_references(train: list[Flight], held: list[Flight], calibrated: Reference, *,
                       effects: Sequence[str] | None = None) -> Against:
    """The training and held-out flights against the references' model ``calibrated``
    (module doc, "Held out against nominal references"): aligned to the references' rotor
    timing, checked to be of their kind (:func:`quadsim.gap.logcheck.check_same_kind`),
    placed on their envelope at the stacked training flights' place, the drag law chosen on
    the stacked training flights (:func:`quadsim.gap.evidence.choose`) and the per-flight
    explanations built under it (``effects``: restrict them). Raises
    :class:`~quadsim.core.errors.InputError` for a flight not of the references' kind."""
    from .reference import reach_of

    ref = calibrated
    states = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        for f in list(train) + list(held):
            states.append(aligned(f, ref, f.name))
        tr, he = states[:len(train)], states[len(train):]
        stacked = _stacked(tr)
        trend = getattr(ref.envelope, "trend", None)
        informed = (trend is not None and trend.q_weight is not None
                    and np.any(trend.q_weight > 0))
        info = inverse_information(stacked, ref) if informed else None
        place = envelope_position(stacked, ref.envelope, info)
        local = local_reference(ref, place)
        # each training flight at its own place, as per flight (weigh_flight)
        places = [envelope_position(s, ref.envelope,
                                    inverse_information(s, ref) if informed else None)
                  for s in tr]
        placed = tuple(local_reference(ref, p) for p in places)
        # every flight's reach in the stacked place's noise scale (judge.heldout_share)
        reaches = tuple(reach_of(ref, p, local.sigma) for p in places + [
            envelope_position(s, ref.envelope, inverse_information(s, ref) if informed
                              else None) for s in he])
        flown = tuple(f"Training flight {os.path.basename(str(f.name))}"
                      + (f" (flown {p.text})" if p is not None and p.distance > 0 else "")
                      for f, p in zip(train, places))
        check = ref.self_check
        if local is not ref and check is not None:
            # the references' readings (calibrate.placed) and the systematic remainder's
            # normal (judge.placed_slow) at the same place
            check = placed_check(check, local)
            if getattr(check, "slow", None) is not None:
                check = dataclasses.replace(check, slow=placed_slow(check.slow, ref, local))
            local = dataclasses.replace(local, self_check=check)

        def hint(f):
            mine = (f.delays_ms or {}).get("rotor")
            return (1e-3 * mine - local.rotor_shift_s
                    if mine is not None and "rotor" in local.delays_ms else 0.0)

        start = float(np.mean([hint(f) for f in train]))
        memos = tuple({} for _ in range(len(states) + 1))
        law = evidence.choose(stacked, local, start, memos[-1])
        if effects is not None:         # as without references: a name it cannot weigh
            known = {e.name for e in explanations_for(local, stacked)} - {"no_difference"}
            unknown = set(effects) - known
            if unknown:
                raise InputError(f"--effects: unknown or unusable effect(s) {sorted(unknown)}; "
                                 f"valid: {', '.join(sorted(known))}")
        expl = tuple(evidence.under(explanations_for(local, stacked, effects), law))
        null = next(e for e in expl if e.name == "no_difference")
        delays = tuple(
            evidence.delay_starts(_problem(s, local, null, m), 0.0, hint(f))[0]
            if null.shift else None
            for s, m, f in zip(states, memos, list(train) + list(held)))
    return Against(ref, local, tuple(tr), tuple(he), stacked, start, delays, law, place,
                   expl, memos, placed, flown, reaches)


def weigh_against(against: Against, batch: tuple) -> list[Weighed]:
    """:meth:`Against.weigh` of ``batch`` (explanations, "no difference" or None; module
    level: sent to workers)."""
    return against.weigh(*batch)


def _weigh_against(against: Against, *, map_fn, tick) -> list[Weighed]:
    """Every explanation of :attr:`Against.explanations` weighed (:meth:`Against.weigh`):
    one call in this process, one task per explanation on workers."""
    expl = list(against.explanations)
    weighed = []
    null = next(e for e in expl if e.name == "no_difference")
    batches = [(expl, None)] if map_fn is map else [([e], None if e is null else null)
                                                    for e in expl]
    # to workers without the kept residual parts (they hold LAPACK handles, which do not
    # pickle; each task computes its own)
    sent = against if map_fn is map else dataclasses.replace(
        against, memos=tuple({} for _ in against.memos))
    for ws in map_fn(partial(weigh_against, sent), batches):
        for w in ws:
            weighed.append(w)
            tick(w.name)
    return weighed


def simulable(effects: list) -> list:
    """``effects`` as the k-step prediction simulates them (:func:`quadsim.gap.judge.where`,
    multiple shooting): a cable payload read from the logged motion
    (:class:`quadsim.gap.fitting.CableSwing`, no internal state: it differentiates the logged
    velocity, which a simulation step does not have) becomes the engines'
    ``cable_payload`` with its mass, length and attachment (its swing integrated from the
    engine's start at each restart); every other effect is kept as it is."""
    from ..effects import make_effect
    from .fitting import CableSwing

    return [make_effect("cable_payload", mass=e.mass, length=e.length, x=e.x, y=e.y, z=e.z)
            if isinstance(e, CableSwing) else e for e in effects]


def map_voltage(train: list, held: list) -> float | None:
    """The voltage (V) the held-out reference's command map is read at, in command x vbat
    (:func:`quadsim.gap.residual.fit_motor_map`'s ``duty_voltage``): the mean of the
    training flights' mean logged battery voltages, where every flight (training and held
    out) logs a finite one and the flights were flown at different charges: their mean
    voltages spread (max - min over the mean) by at least
    :data:`quadsim.gap.calibrate.VBAT_TESTED` (the per-flight references' rule for sharing
    the voltage law). Else None: the map in the command alone, as before.

    Why between flights: a map read at one charge transfers to a flight at another only in
    command x voltage (a DC motor's speed follows duty x voltage); flights that share one
    voltage profile (a constant log, every generated nominal flight's; or the same sag from
    the same full voltage, a generated ``battery_sag`` case's flights of one length) need no
    transfer, and there a sag within each flight stays the reading ``battery_sag``."""
    states = list(train) + list(held)
    if not train or any(s.vbat is None or not np.all(np.isfinite(s.vbat)) for s in states):
        return None
    means = np.array([float(np.mean(s.vbat)) for s in states])
    if not means.mean() > 0 or np.ptp(means) / means.mean() < VBAT_TESTED:
        return None
    return float(np.mean(means[:len(train)]))


def declares_voltage_law(params: VehicleParams) -> bool:
    """Whether ``params``' motor map declares a battery-voltage law (a reference voltage
    and a non-zero ``voltage_gain``, :meth:`quadsim.vehicle.params.MotorMap.speed_at`)."""
    mm = params.motor_map
    return mm is not None and mm.reference_voltage is not None and mm.voltage_gain != 0.0


def training_map(train: list, params: VehicleParams, *,
                 duty_voltage: float | None = None) -> VehicleParams:
    """The held-out reference's command map against the bare set, fitted on the training
    states ``train`` in the form they show (:func:`quadsim.gap.residual.fit_command_map`):
    where the set has a motor map and its flights follow it, that map in its own shape (its
    table and voltage law) with a per-rotor gain and offset
    (:func:`quadsim.gap.residual.fit_set_map`), so that what the set declares is not read
    as an effect (a voltage law read as a line in the command alone is a ``battery_sag``
    where nothing changed; a curved PWM table leaves the line's bend on the rotor channel)
    while a sag beyond the set's law stays in the speeds; where the training flights'
    speeds follow a line better (a speed-controlled motor), or the set has no map, the
    straight line per rotor (:func:`quadsim.gap.residual.fit_motor_map`). ``duty_voltage``:
    :func:`map_voltage`'s, read as those functions say."""
    return fit_command_map(train, params, duty_voltage=duty_voltage)


def params_have_data_map(params: VehicleParams) -> bool:
    """True when the motor map was already fitted from data by the diagnosis."""
    return params.motor_map is not None and "quadsim.gap" in params.motor_map.source


def _weigh(train: list, held: list, reference, *, effects, map_fn, tick) -> list:
    """Every explanation of how the training flights differ from ``reference`` (restricted
    to ``effects`` plus "no difference" and ``nominal_refit``), weighed on the split
    (:func:`weigh`): one call in this process, one task per
    explanation on workers."""
    vbat = None
    mm = reference.params.motor_map
    if (reference.rotor and (mm is None or mm.duty_voltage is None)
            and all(s.vbat is not None and np.all(np.isfinite(s.vbat)) for s in train)):
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
#: prior spread of the relative thrust factor error: :mod:`.fitting` -15 .. +5 %, half the
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
    discrepancy = fit_discrepancy(nominal, train, proportional_rotors(params))
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
        out = [e for e in out if not needs_pose(e.parts, logged_parts(train_states))]
    if not timing_carried(getattr(train_states, "window_s", 0.0)):   # judged in a band
        out = [e for e in out if e.name not in TIMING_READINGS]
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
    (linear-Gaussian: the columns X of :func:`quadsim.gap.reference.columns`, unit prior):
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
    """Stage 3 (module doc): training evidence of every explanation (on the stacked
    training flights, a cable payload with each flight's own start swing:
    :func:`fit_own_starts`), plus its held-out log-likelihood at the training MAP.
    ``train``/``held``: decimated states."""
    # every explanation fully fitted (no screen): its result must not depend on which others
    # share its batch, so that workers and one process give the same bytes
    rows = evaluate(stack_states(train), reference, expl, full=True,
                    fit=partial(fit_own_starts, at=joins(train)))
    out = []
    for ev in rows:
        if not np.isfinite(ev.log_z):   # its fit ended where no rigid vehicle is: no reading
            continue
        try:
            out.append(check(ev, train, held, reference))
        except ModelError:      # its values make no rigid vehicle: not a reading
            continue
    return out


def _beyond_at(ev: Evidence, states, reference: Reference) -> tuple[np.ndarray, float]:
    """:func:`_beyond` of one flight under ``ev``'s values (the reference's base effects
    and the explanation's)."""
    effects = list(reference.candidate.base) + effects_of(ev)
    r = residuals(states, reference.params, effects, rotor_channel=reference.rotor)
    return _beyond(r - centre_term(states, reference.discrepancy, r.shape[1]), states,
                   reference)


def _beyond_own_start(ev: Evidence, states, reference: Reference
                      ) -> tuple[np.ndarray, float]:
    """:func:`_beyond_at`, a cable payload's start swing (:data:`START_SWING`) that
    flight's own, as :func:`_read_own_start`: fitted on the flight from hanging still, the
    other values held at ``ev``'s, by least squares on the squares of -2 log L (the
    weighted residual less the discrepancy's posterior mean, that mean, and the start in
    units of its prior spread, inside :class:`quadsim.gap.fitting.CableSwing`'s bounds); its
    prior penalty -1/2 |z_start|^2 added to the log-likelihood. Without a start swing:
    :func:`_beyond_at` unchanged."""
    expl = ev.explanation
    idx = start_swing_index(expl)
    if not idx:
        return _beyond_at(ev, states, reference)
    from scipy.optimize import least_squares

    names = [expl.parameter_names[k] for k in idx]
    mean, sd = np.asarray(expl.mean, float)[idx], np.asarray(expl.sd, float)[idx]
    bound = {p.name: (p.lower, p.upper) for p in CableSwing.parameters}
    lo = (np.array([bound[n.split(".")[-1]][0] for n in names]) - mean) / sd
    hi = (np.array([bound[n.split(".")[-1]][1] for n in names]) - mean) / sd
    root = np.sqrt(reference.weights)
    x = (None if reference.discrepancy is None
         else columns(states, reference.discrepancy, reference.weights))

    def at(zs):
        return dataclasses.replace(ev, values={**ev.values, **dict(zip(names, mean + sd * zs))})

    def cost(zs):
        effects = list(reference.candidate.base) + effects_of(at(zs))
        r = residuals(states, reference.params, effects, rotor_channel=reference.rotor)
        rw = ((r - centre_term(states, reference.discrepancy, r.shape[1])) * root).ravel()
        if x is None:
            return np.concatenate([rw, zs])
        u = np.linalg.solve(np.eye(x.shape[1]) + x.T @ x, x.T @ rw)
        return np.concatenate([rw - x @ u, u, zs])

    got = least_squares(cost, np.zeros(len(idx)), bounds=(lo + 1e-6, hi - 1e-6),
                        max_nfev=START_FIT_EVALS)
    resid, ll = _beyond_at(at(got.x), states, reference)
    return resid, ll - 0.5 * float(got.x @ got.x)


def check(ev: Evidence, train: list, held: list, reference: Reference) -> Weighed:
    """One explanation's residuals on both sets and its held-out log-likelihood, each
    flight's own discrepancy marginalised (:func:`_beyond`), a cable payload at each
    flight's own start swing (:func:`_beyond_own_start`)."""
    def res(states):
        return _beyond_own_start(ev, states, reference)

    held_res = [res(s) for s in held]
    ll = sum(h[1] for h in held_res)
    return Weighed(ev, dataclasses.replace(ev, log_z=ev.log_z + ll),
                   [res(s)[0] for s in train], [h[0] for h in held_res], ll)


def pair(lead: Weighed, other: Weighed, *, partners: int, train: list, held: list,
         reference: Reference, against: Against | None = None) -> Weighed:
    """The lead fitted together with ``other`` (module doc, stage 4): its prior is the
    lead's with the partner's, less log(partners) (a second simultaneous effect is a priori
    no likelier than the first alone). ``against``: weighed against nominal references
    (:meth:`Against.weigh`) instead of the parameter set. Without references the pair is
    screened and fitted (:func:`quadsim.gap.evidence.evaluate`); a pair with a cable
    payload whose training flights start at their own swings (:func:`own_starts`) is
    fitted fully instead, each at its own (:func:`fit_own_starts`), as the cable alone
    was."""
    a, b = lead.train.explanation, other.train.explanation
    # a rotor delay (against references with a timing reading) is one parameter of the pair,
    # last, with the lead's prior (or the partner's where the lead fits none)
    timed = a if a.shift else b if b.shift else None
    mean, sd = _own(a.mean, a) + _own(b.mean, b), _own(a.sd, a) + _own(b.sd, b)
    if timed is not None:
        mean, sd = mean + (timed.mean[-1],), sd + (timed.sd[-1],)
    expl = Explanation(f"{a.name}+{b.name}", " ".join(v for v in (a.variant, b.variant) if v),
                       a.parts + b.parts, mean, sd,
                       tuple(dict.fromkeys(a.replaces + b.replaces)),
                       None if timed is None else timed.shift,
                       a.log_prior + b.log_prior - float(np.log(max(1, partners))),
                       loose=tuple(dict.fromkeys(a.loose + b.loose)))
    if against is not None:
        got = against.weigh([expl])
        if not got:
            raise ModelError(f"{expl.name}: no fit where a rigid vehicle is")
        return got[0]
    ev = evaluate(stack_states(list(train)), reference, [expl],
                  full=own_starts(expl, len(train)),
                  fit=partial(fit_own_starts, at=joins(train)))[0]
    return check(ev, train, held, reference)


def _own(values: tuple, expl: Explanation) -> tuple:
    """``values`` (an explanation's prior means or spreads) less its rotor delay's, the last
    where it fits one."""
    return tuple(values[:-1]) if expl.shift else tuple(values)


def readings_of(ranked: list, reference: Reference, *,
                references: bool = False, bias: Callable | None = None,
                pool: Sequence = ()) -> list[Reading]:
    """The posterior as :class:`~quadsim.gap.result.Reading` rows, in held-out words
    (``references``: against nominal reference flights, as per flight,
    :func:`quadsim.gap.words.nominal_words`), each named as per flight: the physical change
    largest against the references first (:func:`quadsim.gap.judge.reading_name`, the lead
    rule; the training flights' fit). ``bias(w)``: a Weighed's bias bound in standard
    errors beyond the references' reach (:meth:`Against.bias`; None: 0): its words, values'
    intervals and a payload's total (:func:`quadsim.gap.words.total_mass`) as stated,
    (1.96 + bias) standard errors (:func:`quadsim.gap.judge.as_stated`, module doc of
    :mod:`quadsim.gap.judge`, 1d); the name is the fit's own. ``pool``: every Weighed the
    posterior weighed (every form of each reading, not only the best ranked): a reading's
    forms the flights do not tell apart are said in its words by the per-flight rule,
    :func:`quadsim.gap.judge.form_words` on the total evidence (training plus held-out
    log-likelihood, what the posterior weighs); empty: ``ranked``'s own."""
    out = []
    totals = [w.total for w in (pool or [w for _, _, w in ranked])]
    for k, p, w in ranked:
        b = 0.0 if bias is None else bias(w)
        ev = as_stated(w.train, b)
        det = [q for q, ok in ev.determined.items() if ok]
        out.append(Reading(reading_name(k, w.train), p,
                           nominal_words(reading_text(ev, reference), k == ev.name,
                                         references=references)
                           + form_words(w.total, totals),
                           w.total.log_z, {q: ev.values[q] for q in det},
                           {q: 1.96 * ev.post_sd[q] for q in det},
                           tuple(q for q, ok in ev.determined.items() if not ok),
                           ev.explanation.fixed_values, ev.explanation.variant,
                           total=total_mass(ev) or {}, bias=b,
                           across=across_sessions(ev, reference.params.mass)))
    return out


def entry_of(w: Weighed, probability: float, before: list, reference: Reference, *,
             bias: float = 0.0) -> dict:
    """One ranked explanation as an ``effects`` JSON entry (:mod:`.schema` ``_EFFECT``):
    only determined parameters get values (``undetermined`` names the others); the held-out
    gap (mean squared residual over sigma^2) before (``before``: scaled nominal residuals)
    and after, and its ``reduction`` (gap_before - gap_after) / gap_before. ``bias``: the
    bias bound (standard errors, :meth:`Against.bias`) beyond the references' reach: each
    ``ci`` is (1.96 + bias) posterior spreads (:func:`quadsim.gap.judge.as_stated`);
    ``significant`` stays the fit's own (1.96 spreads: what the consistency check judges)."""
    ev = w.train
    stated = as_stated(ev, bias)
    sigma = reference.sigma
    gap_before = float(np.mean(np.concatenate(before) ** 2))
    after = [r / sigma for r in w.held_residuals]
    gap_after = float(np.mean(np.concatenate(after) ** 2))
    det = {q for q, ok in ev.determined.items() if ok}
    names = channel_names(reference)
    rms = np.sqrt(np.mean(np.concatenate(w.held_residuals) ** 2, axis=0))
    entry = {"name": ev.name, "probability": probability, "log_evidence": w.total.log_z,
             "params": {q: ev.values[q] for q in ev.values if q in det},
             "ci": {q: 1.96 * stated.post_sd[q] for q in ev.values if q in det},
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


def consistent(w: Weighed, entry: dict, flights: list, reference: Reference,
               base: tuple | None = None) -> dict:
    """The consistency check (:func:`quadsim.gap.judge.check`) of the reading ``w``
    (its ``effects`` ``entry``) on ``flights`` (decimated states) on top of ``base``
    (default the reference's base effects; against references, the references' model the
    reading keeps, :meth:`Against.model`); the propeller's speed exponent is held at its
    value (the library's thrust_factor has none)."""
    ev = w.train
    parts, theta = [], []
    for name, fixed, fitted in ev.explanation.parts:
        keep = tuple(p for p in fitted if not (name == "thrust_factor" and p == "alpha"))
        parts.append((name, dict(fixed), keep))
        theta += [ev.values[f"{name}.{p}"] for p in keep]
    cand = Candidate(ev.name, tuple(parts),
                     reference.candidate.base if base is None else tuple(base))
    judged = [q for q in entry["params"] if not q.endswith(".alpha")
              and entry["significant"].get(q)]
    return consistency_check(cand, np.asarray(theta, float), judged, flights,
                             params=reference.params, sigma=reference.sigma,
                             rotor=reference.rotor)


#: how many leads in turn :class:`Practical` measures on the training flights one by one
#: before the ranking stands (each a fit per training flight of one explanation)
PRACTICAL_ROUNDS = 3


class Practical:
    """Held-out practical significance (:mod:`quadsim.gap.calibrate`, the per-flight rule
    with the training flights as the references): a reading is a difference only when, on
    one of its own determined parameters, its 95 % interval lies beyond
    :data:`quadsim.gap.calibrate.PRACTICAL_Z` between-flight standard deviations of the same
    reading fitted on each training flight alone, from the no-difference value (the prior's
    centre): ``|v - centre| - 1.96 sd_post > 2 sd_between``, ``sd_between`` their physical
    spread (their readings' scatter less their own estimation noise,
    :meth:`quadsim.gap.calibrate.Spread.of`; the centre is exact). The training flights share
    the gap, so the scale is their spread about no difference, not about their mean. Measured
    lazily (:meth:`rank`): only for the readings that lead, at most
    :data:`PRACTICAL_ROUNDS` of them; none below 3 training flights (no spread to speak
    of). In both cases a reading is no difference either when it removes at most
    :data:`quadsim.gap.judge.FORM_ERROR` of the held-out gap (:meth:`small`, given the
    held-out flights' residuals under the nominal model, ``before``; :func:`decide` gives
    them only where "no difference" leaves no systematic remainder,
    :func:`quadsim.gap.judge.remainder`: where it does, a small reading may be the
    library's description of that remainder, and calling the flight ``unexplained``
    would say the library has none). ``timing_taken`` (against nominal references, where
    "no difference" reads each flight at its own rotor delay, :meth:`Against.check`, and
    that delay lies beyond the references' timing on every held-out flight,
    :meth:`Against.timing_taken`): the size rule does not size ``signal_delay``, whose
    change "no difference" has then taken with each flight's own delay (its share of the
    held-out gap nil by construction: what tells them apart is that delay's prior, paid in
    the evidence); per flight a delay is a nuisance parameter, outside practical
    significance too (:data:`quadsim.gap.calibrate.NUISANCE`). Where the held-out flights'
    own delays lie within the references' timing the share is the reading's size, as for
    every reading (a delay read at a periodic optimum far from the timing the flights show
    removes little of their gap)."""

    def __init__(self, train: list, reference: Reference, before: list | None = None, *,
                 timing_taken: bool = False):
        self.train, self.reference, self.before = train, reference, before
        self.timing_taken = timing_taken
        self.spreads: dict = {}
        self.shares: dict = {}

    def negligible(self, ev) -> bool:
        """Whether reading ``ev`` (an Evidence) is within the training flights' spread, or
        changes the held-out flights by no more than the library's form error
        (:meth:`small`)."""
        return self.spread_negligible(ev) or self.small(ev)

    def spread_negligible(self, ev) -> bool:
        """Whether reading ``ev`` is within the training flights' spread (alone); against
        nominal references (the reference carries their self-check), within the
        references' between-flight spread about their own readings, the per-flight rule
        (:func:`quadsim.gap.calibrate.negligible`)."""
        check = getattr(self.reference, "self_check", None)
        return negligible(ev, check if check is not None
                          else SelfCheck((), (), (), self.spreads))

    def small(self, ev) -> bool:
        """Whether reading ``ev`` removes at most :data:`quadsim.gap.judge.FORM_ERROR` of the
        held-out gap (the share :func:`entry_of` states as ``reduction``; measured in
        :meth:`rank`). Why: a right reading may leave that share of the gap as its form's
        error (:func:`quadsim.gap.judge.within_form_error`), so a reading whose whole effect
        on the held-out flights is no larger is no difference that matters -- whatever its
        log evidence, which assumes the library's forms exact. The same size in the
        data's own units as the between-flight spread is in a parameter's, and the one
        that applies with fewer than 3 training flights, where there is no spread."""
        if self.timing_taken and ev.name == "signal_delay":
            return False
        share = self.shares.get((ev.name, ev.explanation.variant))
        return share is not None and share <= FORM_ERROR

    def _measure(self, weighed: list) -> None:
        if self.before is None:
            return
        gap = float(np.mean(np.concatenate(self.before) ** 2))
        for w in weighed:
            key = (w.name, w.train.explanation.variant)
            if key in self.shares or w.name == "no_difference" or gap <= 0:
                continue
            after = float(np.mean(np.concatenate(
                [r / self.reference.sigma for r in w.held_residuals]) ** 2))
            self.shares[key] = (gap - after) / gap

    def rank(self, weighed: list) -> list:
        """:func:`quadsim.gap.judge.rank` with practical significance: the lead's spread
        over the training flights measured, then ranked again, until the lead is one
        measured or "no difference"."""
        self._measure(weighed)
        ranked = rank(weighed, self.negligible)
        for _ in range(PRACTICAL_ROUNDS):
            name, _, lead = ranked[0]
            key = (lead.name, lead.train.explanation.variant)
            if name == "no_difference" or key in self.spreads or len(self.train) < 3 \
                    or getattr(self.reference, "self_check", None) is not None:
                break
            self.spreads[key] = self.spread_of(lead)
            ranked = rank(weighed, self.negligible)
        return ranked

    def spread_of(self, w: Weighed) -> dict:
        """Parameter -> :class:`~quadsim.gap.calibrate.Spread` (centre: the prior's; sd: the
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
            out[key] = Spread(float(centre.get(key, 0.0)), s.sd, s.count, s.noise)
        return out


@dataclass(frozen=True)
class Decision:
    """The weighed explanations of a split, ranked (:func:`decide`): ``ranked`` (reading,
    probability, Weighed), most probable first; ``rows`` its :class:`Reading` rows;
    ``entries`` every explanation as an ``effects`` JSON entry (most probable first);
    ``lead`` and ``lead_name`` the most probable reading; ``null`` the "no difference"
    Weighed; ``combination`` the pair kept as the lead (or None); ``consistency`` the lead's
    check (None for "no difference"); ``implausible`` (name, magnitude, prior text) of the
    explanations whose determined values lie outside their documented plausible range:
    weighed like every other, a lead among them named only with the caveat of
    :func:`quadsim.gap.judge.lead_caveat` (tentative), as per flight; ``small`` (name,
    magnitude, share of the held-out gap it removes) of the readings more probable than
    "no difference" that count as none because they remove at most
    :data:`quadsim.gap.judge.FORM_ERROR` of the held-out gap (:meth:`Practical.small`),
    most probable first; ``weighed`` every explanation weighed (and the pair kept), the
    set :func:`quadsim.gap.judge.beyond_misfit` measures the lead's misfit against;
    ``reach``/``moved``: against references beyond their reach, the flights' furthest
    :class:`quadsim.gap.reference.Reach` and reading -> (its p before, the share of it that
    counts as no difference) (:meth:`Against.split`; None / empty otherwise)."""

    ranked: tuple
    rows: tuple
    entries: tuple
    lead: Weighed
    lead_name: str
    null: Weighed | None
    combination: Weighed | None
    consistency: dict | None
    implausible: tuple
    small: tuple = ()
    weighed: tuple = ()
    reach: object = None
    moved: dict = field(default_factory=dict)

    @property
    def probability(self) -> dict:
        """Reading -> posterior probability."""
        return {k: p for k, p, _ in self.ranked}

    def entry(self, name: str) -> dict | None:
        """The ``effects`` entry of ``name`` (None for "no difference" or one not fitted):
        a reading's key, or its row's name (:func:`readings_of`: a key the lead rule
        renamed, e.g. ``body_drag`` for the wind reading that carries it)."""
        name = next((k for r, (k, _, _) in zip(self.rows, self.ranked) if r.name == name
                     and k != r.name and not any(e["name"] == name for e in self.entries)),
                    name)
        return next((e for e in self.entries if e["name"] == name), None)

    @property
    def shown(self) -> str:
        """The lead's name as the answer states it (its row's: the lead rule)."""
        return self.rows[0].name if self.rows else self.lead_name


def decide(weighed: list[Weighed], *, train: list, held: list, reference: Reference,
           before: list, max_combination: int = 2, tick=None,
           against: Against | None = None) -> Decision:
    """Rank the weighed explanations; try the lead with a second effect when it leaves a
    systematic remainder or does not carry over (module doc, stage 4); check the lead's
    consistency. ``train``/``held``: decimated states; ``before``: the held-out residuals
    over sigma under the nominal model (against references: under "no difference");
    ``tick(name)``: progress per pair fitted; ``against``: weighed against nominal
    references (:class:`Against`: a pair is fitted and read as its explanations were, and
    the consistency check fits on top of the references' model)."""
    params = reference.params
    tick = tick or (lambda *_: None)
    dt = float(train[0].t[1] - train[0].t[0])
    # beyond the references' reach, the model's own error there is a reading (Against.split)
    split = (lambda r: (r, {})) if against is None else against.split

    def base_of(w):
        return None if against is None else against.model(w.train.explanation)

    # the per-flight rule (quadsim.gap.judge.lead_caveat): a value outside its documented
    # plausible range keeps its evidence; a lead with one is named with a caveat, tentative
    implausible = []
    for w in weighed:
        ok, text = plausible(plausible_values(w.train, params), params)
        if not ok:
            implausible.append((w, text))
    null = next((w for w in weighed if w.name == "no_difference"), None)
    # beyond the references' reach every interval is stated with the bias the model's own
    # error can cause there (quadsim.gap.judge, module doc 1d; Against.bias); within it 0
    sized: dict = {}

    def bias(w):
        if against is None:
            return 0.0
        if id(w) not in sized:
            sized[id(w)] = against.bias(w, null)
        return sized[id(w)]

    def stated(w):          # its reading in words, as stated (module doc 1d of judge)
        return reading_text(as_stated(w.train, bias(w)), reference)

    # the size rule (Practical.small) only where "no difference" leaves nothing systematic:
    # where it leaves a remainder, a small reading may be the library's description of it
    quiet = null is not None and not remainder(null.train_residuals + null.held_residuals,
                                               reference, dt)
    scale = Practical(train, reference, before if quiet else None,
                      timing_taken=against is not None and null is not None
                      and against.timing_taken(null.train.explanation))
    ranked, moved = split(scale.rank(weighed))
    lead_name, _, lead = ranked[0]
    combination = checked = None
    if lead_name != "no_difference":
        checked = consistent(lead, entry_of(lead, 1.0, before, reference), train + held,
                             reference, base_of(lead))
    # a pair needs every part plausible (every_part_stands), so it is built on the most
    # probable plausible reading: the lead, or the most probable below an implausible lead
    # (by probability, then log evidence: the readings below a lead of probability ~1 all
    # have ~0, and their ranked order among themselves is then by name)
    outside = {id(w) for w, _ in implausible}
    base = min(((-p, -float(w.total.log_z), i, w) for i, (k, p, w) in enumerate(ranked)
                if k == w.name and k != "no_difference" and id(w) not in outside),
               key=lambda c: c[:3], default=(None,) * 4)[3]
    base_checked = checked if base is lead else (
        None if base is None else consistent(base, entry_of(base, 1.0, before, reference),
                                             train + held, reference, base_of(base)))
    if lead_name != "no_difference" and base is not None and max_combination >= 2 \
            and base_checked["consistent"] \
            and (remainder(base.train_residuals + base.held_residuals, reference, dt)
                 or carry_over(base, reference, null)):
        # partners as ranked before the size rule: a reading too small alone may be the
        # second half of a pair (whose own size is judged when it is ranked)
        # not a reading that carries an effect the base carries already (a wind carries
        # the flapping moment, explanations.wind_moment): that pair fits it twice
        carried = {part[0] for part in base.train.explanation.parts}
        others = [w for k, _, w in rank(weighed, scale.spread_negligible)
                  if k not in ("no_difference", base.name) and w.name == k
                  and id(w) not in outside
                  and not carried & {part[0] for part in w.train.explanation.parts}]
        trials = []
        for other in others:
            try:
                trials.append(pair(base, other, partners=len(others), train=train,
                                   held=held, reference=reference, against=against))
            except ModelError:      # against references: no fit where a rigid vehicle is
                if against is None:
                    raise
                continue
            tick(trials[-1].name)
        best = max(trials, key=lambda w: w.total.log_z, default=None)
        if best is not None:
            stands = every_part_stands(entry_of(best, 0.0, before, reference), params)
            with_pair, pair_moved = split(scale.rank(weighed + [best]))
            if stands and with_pair[0][2] is best:
                ranked, combination, moved = with_pair, best, pair_moved
                lead_name, _, lead = ranked[0]
                checked = consistent(lead, entry_of(lead, 1.0, before, reference),
                                     train + held, reference, base_of(lead))
    entries = [entry_of(w, p, before, reference, bias=bias(w)) for k, p, w in ranked
               if k == w.name and k != "no_difference"]
    seen = {e["name"] for e in entries}
    # a reading the size rule counts as "no difference": its entry is its best variant,
    # as ranked before that rule (Practical.small), at probability 0
    # (ranked again: the pair's ranking may have measured more spreads)
    entries += [entry_of(w, 0.0, before, reference, bias=bias(w)) for k, _, w in
                rank(weighed, scale.spread_negligible) if k == w.name and k not in seen
                and k != "no_difference" and scale.small(w.train) and not seen.add(k)]
    entries += [entry_of(w, 0.0, before, reference, bias=bias(w)) for w in weighed
                if w.name not in seen and w.name != "no_difference" and not seen.add(w.name)]
    entries.sort(key=lambda e: (-e["probability"], -e["log_evidence"], e["name"]))
    small = sorted((w for w in weighed if null is not None and w is not null
                    and w.total.log_z > null.total.log_z and scale.small(w.train)),
                   key=lambda w: -w.total.log_z)
    pool = tuple(weighed) + ((combination,) if combination is not None else ())
    rows = readings_of(ranked, reference, references=against is not None, bias=bias,
                       pool=pool)
    return Decision(tuple(ranked), tuple(rows), tuple(entries),
                    lead, lead_name, null, combination, checked,
                    tuple((w.name, stated(w), text) for w, text in implausible),
                    tuple((w.name, stated(w),
                           scale.shares[(w.name, w.train.explanation.variant)])
                          for w in small),
                    pool,
                    None if against is None or not moved else against.reach, moved)


#: fewer reference flights than this gives a note (their scatter is poorly known).
MIN_REFERENCE = 10


def diagnose_per_flight(logs: Sequence[FlightLog], reference: Sequence[FlightLog],
                        params: VehicleParams, *, effects: Sequence[str] | None = None,
                        progress: Callable | None = None,
                        window_s: float = DEFAULT_WINDOW_S, map_fn: Callable = map,
                        refused: Sequence[tuple[int, str, str]] = (),
                        base_effects: Sequence = (),
                        store=None, orders: Sequence | None = None) -> Diagnosis:
    """Judge each flight on its own against ``reference`` (nominal) flights (module doc);
    or against their stage already computed (a :class:`Calibrated`: the CLI's cache,
    :mod:`quadsim.gap.cache`).

    ``refused``: (position, file, reason) of flights refused before this call (the CLI's
    loader and checks); they are placed at their position in ``flights``.
    ``base_effects``: effects already in the model (an effect file,
    :mod:`quadsim.effects.effectfile`), as in :func:`diagnose`: part of the references' model
    and so of every flight's (:func:`quadsim.gap.calibrate.calibrate`'s ``base``), never
    refitted; the shared groups and every reading are fitted on top of them.
    ``map_fn(fn, logs)`` runs the flights (e.g. a :mod:`quadsim.core.executor` executor).
    ``store``: keeps the reference stage between runs (``get(key)`` -> a
    :class:`quadsim.gap.calibrate.Calibrated` or None, ``put(calibrated)``; the CLI's
    cache writes through it, :mod:`quadsim.gap.cache`): where it holds the stage of these references
    (:func:`quadsim.gap.calibrate.reference_key`), their preparation, calibration and
    self-check are not done again.
    ``orders``: each log's rotor-order status where the checks already read it
    (:func:`quadsim.logs.checks.check_logs` with ``orders``; None entries, or None: read
    here), in the order of ``logs``.
    Raises :class:`~quadsim.core.errors.InputError` for fewer than two reference flights."""
    base = tuple(base_effects)
    kept = calibrated_stage(reference, params, effects=effects, window_s=window_s,
                            base=base, store=store, map_fn=map_fn)
    ref, vehicle = kept.reference, kept.vehicle
    if progress is not None:
        progress("reference")
    notes = _stage_notes(kept)
    one = partial(_judge, reference=ref, effects=effects, window_s=window_s)
    orders = [None] * len(logs) if orders is None else list(orders)
    if len(orders) != len(logs):
        raise ValueError(f"orders: {len(orders)} statuses for {len(logs)} logs")
    flights = []
    for entry in map_fn(one, [ToJudge(log, order) for log, order in zip(logs, orders)]):
        flights.append(entry)
        if progress is not None and map_fn is map:
            progress(entry.file)
    for position, name, reason in sorted(refused):
        flights.insert(position, refused_entry(name, reason))
    return Diagnosis(SCHEMA, params.name, "per-flight", flights=tuple(flights),
                     answer=batch_answer(flights), reference=tuple(ref.names),
                     reference_model=reference_summary(ref),
                     reference_refit={k: v for k, v in ref.values().items()
                                      if k.startswith("nominal_refit.")},
                     checks=vehicle, notes=tuple(notes), base_effects=base_json(base))


def base_json(base: Sequence) -> tuple:
    """The effects already in the model as JSON: ({"name", "params": {parameter: value in
    the effect's declared unit}}, ...)."""
    return tuple({"name": e.name, "params": {p.name: float(getattr(e, p.name))
                                             for p in e.parameters}} for e in base)


def calibrated_stage(reference, params: VehicleParams, *, effects, window_s: float,
                     base: tuple, store=None, map_fn: Callable = map) -> Calibrated:
    """The reference stage of ``reference`` (logs): from ``store`` where it holds it
    (:func:`quadsim.gap.calibrate.reference_key`), else :func:`_reference_stage` (then put
    there); both modes' (:func:`diagnose_per_flight`, :func:`diagnose` with references).
    ``reference`` already a :class:`Calibrated` (the CLI's cache, :mod:`quadsim.gap.cache`):
    that stage, as it is. ``map_fn(fn, items)``: runs the self-check's weighings
    (:func:`reference_self_check`; an executor's, as the flights'), the same values as
    ``map``."""
    if isinstance(reference, Calibrated):
        return reference
    key = None if store is None else reference_key(reference, params, effects=effects,
                                                   window_s=window_s, base=base)
    kept = None if store is None else store.get(key)
    if kept is None:
        kept = _reference_stage(reference, params, effects=effects, window_s=window_s,
                                key=key, base=base, map_fn=map_fn)
        if store is not None:
            store.put(kept)
    return kept


def _stage_notes(kept: Calibrated) -> list[str]:
    """The reference stage's notes: too few references (below :data:`MIN_REFERENCE`), the
    references left out (:func:`quadsim.gap.words.left_out_words`), a thrust per Omega^2 the
    set's mass and b do not give (:func:`~quadsim.gap.words.refit_words`), the reference
    model's values at a bound of its fit (:func:`~quadsim.gap.words.bound_words`), and the
    references' signal-delay notes."""
    notes = ([(f"only {kept.count} reference flights: their scatter is poorly known; "
              "give 10 or more")] if kept.count < MIN_REFERENCE else [])
    said = [left_out_words(kept.reference), refit_words(kept.reference),
            bound_words(kept.reference)]
    return notes + [text for text in said if text] + list(kept.notes)


def _reference_stage(reference, params: VehicleParams, *, effects, window_s: float,
                     key: str | None, base: tuple = (), map_fn: Callable = map) -> Calibrated:
    """The reference flights prepared, checked against the model, calibrated on top of the
    ``base`` effects (an effect file) and judged against each other
    (:func:`reference_self_check`); a reference the self-check judges confidently unlike the
    others in an otherwise clean set (:func:`quadsim.gap.calibrate.odd_references`) is left
    out and the rest calibrated and checked again (``Reference.left_out`` says which)."""
    ref_flights = prepare(reference, params, window_s=window_s)
    if len(ref_flights) < 2:
        raise InputError("--reference: give at least 2 nominal flights")
    vehicle = vehicle_check([f.fit for f in ref_flights], params)
    ref = calibrate(ref_flights, params, base=base)
    ref.self_check = reference_self_check(ref_flights, ref, effects, map_fn=map_fn)
    odd = odd_references(ref.self_check)
    if odd:     # unlike the others beyond their spread: calibrated again without them
        left = tuple(a for a in ref.self_check.false_alarms if a[0] in odd)
        ref_flights = [f for f in ref_flights if f.name not in odd]
        ref = calibrate(ref_flights, params, base=base)
        ref.self_check = reference_self_check(ref_flights, ref, effects, map_fn=map_fn)
        ref.left_out = left
    return Calibrated(key or "", ref, vehicle, tuple(delay_notes(ref_flights)),
                      len(ref_flights))


def reference_summary(ref: Reference) -> dict:
    """The calibrated reference model as JSON: values, pooled standard error, between-flight
    scatter and whether the reference flights determine it (``identified``) per shared
    parameter; noise scale (sigma) and correlation time per channel; the references'
    envelope (:func:`quadsim.gap.reference.envelope_summary`); their drag as a quadratic
    airframe drag's C_d A (m^2, :func:`quadsim.gap.calibrate.quadratic_equivalent`); the
    speed-per-command exponent their map implies for a propeller change
    (:func:`quadsim.gap.residual.load_exponent`); the shared effects' fixed values (the
    thrust curve's centre, rad/s)."""
    names = channel_names(ref)
    return {"params": ref.values(),
            "se": dict(zip(ref.candidate.parameter_names, map(float, ref.se_pool))),
            "scatter": dict(zip(ref.candidate.parameter_names, map(float, ref.scatter))),
            "identified": {k: bool(v) for k, v in ref.identified.items()},
            "at_bound": dict(ref.at_bound),
            "left_out": [{"flight": n, "verdict": v, "channels": list(c)}
                         for n, v, c in getattr(ref, "left_out", ())],
            "sigma": dict(zip(names, map(float, ref.sigma))),
            "correlation_samples": dict(zip(names, map(float, ref.tau))),
            "rotor_timing_ms": {"value": 1e3 * ref.rotor_shift_s,
                                "se": 1e3 * ref.rotor_shift_se},
            "delays_ms": {k: {"mean": m, "sd": s, "count": n}
                          for k, (m, s, n) in ref.delays_ms.items()},
            "envelope": envelope_summary(ref.envelope, ref.candidate.parameter_names),
            "quadratic_drag_m2": float(ref.quadratic_drag),
            "quadratic_drag_axes_m2": float(ref.quadratic_drag_axes),
            "quadratic_vertical_axes_m2": float(ref.quadratic_vertical_axes),
            "fixed": {f"{name}.{k}": float(v) for name, fixed, _ in ref.candidate.parts
                      for k, v in fixed.items()},
            "load_exponent": None if ref.load_exponent is None else
            {"alpha": ref.load_exponent[0], "sd": ref.load_exponent[1]},
            "discrepancy": None if ref.discrepancy is None
            else ref.discrepancy.to_json(names),
            "self_check": None if ref.self_check is None else ref.self_check.to_json()}


def reference_self_check(ref_flights: list, ref: Reference, effects=None, *,
                         map_fn: Callable = map):
    """The references judged against each other (:mod:`quadsim.gap.calibrate`): each
    reference weighed against :func:`~quadsim.gap.calibrate.leave_one_out` of ``ref``, then
    judged with the other references' readings as the practical-significance scale, a false
    alarm's readings read on every reference first
    (:func:`~quadsim.gap.calibrate.settled_self_check`, :func:`refined_rows`). None for
    fewer than 3 references. ``map_fn(fn, items)`` weighs the references (an executor's:
    they are independent; the same values as ``map``, :mod:`quadsim.core.executor`)."""
    if len(ref_flights) < 3 or getattr(ref, "log_ms", None) is None:
        return None
    # each reference's inverse information, as the calibration took it (its one-step
    # standard errors, quadsim.gap.calibrate.inverse_information): the same Jacobian at the
    # same shared values, up to round-off (the left-out discrepancy's centre, which no shared
    # parameter moves, cancels in its differences)
    per = getattr(ref, "per_flight", None)
    infos = ([None] * len(ref_flights) if per is None or len(per.se) != len(ref_flights) else
             [per.se[j] ** 2 * len(getattr(f, "fit", f).t) for j, f in enumerate(ref_flights)])
    weighed = list(map_fn(_weigh_reference, [
        _ToWeigh(f, leave_one_out(ref, j), effects, infos[j])
        for j, f in enumerate(ref_flights)]))

    def rows_of(w):
        return rows_at_reference_voltage(
            w.rows, getattr(getattr(w.flight, "fit", w.flight), "vbat", None), ref.vbat_ref)

    # a false alarm's readings read on every reference (calibrate.settled_self_check)
    return settled_self_check([f.name for f in ref_flights], weighed, rows_of=rows_of,
                              judge_of=verdict_of, refine=refined_rows)


@dataclass(frozen=True)
class _ToWeigh:
    """One reference flight to weigh against the others (:func:`reference_self_check`):
    ``flight`` (prepared), ``reference`` (:func:`~quadsim.gap.calibrate.leave_one_out` of
    the references without it), ``effects`` and ``info`` (its inverse information, or
    None)."""

    flight: object
    reference: Reference
    effects: object
    info: object

    @property
    def name(self) -> str:
        return self.flight.name


def _weigh_reference(item: _ToWeigh) -> WeighedFlight | None:
    """:func:`weigh_flight` of one reference against the others (module level: sent to
    workers), its memo dropped (its residual parts are not needed once weighed: memory and
    what travels back); None where it cannot be weighed."""
    w = weigh_flight(item.flight, item.reference, item.effects, name=item.flight.name,
                     info=item.info)
    return dataclasses.replace(w, memo=None) if isinstance(w, WeighedFlight) else None


def start_delay(flight, reference: Reference) -> float:
    """Where a flight's rotor delay starts against ``reference`` (s): its logged rotor
    delay less the references' rotor shift (0 where either is not known)."""
    mine = (flight.delays_ms or {}).get("rotor")
    if mine is None or "rotor" not in reference.delays_ms:
        return 0.0
    return 1e-3 * mine - reference.rotor_shift_s


def refined_rows(weighed: WeighedFlight, wanted: set) -> WeighedFlight:
    """``weighed`` with its screened rows of the readings named in ``wanted`` fitted to
    convergence (:func:`quadsim.gap.evidence.evaluate` with ``full=True``, the delay's
    start from its first "no difference", as the screen's): the value and spread a reading
    has on that flight (:func:`quadsim.gap.calibrate.readings`). ``weighed`` itself where
    none is screened, or where the fit fails (the rows stay screened: no reading, as before)."""
    idx = [k for k, ev in enumerate(weighed.rows) if ev.name in wanted and ev.screened]
    if not idx:
        return weighed
    nulls = [ev.explanation for ev in weighed.rows
             if ev.name == "no_difference" and ev.explanation.shift][:1]
    expl = nulls + [weighed.rows[k].explanation for k in idx]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            fitted = evaluate(weighed.states, weighed.reference, expl,
                              start_delay_s=start_delay(weighed.flight, weighed.reference),
                              full=True)
    except (InputError, ModelError, ValueError, np.linalg.LinAlgError):
        return weighed
    rows = list(weighed.rows)
    for k, ev in zip(idx, fitted[len(expl) - len(idx):]):
        rows[k] = ev
    return dataclasses.replace(weighed, rows=rows)


@dataclass(frozen=True)
class ToJudge:
    """One flight log to judge (:func:`diagnose_per_flight`) and its rotor-order status
    where the checks already read it (:func:`quadsim.logs.checks.check_logs` with
    ``orders``; None: read when judged)."""

    log: FlightLog
    order: object = None

    @property
    def path(self):
        """The log's file (the executor's label)."""
        return self.log.path


def _judge(item: ToJudge, **kwargs) -> Verdict:
    """:func:`judge_one` of ``item`` (module level: sent to workers)."""
    return judge_one(item.log, order=item.order, **kwargs)


def judge_one(log: FlightLog, reference: Reference, effects=None,
              window_s: float = DEFAULT_WINDOW_S, full: bool = False, *,
              order=None) -> Verdict:
    """One flight's :class:`~quadsim.gap.result.Verdict` (module level: sent to workers);
    ``refused`` with the reason when the flight cannot be judged. ``effects``: restrict the
    explanations; ``window_s`` (s): smoothing window; ``full``: every explanation fully
    fitted (no screen, :func:`quadsim.gap.evidence.evaluate`); ``order``: the log's
    rotor-order status (:func:`quadsim.logs.checks.rotor_order_status`) where already
    read (None: read here)."""
    name = str(log.path) if getattr(log, "path", None) is not None else "log"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            flight = prepare([log], reference.params, window_s=window_s)[0]
    except (InputError, ModelError, ValueError, np.linalg.LinAlgError) as exc:
        return refused_entry(name, str(exc))
    weighed = weigh_flight(flight, reference, effects, full=full, name=name)
    if not isinstance(weighed, WeighedFlight):
        return weighed
    statuses = (logcheck.order_statuses([log], reference.params) if order is None
                else [order])
    verdict = verdict_of(weighed, reference.self_check, statuses)
    verdict = synthesised_timing_note(verdict, [log])   # a timing read through the motor map
    # the residual before and after, for the report: on the states the flight was weighed
    # on, with the residual parts and Jacobian its weighing kept
    return dataclasses.replace(verdict, series=flight_series(
        weighed.states, weighed.reference, weighed.rows, name=weighed.flight.name,
        memo=weighed.memo))


@dataclass(frozen=True)
class WeighedFlight:
    """One prepared flight weighed against the reference model: ``flight`` (the prepared
    flight), ``rows`` (every explanation's Evidence), ``reference`` (the reference model at
    the flight's place, :func:`quadsim.gap.reference.local_reference`), ``place`` (its
    envelope position or None), ``law`` (the drag law it is judged under, or None),
    ``states`` (the flight's fit states aligned to the references' timing, weighed) and
    ``memo`` (the residual parts and Jacobian the weighing kept for them,
    :func:`quadsim.gap.evidence.evaluate`)."""

    flight: object
    rows: list
    reference: Reference
    place: object
    law: object
    states: object = None
    memo: dict | None = field(default=None, compare=False, repr=False)


def aligned(flight, reference: Reference, name: str) -> FlightStates:
    """A prepared flight's fit states at the references' rotor-speed timing
    (:meth:`~quadsim.gap.reference.Reference.align`), checked against the references: a pose
    on both or neither (:func:`quadsim.gap.logcheck.check_same_kind`), motor commands where
    the references log them, at least 20 samples after smoothing (fewer fit no reading).
    Raises :class:`InputError` naming ``name`` and the field."""
    states = reference.align(flight)
    check_same_kind(states, reference, name)
    if states.command is None and reference.rotor:
        raise InputError(f"{name}: cmd_1..cmd_N: the reference flights log motor "
                         "commands, this one does not")
    if len(states.t) < 20:
        raise InputError(f"{name}: t: too short to judge ({len(states.t)} samples "
                         "after smoothing)")
    return states


def weigh_flight(flight, reference: Reference, effects=None, *, full: bool = False,
                 name: str = "log", info: np.ndarray | None = None
                 ) -> WeighedFlight | Verdict:
    """The :class:`WeighedFlight` of a prepared flight, or its ``refused`` verdict.
    ``info``: the flight's inverse information per sample (M,) where already known
    (:func:`quadsim.gap.calibrate.inverse_information`; None: computed here)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            states = aligned(flight, reference, name)
            trend = getattr(reference.envelope, "trend", None)
            if trend is None or trend.q_weight is None or not np.any(trend.q_weight > 0):
                info = None
            elif info is None:
                info = inverse_information(states, reference)
            place = envelope_position(states, reference.envelope, info)
            reference = local_reference(reference, place)   # the model at this flight
            start = start_delay(flight, reference)
            memo: dict = {}        # the flight's residual parts and shared Jacobian, kept
            law = evidence.choose(states, reference, start, memo)
            expl = evidence.under(explanations_for(reference, states, effects), law)
            rows = evaluate(states, reference, expl, start_delay_s=start, full=full, memo=memo)
    except (InputError, ModelError, ValueError, np.linalg.LinAlgError) as exc:
        return refused_entry(name, str(exc))
    return WeighedFlight(flight, rows, reference, place, law, states, memo)


def verdict_of(weighed: WeighedFlight, check=None, statuses=()) -> Verdict:
    """The :class:`~quadsim.gap.result.Verdict` of a :class:`WeighedFlight` flight, judged with the
    references' self-check ``check`` (:class:`quadsim.gap.calibrate.SelfCheck`, or None) and
    the rotor-order ``statuses`` of its log (:mod:`quadsim.gap.logcheck`; none: not checked),
    with :func:`~quadsim.gap.logcheck.without_pose_note` and
    :func:`~quadsim.gap.logcheck.confusable_note` by its states' ``pose``."""
    flight, rows, place, law = weighed.flight, weighed.rows, weighed.place, weighed.law
    reference = dataclasses.replace(weighed.reference, self_check=check)
    verdict = logcheck.mark(judge(rows, reference, flight.name,
                                  cap=logcheck.probability_cap(statuses),
                                  vbat=getattr(getattr(flight, "fit", flight), "vbat", None)),
                            statuses)
    words = verdict.answer
    if law is not None:       # the drag law in words; None: the references'
        words += f" Judged with {law.variant} (the law this flight shows)."
    if place is not None and place.distance > 0:
        words += f" Flown {place.text}."
    corrections = tuple(getattr(flight, "corrections", ()))
    if corrections:         # what the log checks changed (FlightLog.corrections)
        words += f" The log as corrected: {'; '.join(corrections)}."
    verdict = dataclasses.replace(
        verdict, answer=words, drag_law=None if law is None else law.variant,
        envelope=None if place is None else place.to_json(),
        signal_delays_ms=flight.delays_ms,
        notes=verdict.notes + tuple(delay_notes([flight]))
        + tuple(f"{flight.name}: {c}" for c in corrections))
    # what a pose would add, and a declared pair the data do not separate: here, so that a
    # reference judged against the others (the self-check) is worded and marked as a flight
    states = getattr(flight, "states", flight)
    # what a reading scaling the rotors' wrench may owe to the speeds' noise (judge)
    samples = len(weighed.states.t) if weighed.states is not None else 0
    shrink = {(ev.name, ev.explanation.variant): torque_shrinkage(ev, weighed.reference,
                                                                  samples) for ev in rows}
    return confusable_note(without_pose_note(verdict, states), states, shrink)


def refused_entry(name: str, reason: str) -> Verdict:
    """The verdict of a flight that could not be judged, with the reason."""
    return Verdict("refused", "refused", f"Not judged: {reason}", None, file=name,
                   reason=reason)
