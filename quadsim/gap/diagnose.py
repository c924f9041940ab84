"""The gap diagnosis: prepare the logs, split by flight, judge by evidence (:mod:`.heldout`).

See :mod:`quadsim.gap` for the method and the result schema. Everything here returns plain
dicts (the ``quadsim.gap/3`` JSON) so that the CLI, the HTML report and tests read the same
thing.
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
from . import collinear, consistency, heldout
from . import heldout_verdict as hv
from .baseline import BASELINE, NominalRefit  # noqa: F401  (re-exported)
from .checks import check_length, vehicle_check
from .fitting import fit_motor_map, stack_states
from .priors import candidate_plausibility
from .residual import DEFAULT_WINDOW_S, FlightStates, channel_unit, flight_states
from .scoring import _channel_rms, _channels, _gap, _scaled
from .where import by_band, by_regime, kstep_errors, regime_masks

__all__ = ["Flight", "prepare", "diagnose", "SCHEMA", "MIN_GAIN", "EDGE_S", "interior"]

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

SEPARATE = collinear.SEPARATE
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

    The first and last :data:`EDGE_S` = 0.2 s of each log (at most 10 % of its duration per
    end) are dropped after smoothing: there the derived signals are not valid. The
    Savitzky–Golay derivatives fall back to a one-sided polynomial fit (noise gain several
    times the centre's) within half a window of an end, and a log's own offline filters
    leave transients there: a zero-phase 2nd-order low-pass at f_c (Butterworth, zeta =
    0.707) decays to 1 % in 4.6 / (zeta 2 pi f_c) ~= 1.04 / f_c, i.e. 0.05 s at 20 Hz and
    0.1 s at 10 Hz; a finite-difference accelerometer is one-sided at the ends, and a
    delayed signal is held at its first sample. Measured on the independent benchmark's
    sensor-pipeline nominal flights (20 Hz finite-difference accelerometer, 8 ms mocap
    latency): within 0.05 s of an end the force residual is 20-90x its interior RMS and
    carried 70-99 % of a flight's force residual; beyond 0.15 s it is at the interior level
    (docs/gap.md). 0.2 s covers the Savitzky–Golay window twice over and low-pass filters
    down to 5 Hz; it costs 5 % of an 8 s flight.

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
        stride = max(1, int(round(1.0 / (FIT_RATE_HZ * dt))),
                     int(np.ceil(len(states.t) / MAX_FIT_SAMPLES_PER_FLIGHT)))
        out.append(Flight(name, states, decimated(states, stride), delays.ms(), delays.notes))
    return out


def decimated(states: FlightStates, stride: int) -> FlightStates:
    """Every ``stride``-th sample of ``states`` (the fit view), low-passed first below the
    new Nyquist frequency: a zero-phase 4th-order Butterworth at :data:`ANTI_ALIAS` of it on
    every signal but the quaternion (already smooth; a filtered one would leave the unit
    sphere). Why: picking samples folds what lies above the fit rate's Nyquist frequency
    into its band. PyFlyt's rotor speeds carry a 60 Hz ripple (a third of their variance
    above 30 Hz; 240 Hz log, 120 Hz fit): picked, it became a ripple at the fit's Nyquist
    frequency whose size rose and fell with the rotor log's timing, so the references'
    timing settled where it vanished (:func:`quadsim.gap.reference.aligned`) and a rotor log
    11 ms late was read as a slower motor at 0.98."""
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


def _where(held, params, sigma, rotor, before, effects_after, after, kstep,
           base=()) -> dict:
    masks = [regime_masks(f.fit, params) for f in held]
    dt = float(held[0].fit.t[1] - held[0].fit.t[0])
    names = _channels(rotor, params)
    energy = np.sum(np.concatenate(before) ** 2, axis=0)
    return {
        "channels": names,
        "noise_scale": dict(zip(names, map(float, sigma))),
        "heldout_rms_before": dict(zip(names, map(float, _channel_rms(before, sigma)))),
        "heldout_rms_after": dict(zip(names, map(float, _channel_rms(after, sigma)))),
        "channel_share": dict(zip(names, map(float, energy / max(energy.sum(), 1e-300)))),
        "regime": by_regime(before, masks),
        "regime_after": by_regime(after, masks),
        "band": by_band(before, dt),
        "kstep_before": kstep_errors([f.fit for f in held], params, list(base)) if kstep
        else {},
        "kstep_after": kstep_errors([f.fit for f in held], params, effects_after) if kstep else {},
    }


def _split(flights: list[Flight], holdout: list[Flight] | None, notes: list[str]):
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
             map_fn: Callable = map, base_effects: Sequence = ()) -> dict:
    """Diagnose the gap between ``params`` and ``logs`` (see :mod:`quadsim.gap`).

    ``base_effects``: effects already in the model (e.g. from an effect file,
    :mod:`quadsim.effects.effectfile`): the diagnosis starts from ``params`` plus them -- the
    "before" gap is theirs, every candidate is fitted and scored on top of them, and they
    are never refitted -- so that a diagnosed model can be diagnosed again.

    ``kstep=False`` skips the k-step prediction errors (the slowest part of "where").
    ``map_fn(fn, items)`` runs the candidate fits (e.g. a :mod:`quadsim.core.executor` executor)."""
    notes: list[str] = []
    flights = prepare(logs, params, window_s=window_s)
    held_in = prepare(holdout, params, window_s=window_s) if holdout else None
    checks = vehicle_check([f.fit for f in flights + (held_in or [])], params)
    notes.extend(delay_notes(flights + (held_in or [])))
    train, held = _split(flights, held_in, notes)
    result = _diagnose_split(train, held, params, effects, max_combination, progress, notes,
                             kstep, map_fn, tuple(base_effects))
    result["checks"] = checks
    if base_effects:
        result["base_effects"] = [{"name": e.name, "params": {
            p.name: float(getattr(e, p.name)) for p in e.parameters}} for e in base_effects]
    return result


def params_have_data_map(params: VehicleParams) -> bool:
    """True when the motor map was already fitted from data by the diagnosis."""
    return params.motor_map is not None and "quadsim.gap" in params.motor_map.source


def _diagnose_split(train, held, params, effect_names, max_combination, progress, notes,
                    kstep=False, map_fn=map, base=()):
    """The held-out verdict by evidence (:mod:`.heldout`, :mod:`.heldout_verdict`)."""
    rotor = all(f.fit.command is not None for f in train + held)
    if rotor and not params_have_data_map(params):
        params = fit_motor_map([f.fit for f in train], params)
    fit_on, held_on = [f.fit for f in train], [f.fit for f in held]
    reference = heldout.nominal_reference(fit_on, params, rotor, base)
    sigma = reference.sigma
    vbat = None
    if rotor and all(s.vbat is not None and np.all(np.isfinite(s.vbat)) for s in fit_on):
        vbat = max(float(np.max(s.vbat)) for s in fit_on)
    expl = heldout.heldout_explanations(reference, stack_states(fit_on), vbat=vbat)
    if effect_names is not None:
        known = {e.name for e in expl} - {"no_difference"}
        unknown = set(effect_names) - known
        if unknown:
            raise InputError(f"--effects: unknown or unusable effect(s) {sorted(unknown)}; "
                             f"valid: {', '.join(sorted(known))}")
        expl = [e for e in expl if e.name in set(effect_names) | {"no_difference",
                                                                   "nominal_refit"}]
    tick = progress or (lambda *_: None)
    weighed = []
    # one evaluate call in one process (the shared Jacobian once), one task per explanation
    # on workers
    batches = [expl] if map_fn is map else [[e] for e in expl]
    for ws in map_fn(partial(heldout.weigh, fit_on, held_on, reference), batches):
        for w in ws:
            weighed.append(w)
            tick(w.name)
    before = _scaled(held, params, list(base), sigma, rotor)
    decision = hv.decide(weighed, fit_on, held_on, reference, before, max_combination, tick)
    lead = decision["lead"]
    effects_after = list(base) + (heldout.effects_of(lead.train)
                                  if decision["lead_name"] != "no_difference" else [])
    after = [r / sigma for r in lead.held_residuals] if effects_after else before
    verdict = _verdict(decision, train, held, reference, before, after, notes)
    names = _channels(rotor, params)
    result = {
        "schema": SCHEMA,
        "model": params.name,
        "train": [f.name for f in train], "holdout": [f.name for f in held],
        "where": _where(held, params, sigma, rotor, before, effects_after, after, kstep, base),
        "baseline": _public(decision["baseline"] or {}),
        "effects": [_public(e) for e in decision["entries"]],
        "verdict": verdict,
        "noise_model": {"sigma": dict(zip(names, map(float, sigma))),
                        "correlation_samples": dict(zip(names, map(float, reference.tau))),
                        "window_s": heldout.NOISE_WINDOW_S},
        "notes": notes,
    }
    if decision["combination"] is not None and decision["lead_name"] == \
            decision["combination"].name:
        result["combination"] = _public(next(e for e in decision["entries"]
                                             if e["name"] == decision["lead_name"]))
    # Arrays for plots and recordings (not part of the JSON): first held-out flight.
    result["_series"] = {"t": held[0].fit.t, "before": before[0] * sigma,
                         "after": after[0] * sigma, "channels": names,
                         "flight": held[0].name, "states": held[0].fit, "params": params,
                         "effects": effects_after}
    return result


FLOOR_SOURCE = ("the noise model: the short-window (0.5 s) scatter of the nominal residual "
                "on the training flights")


def _verdict(decision, train, held, reference, before, after, notes) -> dict:
    """The ``verdict`` block (schema in :mod:`.schema`; rule in :mod:`.heldout_verdict`)."""
    params = reference.params
    names = _channels(reference.rotor, params)
    dt = float(train[0].fit.t[1] - train[0].fit.t[0])
    rows, lead_name, lead = decision["rows"], decision["lead_name"], decision["lead"]
    entry = next((e for e in decision["entries"] if e["name"] == lead_name), None)
    p_lead = decision["probability"][lead_name]
    for name, magnitude, prior_text in decision["implausible"]:
        notes.append(f"{name} fits only at an implausible magnitude ({_words_of(magnitude)}; "
                     f"{prior_text}): given no weight")
    stated = [r for r in rows if r["probability"] >= hv.READING_P
              and r["name"] != "no_difference"]
    remains = hv.remainder(lead, reference, dt)
    carries = hv.generalisation(lead, reference, decision.get("null")) \
        if entry is not None else {}
    outcome = "effect" if entry is not None else (
        "unexplained" if remains else "no_significant_gap")
    ok, prior_text = hv.plausible(entry, params) if entry is not None else (True, "")
    if entry is not None and not ok:
        notes.append(f"{lead_name} is the most probable reading only with an implausible "
                     f"magnitude ({rows[0]['magnitude']}; {prior_text}): not named")
        outcome = "unexplained"
    rms_before, rms_after = _channel_rms(before, reference.sigma), _channel_rms(after,
                                                                                 reference.sigma)
    flagged = set(remains) | set(carries)
    channels = {n: {"before": float(b), "after": float(a), "floor": float(s),
                    "unit": channel_unit(n), "at_floor": n not in flagged}
                for n, b, a, s in zip(names, rms_before, rms_after, reference.sigma)}
    others = [r["name"] for r in stated if r["name"] != lead_name]
    listed = [r for r in rows if r["name"] == lead_name] + [r for r in stated
                                                           if r["name"] != lead_name]
    # the two most probable readings after those stated: what else was weighed, and how much
    listed += [r for r in rows if r not in listed and r["name"] != "no_difference"][:2]
    alts = [_alternative(r, decision, lead_name, params) for r in listed
            if r["name"] != "no_difference"]
    verdict = {
        "outcome": outcome,
        "effect": lead_name if outcome == "effect" else outcome,
        "probability": p_lead,
        "tentative": outcome == "effect" and p_lead < hv.CONFIDENT,
        "floor_source": FLOOR_SOURCE,
        "channels": channels,
        "alternatives": alts if entry is not None else [],
        "posterior": rows,
        "best_candidate": next((r["name"] for r in rows if r["name"] != "no_difference"),
                               None),
        "lack_of_fit": {**{k: v[1] ** 0.5 for k, v in remains.items()},
                        **{k: v[0] for k, v in carries.items()}},
        "heldout_channel_gap_after": dict(zip(names, map(float, np.mean(
            np.concatenate(after) ** 2, axis=0)))),
        "reduction": entry["reduction"] if entry else 0.0,
        "confusable_with": others if outcome == "effect" else [],
        "readings": ([lead_name] + others) if outcome == "effect" else [],
        "separate_by": hv.separate_by(lead_name, others) if outcome == "effect" else {},
        "params": entry["params"] if entry else {},
        "ci": entry["ci"] if entry else {},
        "fixed": entry["fixed"] if entry else {},
        "units": {k: collinear.unit_of(k) for k in (entry["params"] if entry else {})},
        "heldout_gap_before": _gap(before),
        "heldout_gap_after": entry["heldout_gap_after"] if entry else _gap(before),
    }
    verdict["answer"] = _answer(verdict, rows, remains, carries, reference)
    if outcome == "effect":    # one value in every regime, or not named
        consistency.apply_to_verdict(verdict, notes, decision["consistency"])
        if verdict["outcome"] == "effect" and carries:
            verdict.update(outcome="unexplained", effect="unexplained", readings=[],
                           confusable_with=[], separate_by={},
                           answer=_answer({**verdict, "outcome": "unexplained"}, rows,
                                          remains, carries, reference))
    return verdict


def _words_of(text: str) -> str:
    return hv._words(text, True)


def _alternative(row, decision, lead_name, params) -> dict:
    entry = next((e for e in decision["entries"] if e["name"] == row["name"]), {})
    score, ok, prior = candidate_plausibility(row["params"], params)
    alt = {"name": row["name"], "magnitude": row["magnitude"], "params": row["params"],
           "ci": row["ci"], "units": {k: collinear.unit_of(k) for k in row["params"]},
           "probability": row["probability"], "reduction": entry.get("reduction"),
           "torque_yaw": collinear._torque_text(entry), "plausibility": score,
           "plausible": bool(ok), "prior": prior}
    if row["name"] != lead_name:
        alt["separate_by"] = collinear.separation(lead_name, [row["name"]])[row["name"]]
    return alt


def _pct(p: float) -> str:
    return f"{100 * p:.0f} %" if p < 0.995 else "> 99 %"


def _remains_text(remains: dict) -> str:
    return ", ".join(f"{k} {v[0]:.2g} {channel_unit(k)} ({v[1] ** 0.5:.1f}x the noise's)"
                     for k, v in remains.items())


def _answer(verdict, rows, remains, carries, reference) -> str:
    """The verdict in words a quadrotor engineer acts on."""
    lead = rows[0]
    if verdict["outcome"] == "no_significant_gap":
        nxt = next((r for r in rows[1:] if r["probability"] >= hv.READING_P), None)
        return (f"No significant gap: no difference from the nominal model is the most "
                f"probable reading ({_pct(lead['probability'])}) and the residual is within "
                f"the noise on every channel." + (f" Next: {nxt['name']} "
                                                  f"({_pct(nxt['probability'])}: "
                                                  f"{nxt['magnitude']})." if nxt else ""))
    if verdict["outcome"] == "unexplained":
        if carries:
            where = ", ".join(f"{k} at {v[0]:.2g}x" for k, v in carries.items())
            return (f"Unexplained: the most probable reading ({lead['name']}, "
                    f"{_pct(lead['probability'])}: {lead['magnitude']}) leaves the held-out "
                    f"flights beyond what it leaves on the training flights ({where} their "
                    "RMS): it does not carry over; the cause is outside the library, several "
                    "effects at once, or the data cannot tell.")
        if lead["name"] != "no_difference":
            return (f"Unexplained: the most probable reading ({lead['name']}: "
                    f"{lead['magnitude']}) needs an implausible magnitude; the cause is "
                    "outside the library.")
        return ("Unexplained: no library effect explains the residual (no difference from "
                f"the nominal model is the most probable reading, {_pct(lead['probability'])}"
                f"), yet a systematic residual stays beyond the noise: {_remains_text(remains)}"
                " (slow part, RMS). The cause is outside the library.")
    text = f"Behaves as if {lead['magnitude']} ({_pct(lead['probability'])})"
    rest = [r for r in rows[1:] if r["probability"] >= hv.READING_P
            and r["name"] != "no_difference"]
    if rest:
        text += "; or as if " + "; or as if ".join(
            f"{r['magnitude']} ({_pct(r['probability'])})" for r in rest)
        text += f" (to separate them: {verdict['separate_by'].get(rest[0]['name'], '')})"
    if verdict["tentative"]:
        text += ". Tentative"
    text += f". Explains {100 * verdict['reduction']:.0f} % of the held-out gap"
    if remains:
        text += (f"; beyond it a systematic residual stays above the noise on "
                 f"{_remains_text(remains)}: part of the gap is outside the library.")
    else:
        text += ", the residual within the noise on every channel after it."
    return text


def _public(entry: dict) -> dict:
    return {k: v for k, v in entry.items() if not k.startswith("_")}
