"""Held-out mode and the shared preparation: prepare the logs, split by flight, judge.

:func:`prepare` turns logs into :class:`Flight` (smoothed states at the log's rate, the
decimated fit view, signal delays); :func:`diagnose` splits the flights (``holdout`` or
every third flight; one flight: its two halves), takes the parameter set as the reference
model (:func:`quadsim.gap.heldout.nominal_reference`), weighs every explanation
(:func:`quadsim.gap.heldout.weigh`, :func:`quadsim.gap.heldout.decide`), judges
(:func:`quadsim.gap.judge.judge_heldout`) and says where the gap lies (:mod:`.where`). It
returns a :class:`quadsim.gap.result.Diagnosis` (``mode`` ``"held-out"``; its ``to_json()``
is the ``quadsim.gap/3`` JSON, :mod:`.schema`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..core.errors import InputError
from ..logs.delays import align_signal_delays, delay_notes
from ..logs.flightlog import FlightLog
from ..vehicle.params import VehicleParams
from . import heldout, order
from .baseline import BASELINE  # noqa: F401  (re-exported: quadsim.identify, tests)
from .checks import check_length, vehicle_check
from .fitting import fit_motor_map, stack_states
from .judge import channel_names, judge_heldout
from .residual import DEFAULT_WINDOW_S, FlightStates, flight_states
from .result import Diagnosis, Series
from .where import scaled_residuals, where

__all__ = ["EDGE_S", "MIN_GAIN", "SCHEMA", "Flight", "diagnose", "interior", "prepare"]

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

#: the benchmarks' observability threshold (benchmarks/gap_benchmark.py): a hidden
#: effect whose true values cut the held-out gap by less than this fraction is listed apart
#: as unobservable. Not used by the verdict.
MIN_GAIN = 0.05




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
        log, delays = align_signal_delays(log)    # quadsim.logs.delays (estimate, shift, ms)
        states = flight_states(log, window_s=window_s, gravity=params.gravity)
        states = states.take(interior(states.t))
        dt = float(states.t[1] - states.t[0])
        stride = max(1, round(1.0 / (FIT_RATE_HZ * dt)),
                     int(np.ceil(len(states.t) / MAX_FIT_SAMPLES_PER_FLIGHT)))
        out.append(Flight(name, states, decimated(states, stride), delays.ms(), delays.notes))
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
                              states.window_s, states.polyorder, states.name)
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
    reference = heldout.nominal_reference(fit_on, params, rotor, base)
    weighed = _weigh(fit_on, held_on, reference, effects=effects, map_fn=map_fn,
                     tick=progress or (lambda *_: None))
    sigma = reference.sigma
    before = scaled_residuals(held_on, params, list(base), sigma, rotor=rotor)
    decision = heldout.decide(weighed, train=fit_on, held=held_on, reference=reference,
                              before=before, max_combination=max_combination,
                              tick=progress or (lambda *_: None))
    lead = decision.lead
    effects_after = list(base) + (heldout.effects_of(lead.train)
                                  if decision.lead_name != "no_difference" else [])
    after = [r / sigma for r in lead.held_residuals] if effects_after else before
    dt = float(fit_on[0].t[1] - fit_on[0].t[0])
    statuses = order.order_statuses(list(logs) + list(holdout or []), params)
    decision = order.cap_decision(decision, order.probability_cap(statuses))
    verdict, more = judge_heldout(decision, reference, before=before, after=after, dt=dt)
    verdict = order.mark(verdict, statuses)
    names = channel_names(reference)
    combination = None
    if decision.combination is not None and decision.lead_name == decision.combination.name:
        combination = decision.entry(decision.lead_name)
    return Diagnosis(
        SCHEMA, params.name, "held-out", verdict=verdict,
        train=tuple(f.name for f in train), holdout=tuple(f.name for f in held),
        where=where(held_on, params, names=names, sigma=sigma, before=before, after=after,
                    effects_after=effects_after, base=list(base), kstep=kstep),
        effects=decision.entries, baseline=decision.entry("nominal_refit") or {},
        combination=combination,
        noise_model={"sigma": dict(zip(names, map(float, sigma))),
                     "correlation_samples": dict(zip(names, map(float, reference.tau))),
                     "window_s": heldout.NOISE_WINDOW_S},
        checks=checks, notes=tuple(notes) + more,
        base_effects=tuple({"name": e.name, "params": {
            p.name: float(getattr(e, p.name)) for p in e.parameters}} for e in base),
        series=Series(held_on[0].t, before[0] * sigma, after[0] * sigma, tuple(names),
                      held[0].name, held_on[0], params, tuple(effects_after)))


def params_have_data_map(params: VehicleParams) -> bool:
    """True when the motor map was already fitted from data by the diagnosis."""
    return params.motor_map is not None and "quadsim.gap" in params.motor_map.source


def _weigh(train: list, held: list, reference, *, effects, map_fn, tick) -> list:
    """Every explanation of how the training flights differ from ``reference`` (restricted
    to ``effects`` plus "no difference" and ``nominal_refit``), weighed on the split
    (:func:`quadsim.gap.heldout.weigh`): one call in this process, one task per
    explanation on workers."""
    vbat = None
    if reference.rotor and all(s.vbat is not None and np.all(np.isfinite(s.vbat))
                               for s in train):
        vbat = max(float(np.max(s.vbat)) for s in train)
    expl = heldout.heldout_explanations(reference, stack_states(train), vbat=vbat)
    if effects is not None:
        known = {e.name for e in expl} - {"no_difference"}
        unknown = set(effects) - known
        if unknown:
            raise InputError(f"--effects: unknown or unusable effect(s) {sorted(unknown)}; "
                             f"valid: {', '.join(sorted(known))}")
        expl = [e for e in expl if e.name in set(effects) | {"no_difference", "nominal_refit"}]
    weighed = []
    batches = [expl] if map_fn is map else [[e] for e in expl]
    for ws in map_fn(partial(heldout.weigh, train, held, reference), batches):
        for w in ws:
            weighed.append(w)
            tick(w.name)
    return weighed
