"""Per-flight mode: each flight judged on its own against nominal reference flights, by
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
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..core.errors import InputError, ModelError, QuadsimWarning
from ..logs.delays import delay_notes
from ..logs.flightlog import FlightLog
from ..vehicle.params import VehicleParams
from . import drag_law, order
from .calibrate import Reference, calibrate, inverse_information
from .checks import vehicle_check
from .diagnose import SCHEMA, prepare
from .envelope import envelope_summary, local_reference
from .envelope import position as envelope_position
from .evidence import evaluate, explanations_for
from .judge import channel_names, judge
from .posefree import check_same_kind, without_pose_note
from .residual import DEFAULT_WINDOW_S
from .result import Diagnosis, Verdict
from .selfcheck import leave_one_out, self_check_of
from .traces import flight_series
from .words import batch_answer

__all__ = ["MIN_REFERENCE", "Weighed", "diagnose_per_flight", "judge_one",
           "reference_self_check", "reference_summary", "refused_entry", "verdict_of",
           "weigh_flight"]

#: fewer reference flights than this gives a note (their scatter is poorly known).
MIN_REFERENCE = 10


def diagnose_per_flight(logs: Sequence[FlightLog], reference: Sequence[FlightLog],
                        params: VehicleParams, *, effects: Sequence[str] | None = None,
                        progress: Callable | None = None,
                        window_s: float = DEFAULT_WINDOW_S, map_fn: Callable = map,
                        refused: Sequence[tuple[int, str, str]] = ()) -> Diagnosis:
    """Judge each flight on its own against ``reference`` (nominal) flights (module doc).

    ``refused``: (position, file, reason) of flights refused before this call (the CLI's
    loader and checks); they are placed at their position in ``flights``.
    ``map_fn(fn, logs)`` runs the flights (e.g. a :mod:`quadsim.core.executor` executor).
    Raises :class:`~quadsim.core.errors.InputError` for fewer than two reference flights."""
    ref_flights = prepare(reference, params, window_s=window_s)
    if len(ref_flights) < 2:
        raise InputError("--reference: give at least 2 nominal flights")
    vehicle = vehicle_check([f.fit for f in ref_flights], params)
    ref = calibrate(ref_flights, params)
    ref.self_check = reference_self_check(ref_flights, ref, effects)
    if progress is not None:
        progress("reference")
    notes = ([(f"only {len(ref_flights)} reference flights: their scatter is poorly known; "
              "give 10 or more")] if len(ref_flights) < MIN_REFERENCE else [])
    notes += delay_notes(ref_flights)
    one = partial(judge_one, reference=ref, effects=effects, window_s=window_s)
    flights = []
    for entry in map_fn(one, logs):
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
                     checks=vehicle, notes=tuple(notes))


def reference_summary(ref: Reference) -> dict:
    """The calibrated reference model as JSON: values, pooled standard error, between-flight
    scatter and whether the reference flights determine it (``identified``) per shared
    parameter; noise scale (sigma) and correlation time per channel; the references'
    envelope (:func:`quadsim.gap.envelope.envelope_summary`); their drag as a quadratic
    airframe drag's C_d A (m^2, :func:`quadsim.gap.calibrate.quadratic_equivalent`); the
    speed-per-command exponent their map implies for a propeller change
    (:func:`quadsim.gap.motor_map.load_exponent`); the shared effects' fixed values (the
    thrust curve's centre, rad/s)."""
    names = channel_names(ref)
    return {"params": ref.values(),
            "se": dict(zip(ref.candidate.parameter_names, map(float, ref.se_pool))),
            "scatter": dict(zip(ref.candidate.parameter_names, map(float, ref.scatter))),
            "identified": {k: bool(v) for k, v in ref.identified.items()},
            "at_bound": dict(ref.at_bound),
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


def reference_self_check(ref_flights: list, ref: Reference, effects=None):
    """The references judged against each other (:mod:`quadsim.gap.selfcheck`): each
    reference weighed against :func:`~quadsim.gap.selfcheck.leave_one_out` of ``ref``, then
    judged with the other references' readings as the practical-significance scale. None
    for fewer than 3 references."""
    if len(ref_flights) < 3 or getattr(ref, "log_ms", None) is None:
        return None
    weighed = []
    for j, f in enumerate(ref_flights):
        w = weigh_flight(f, leave_one_out(ref, j), effects, name=f.name)
        weighed.append(w if isinstance(w, Weighed) else None)

    def judge_fn(j, check):
        return verdict_of(weighed[j], check)

    return self_check_of([f.name for f in ref_flights],
                         [None if w is None else w.rows for w in weighed], judge_fn)


def judge_one(log: FlightLog, reference: Reference, effects=None,
              window_s: float = DEFAULT_WINDOW_S, full: bool = False) -> Verdict:
    """One flight's :class:`~quadsim.gap.result.Verdict` (module level: sent to workers);
    ``refused`` with the reason when the flight cannot be judged. ``effects``: restrict the
    explanations; ``window_s`` (s): smoothing window; ``full``: every explanation fully
    fitted (no screen, :func:`quadsim.gap.evidence.evaluate`)."""
    name = str(log.path) if getattr(log, "path", None) is not None else "log"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            flight = prepare([log], reference.params, window_s=window_s)[0]
    except (InputError, ModelError, ValueError, np.linalg.LinAlgError) as exc:
        return refused_entry(name, str(exc))
    weighed = weigh_flight(flight, reference, effects, full=full, name=name)
    if not isinstance(weighed, Weighed):
        return weighed
    verdict = verdict_of(weighed, reference.self_check,
                         order.order_statuses([log], reference.params))
    verdict = without_pose_note(verdict, log)     # what a pose would add (quadsim.gap.posefree)
    local = weighed.reference          # the residual before and after, for the report
    return dataclasses.replace(verdict, series=flight_series(
        local.align(weighed.flight), local, weighed.rows, name=weighed.flight.name))


@dataclass(frozen=True)
class Weighed:
    """One prepared flight weighed against the reference model: ``flight`` (the prepared
    flight), ``rows`` (every explanation's Evidence), ``reference`` (the reference model at
    the flight's place, :func:`quadsim.gap.envelope.local_reference`), ``place`` (its
    envelope position or None), ``law`` (the drag law it is judged under, or None)."""

    flight: object
    rows: list
    reference: Reference
    place: object
    law: object


def weigh_flight(flight, reference: Reference, effects=None, *, full: bool = False,
                 name: str = "log") -> Weighed | Verdict:
    """The :class:`Weighed` of a prepared flight, or its ``refused`` verdict."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            states = reference.align(flight)       # the references' rotor-speed timing
            check_same_kind(states, reference, name)   # a pose on both or neither (posefree)
            if states.command is None and reference.rotor:
                raise InputError(f"{name}: cmd_1..cmd_N: the reference flights log motor "
                                 "commands, this one does not")
            if len(states.t) < 20:
                raise InputError(f"{name}: t: too short to judge ({len(states.t)} samples "
                                 "after smoothing)")
            trend = getattr(reference.envelope, "trend", None)
            info = (inverse_information(states, reference)
                    if trend is not None and trend.q_weight is not None
                    and np.any(trend.q_weight > 0) else None)
            place = envelope_position(states, reference.envelope, info)
            reference = local_reference(reference, place)   # the model at this flight
            start = 0.0
            mine = (flight.delays_ms or {}).get("rotor")
            if mine is not None and "rotor" in reference.delays_ms:
                start = 1e-3 * mine - reference.rotor_shift_s
            memo: dict = {}        # the flight's residual parts and shared Jacobian, kept
            law = drag_law.choose(states, reference, start, memo)
            expl = drag_law.under(explanations_for(reference, states, effects), law)
            rows = evaluate(states, reference, expl, start_delay_s=start, full=full, memo=memo)
    except (InputError, ModelError, ValueError, np.linalg.LinAlgError) as exc:
        return refused_entry(name, str(exc))
    return Weighed(flight, rows, reference, place, law)


def verdict_of(weighed: Weighed, check=None, statuses=()) -> Verdict:
    """The :class:`~quadsim.gap.result.Verdict` of a :class:`Weighed` flight, judged with the
    references' self-check ``check`` (:class:`quadsim.gap.selfcheck.SelfCheck`, or None) and
    the rotor-order ``statuses`` of its log (:mod:`quadsim.gap.order`; none: not checked)."""
    flight, rows, place, law = weighed.flight, weighed.rows, weighed.place, weighed.law
    reference = dataclasses.replace(weighed.reference, self_check=check)
    verdict = order.mark(judge(rows, reference, flight.name,
                               cap=order.probability_cap(statuses)), statuses)
    words = verdict.answer
    if law is not None:       # the drag law in words; None: the references'
        words += f" Judged with {law.variant} (the law this flight shows)."
    if place is not None and place.distance > 0:
        words += f" Flown {place.text}."
    return dataclasses.replace(
        verdict, answer=words, drag_law=None if law is None else law.variant,
        envelope=None if place is None else place.to_json(),
        signal_delays_ms=flight.delays_ms,
        notes=verdict.notes + tuple(delay_notes([flight])))


def refused_entry(name: str, reason: str) -> Verdict:
    """The verdict of a flight that could not be judged, with the reason."""
    return Verdict("refused", "refused", f"Not judged: {reason}", None, file=name,
                   reason=reason)
