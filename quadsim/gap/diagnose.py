"""The gap diagnosis: fit on training flights, score on held-out flights, rank, decide.

See :mod:`quadsim.gap` for the method and the result schema. Everything here returns plain
dicts (the ``quadsim.gap/3`` JSON) so that the CLI, the HTML report and tests read the same
thing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from ..core.errors import InputError
from ..effects.base import EffectBase, EffectParameter
from ..logs.delays import align_signal_delays, delay_notes
from ..logs.flightlog import FlightLog
from ..vehicle.params import VehicleParams
from . import collinear, consistency, fitting
from . import verdict as rule
from .checks import vehicle_check
from .combine import _combination_alternatives, _greedy, parts_identified
from .fitting import (
    Candidate,
    candidates_for,
    fit_candidate,
    fit_motor_map,
    noise_floor,
    noise_scale,
    residuals,
)
from .residual import DEFAULT_WINDOW_S, FlightStates, flight_states
from .scoring import (
    MIN_GAIN,
    MIN_T,
    TIE,
    _channel_rms,
    _channels,
    _clear,
    _fit_score,
    _gap,
    _scaled,
    _score,
)
from .where import by_band, by_regime, kstep_errors, regime_masks

__all__ = ["Flight", "prepare", "diagnose", "parts_identified", "SCHEMA", "MIN_GAIN",
           "MIN_T", "TIE", "EDGE_S", "interior"]

SCHEMA = "quadsim.gap/3"
FIT_RATE_HZ = 100.0
#: long flights are decimated further so that one flight costs at most this many samples.
MAX_FIT_SAMPLES_PER_FLIGHT = 20000
#: samples closer than this (s) to either end of a log are neither fitted nor scored (see
#: :func:`prepare`); at most :data:`MAX_EDGE_SHARE` of a flight's duration per end.
EDGE_S = 0.2
MAX_EDGE_SHARE = 0.1

SEPARATE = collinear.SEPARATE


class NominalRefit(EffectBase):
    """Baseline: the nominal thrust and drag factors refitted (relative changes)."""

    name = "nominal_refit"
    parameters = (
        EffectParameter("thrust", "1", 0.0, -0.5, 0.5, "relative change of b"),
        EffectParameter("drag", "1", 0.0, -0.9, 3.0, "relative change of d"),
    )

    def apply_to_params(self, params):
        return params.replace(thrust_factor=params.thrust_factor * (1 + self.thrust),
                              drag_factor=params.drag_factor * (1 + self.drag))


fitting.LOCAL_EFFECTS["nominal_refit"] = NominalRefit
fitting.FIT_SPEC["nominal_refit"] = (("thrust", "drag"), {}, lambda p: [0.05, 0.2])
BASELINE = Candidate("nominal_refit", (("nominal_refit", {}, ("thrust", "drag")),))


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

    Raises :class:`InputError` for a rotor-count mismatch or logs without rotor speeds."""
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
        log, delays = align_signal_delays(log)    # quadsim.logs.delays (estimate, shift, ms)
        states = flight_states(log, window_s=window_s, gravity=params.gravity)
        states = states.take(interior(states.t))
        dt = float(states.t[1] - states.t[0])
        stride = max(1, int(round(1.0 / (FIT_RATE_HZ * dt))),
                     int(np.ceil(len(states.t) / MAX_FIT_SAMPLES_PER_FLIGHT)))
        index = np.arange(0, len(states.t), stride)
        out.append(Flight(name, states, states.take(index), delays.ms(), delays.notes))
    return out


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


def _separation(best: str, confusable: list[str]) -> dict:
    return collinear.separation(best, confusable)


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
    rotor = all(f.fit.command is not None for f in train + held)
    if rotor and not params_have_data_map(params):
        params = fit_motor_map([f.fit for f in train], params)
    dt = float(held[0].fit.t[1] - held[0].fit.t[0])
    nominal_train = [residuals(f.fit, params, list(base), rotor_channel=rotor) for f in train]
    sigma = noise_scale(np.concatenate(nominal_train), float(train[0].fit.t[1] - train[0].fit.t[0]),
                        floor=noise_floor(params, rotor))
    before = _scaled(held, params, list(base), sigma, rotor)
    has_vbat = all(f.fit.vbat is not None and np.all(np.isfinite(f.fit.vbat)) for f in train)
    cands = [replace(c, base=base) for c in candidates_for(params, rotor, has_vbat)]
    if effect_names is not None:
        unknown = set(effect_names) - {c.name for c in cands}
        if unknown:
            raise InputError(f"--effects: unknown or unusable effect(s) {sorted(unknown)}; "
                             f"valid: {', '.join(c.name for c in cands)}")
        cands = [c for c in cands if c.name in effect_names]
    tick = progress or (lambda *_: None)
    fit_on = [f.fit for f in train]
    baseline = _score(fit_candidate(replace(BASELINE, base=base), fit_on, params, sigma,
                                    rotor_channel=rotor),
                      train, held, params, sigma, rotor, before, dt)
    tick("nominal_refit")
    scored = []
    for cand, entry in zip(cands, map_fn(partial(_fit_score, train=train, held=held,
                                                 params=params, sigma=sigma, rotor=rotor,
                                                 before=before, dt=dt), cands)):
        scored.append(entry)
        tick(cand.name)
    # Candidates of one name that differ in a fixed value (a canted rotor's index): the one
    # that fits the training flights best stands for the effect (held-out data not used).
    best_of = {}
    for entry in scored:
        kept = best_of.get(entry["name"])
        if kept is None or entry["_fit"].cost < kept["_fit"].cost:
            best_of[entry["name"]] = entry
    scored = [e for e in scored if best_of[e["name"]] is e]
    for s in scored:
        bad = [k for k, ok in s["identifiable"].items() if not ok]
        if bad:
            s["warning"] = ("too little excitation to fit " + ", ".join(bad)
                            + " on these flights (CI wider than half the plausible range)")
    nominal = max(_gap(before), 1e-300)
    ranked = sorted(scored, key=lambda s: (round(s["heldout_gap_after"] / nominal, 4),
                                           len(s["params"]), s["name"]))
    return _decide(ranked, baseline, train, held, params, sigma, rotor, before, dt,
                   max_combination, notes, tick, kstep, base)


def _decide(ranked, baseline, train, held, params, sigma, rotor, before, dt, max_combination,
            notes, tick, kstep, base=()) -> dict:
    """Pick the named effect, grow it into a combination, judge it against the floor and
    assemble the result (``quadsim.gap/3``)."""
    nominal_gap = _gap(before)
    names = _channels(rotor, params)
    best, alts = _pick(ranked, baseline, nominal_gap, params, notes)
    combined = best
    if best is not None:
        combined = _greedy(best, ranked, train, held, params, sigma, rotor, before, dt,
                           max_combination, nominal_gap, tick)
        if combined is not best:
            alts = _combination_alternatives(combined, best, alts, params)
    effects_after = combined["_fit"].effects() if combined else list(base)
    after = _scaled(held, params, effects_after, sigma, rotor)
    if best is None and _clear(baseline, nominal_gap, nominal_gap):
        notes.append("the held-out gap shrinks with refitted b and d (nominal_refit) but no "
                     "library effect explains more: the nominal parameters are off")
    kind, channels, lack = _judge(combined, baseline, train, params, sigma, rotor, before,
                                  after, effects_after, names, notes)
    verdict = _verdict(kind, combined, alts, channels, lack, ranked, after, names,
                       nominal_gap, notes)
    if combined is not None and kind == "effect":   # one value in every regime, or not named
        fit = combined["_fit"]
        consistency.apply_to_verdict(verdict, notes, consistency.check(
            fit.candidate, fit.theta, consistency.judged_parameters(combined),
            [f.fit for f in train + held], params, sigma, rotor))
    result = {
        "schema": SCHEMA,
        "model": params.name,
        "train": [f.name for f in train], "holdout": [f.name for f in held],
        "where": _where(held, params, sigma, rotor, before, effects_after, after, kstep, base),
        "baseline": _public(baseline),
        "effects": [_public(e) for e in ranked],
        "verdict": verdict,
        "notes": notes,
    }
    if combined is not None and combined is not best:
        result["combination"] = _public(combined)
    # Arrays for plots and recordings (not part of the JSON): first held-out flight.
    result["_series"] = {"t": held[0].fit.t, "before": before[0] * sigma,
                         "after": after[0] * sigma, "channels": names,
                         "flight": held[0].name, "states": held[0].fit, "params": params,
                         "effects": effects_after}
    return result


def _pick(ranked, baseline, nominal_gap, params, notes) -> tuple[dict | None, list[dict]]:
    """The named effect and its collinear alternatives (described, most plausible first).

    An effect wins only if it beats the nominal model clearly and is not clearly worse than
    simply refitting b and d (a retuned nominal model). Among the winners whose held-out gap
    ties with the best (within TIE), the most plausible magnitude is named (priors); ties in
    plausibility go to fewer parameters. ``ranked`` is reordered: the named effect first."""
    tie = TIE * nominal_gap
    winners = [e for e in ranked if _clear(e, nominal_gap, nominal_gap) and
               e["heldout_gap_after"] <= baseline["heldout_gap_after"] + tie]
    if not winners:
        return None, []
    floor = winners[0]["heldout_gap_after"] + tie
    tied = [e for e in winners if e["heldout_gap_after"] <= floor]
    first = min(tied, key=lambda e: (len(e["params"]), e["heldout_gap_after"]))
    others = [e for e in ranked if e is not first
              and abs(e["heldout_gap_after"] - first["heldout_gap_after"]) <= tie
              and len(e["params"]) <= len(first["params"]) + 1 and parts_identified(e)]
    if baseline["heldout_gap_after"] - first["heldout_gap_after"] <= tie:
        others.append(baseline)
    best, alts = collinear.pick_plausible(first, others, params)
    if best is None:
        notes.append(f"{first['name']} explains the gap only with an implausible magnitude "
                     f"({alts[0]['magnitude']}; {alts[0]['prior']}): flagged, not named")
        return None, alts
    if best is baseline:
        return first, alts  # the refit ties: name the library effect, list the refit
    ranked.remove(best)
    ranked.insert(0, best)
    return best, alts


def _judge(combined, baseline, train, params, sigma, rotor, before, after, effects_after,
           names, notes) -> tuple[str, dict, dict]:
    """The outcome against the floor (:mod:`.verdict`): (kind, channel table, lack of fit).
    The floor is the in-sample (training) residual of the model judged (nominal: b, d
    refitted); a nominal floor above MAX_FLOOR x the noise forbids "no significant gap"."""
    base_train = _scaled(train, params, baseline["_fit"].effects(), sigma, rotor)
    floor_nominal = np.maximum(_channel_rms(base_train, sigma), sigma)
    floor_after = floor_nominal if combined is None else np.maximum(
        _channel_rms(_scaled(train, params, effects_after, sigma, rotor), sigma), sigma)
    rms_before, rms_after = _channel_rms(before, sigma), _channel_rms(after, sigma)
    channels = rule.channel_table(names, rms_before, rms_after, floor_after)
    kind = rule.outcome(combined is not None, rms_before, floor_nominal)
    too_high = [n for n, f, s_ in zip(names, floor_nominal, sigma) if f > rule.MAX_FLOOR * s_]
    if kind == "no_significant_gap" and too_high:
        kind = "unexplained"
        notes.append("the refitted nominal model itself leaves " + ", ".join(too_high)
                     + f" above {rule.MAX_FLOOR:g}x the noise on the training flights: not "
                     "claiming 'no significant gap'")
    lack = {n: c["after"] / max(c["floor"], 1e-300) for n, c in channels.items()
            if not c["at_floor"]}
    if combined is not None and lack:
        notes.append(f"{combined['name']} cuts the held-out gap by "
                     f"{100 * combined['reduction']:.0f} % but leaves "
                     + ", ".join(f"{k} at {v:.1f}x the floor" for k, v in lack.items())
                     + ": part of the gap is outside the library (or not one effect)")
    return kind, channels, lack


def _verdict(kind, combined, alts, channels, lack, ranked, after, names, nominal_gap,
             notes) -> dict:
    """The ``verdict`` block of the result (schema in :mod:`.schema`)."""
    confusable = [a["name"] for a in alts if combined and a["name"] != combined["name"]]
    if combined is not None and confusable:
        notes.append(collinear.collinear_note(combined["name"], alts))
    floor_source = "the training flights' own in-sample residual (b, d refitted)"
    name = combined["name"] if combined else kind
    named = combined or {}
    return {
        "outcome": kind,
        "effect": name,
        "answer": rule.answer(kind, name, named.get("reduction", 0.0),
                              alts if combined else [], channels, floor_source),
        "floor_source": floor_source,
        "channels": channels,
        "alternatives": alts if combined else [],
        "best_candidate": (combined or (ranked[0] if ranked else None) or {}).get("name"),
        "lack_of_fit": lack,
        "heldout_channel_gap_after": dict(zip(names, map(float, np.mean(
            np.concatenate(after) ** 2, axis=0)))),
        "reduction": named.get("reduction", 0.0),
        "confusable_with": confusable,
        "readings": [a["name"] for a in rule.stated_readings(alts)] if combined else [],
        "separate_by": _separation(combined["name"], confusable) if combined else {},
        "params": named.get("params", {}),
        "ci": named.get("ci", {}),
        "fixed": named.get("fixed", {}),
        "units": {k: collinear.unit_of(k) for k in named.get("params", {})},
        "heldout_gap_before": nominal_gap,
        "heldout_gap_after": named.get("heldout_gap_after", nominal_gap),
    }


def _public(entry: dict) -> dict:
    return {k: v for k, v in entry.items() if not k.startswith("_")}
