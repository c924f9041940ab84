"""Per-flight mode: each flight judged on its own against nominal reference flights.

Used as ``python -m quadsim.gap --per-flight LOG... --reference NOMINAL...`` or::

    >>> from quadsim.gap import diagnose_per_flight
    >>> result = diagnose_per_flight(flights, nominal_flights, load_params("crazyflie21"))
    >>> [(f["file"], f["outcome"], f["verdict"]) for f in result["flights"]]

Method
------
1. The nominal thrust and drag factors are refitted on the reference flights (so the
   reference defines "nominal"), and the static motor map is fitted on them.
2. Every reference flight is diagnosed alone (first half trains, second half is held out):
   per effect its held-out reduction and its fitted parameters (value, 95 % CI, identified
   or not); per channel the held-out RMS of the nominal model (the *floor*: the largest over
   the reference flights).
3. Each flight under test is diagnosed the same way and judged (:func:`judge_flight`).

The rule (per flight)
---------------------
An effect *differs from the references* when

* it explains a clear share on this flight (held-out reduction >= ``MIN_GAIN``, block
  t >= ``MIN_T``, each of its effects with a parameter identified and significantly away
  from "off");
* its reduction beats the largest the same effect achieves on any reference flight by
  ``MIN_GAIN`` (effects that help every nominal flight alike, real drag or an imperfect
  motor map, are not named); and
* its **magnitude** differs from the references' (:func:`differs_from_reference`): some
  parameter that is identified and significant here lies outside the band the reference
  flights span, ``[min(r_j - c_j), max(r_j + c_j)]`` over the references that identified it
  (value r_j, 95 % half-width c_j), by more than its own 95 % half-width. A reduction alone
  is not invariant to the manoeuvre: a nominal RotorPy flight flown faster than its
  references showed its motors' 7.2 ms lag more strongly (reduction 0.79 against at most
  0.69 on the references) although the lag was the same 7.2 ms (references 7.0-7.3 ms).

Among the effects that differ, those within ``TIE`` of the largest excess are collinear;
the most plausible (priors) is named and the others are listed. No effect differs: if the
nominal held-out RMS is at the floor on every channel, ``no_significant_gap``; if it is
not, but an effect at the references' own magnitude (*shared*) brings every channel to the
floor, ``no_significant_gap`` as well, with a note naming that shared effect (a model
error of the nominal vehicle, not a difference of this flight); else ``unexplained``.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from functools import partial

import numpy as np

from ..core.errors import InputError, QuadsimWarning
from ..logs.delays import delay_notes
from ..logs.flightlog import FlightLog
from ..vehicle.params import VehicleParams
from . import collinear, consistency
from . import verdict as rule
from .checks import vehicle_check
from .combine import parts_identified
from .diagnose import (
    BASELINE,
    MIN_GAIN,
    MIN_T,
    SCHEMA,
    TIE,
    Flight,
    _diagnose_split,
    prepare,
)
from .fitting import (
    NO_OFF_VALUE,
    candidates_for,
    fit_candidate,
    fit_motor_map,
    noise_floor,
    noise_scale,
    residuals,
)
from .residual import DEFAULT_WINDOW_S

__all__ = ["diagnose_per_flight", "judge_flight", "differs_from_reference",
           "per_flight_answer", "PER_FLIGHT_TIE", "MIN_REFERENCE"]

#: per-flight mode: effects within this held-out reduction of the named one are confusable.
PER_FLIGHT_TIE = 0.05
#: per-flight mode: fewer reference flights than this gives a note (spread poorly known).
MIN_REFERENCE = 10


def diagnose_per_flight(logs: Sequence[FlightLog], reference: Sequence[FlightLog],
                        params: VehicleParams, *, effects: Sequence[str] | None = None,
                        progress: Callable | None = None,
                        window_s: float = DEFAULT_WINDOW_S, map_fn: Callable = map) -> dict:
    """Judge each flight on its own against ``reference`` (nominal) flights (module doc).

    ``map_fn(fn, logs)`` runs the flights (e.g. a :mod:`quadsim.core.executor` executor).
    Raises :class:`~quadsim.core.errors.InputError` for fewer than two reference flights."""
    ref = prepare(reference, params, window_s=window_s)
    if len(ref) < 2:
        raise InputError("--reference: give at least 2 nominal flights")
    vehicle = vehicle_check([f.fit for f in ref], params)
    rotor = all(f.fit.command is not None for f in ref)
    if rotor:
        params = fit_motor_map([f.fit for f in ref], params)
    sigma0 = noise_scale(np.concatenate([residuals(f.fit, params, [], rotor_channel=rotor)
                                         for f in ref]), float(ref[0].fit.t[1] - ref[0].fit.t[0]),
                         floor=noise_floor(params, rotor))
    base = fit_candidate(BASELINE, [f.fit for f in ref], params, sigma0, rotor_channel=rotor)
    notes = ([f"only {len(ref)} reference flights: an effect's spread over nominal flights "
              "is poorly known; give 10 or more"] if len(ref) < MIN_REFERENCE else [])
    tuned = base.effects()[0].apply_to_params(params)
    reference_fits, floors = _reference_spread(ref, tuned, effects, progress)
    one_flight = partial(_one_flight, tuned=tuned, effects=effects, window_s=window_s,
                         spread=reference_fits, floors=floors,
                         progress=None if map_fn is not map else progress)
    flights = list(map_fn(one_flight, logs))
    # Bad input: a reference set that disagrees with the model more than the flights tested.
    ratios = [np.median([c["before"] / max(c["floor"], 1e-300) for c in f["channels"].values()])
              for f in flights]
    checks = {"flights_vs_reference_floor": float(np.median(ratios)) if ratios else None,
              **vehicle}
    if ratios and np.median(ratios) < 1 / rule.FLOOR_TOL:
        notes.append(f"the reference flights disagree with the model more than the flights "
                     f"under test (median nominal residual of the tested flights "
                     f"{np.median(ratios):.2f}x the reference floor): check the reference set")
    return {"schema": SCHEMA, "model": params.name, "mode": "per-flight",
            "reference": [f.name for f in ref],
            "reference_refit": base.params(), "reference_refit_ci": base.ci(),
            "reference_refit_identified": dict(zip(base.candidate.parameter_names,
                                                   map(bool, base.identifiable))),
            "flights": flights,
            "reference_floor": {k: max(v) for k, v in floors.items()}, "checks": checks,
            "notes": notes,
            "where": {}, "effects": [],
            "verdict": {"outcome": "effect" if any(f["outcome"] == "effect" for f in flights)
                        else "unexplained", "effect": "see flights",
                        "answer": per_flight_answer(flights), "reduction": None,
                        "confusable_with": []}}


def _one_flight(log, tuned, effects, window_s, spread, floors, progress) -> dict:
    """Judge one flight against the reference spread (module level: sent to workers)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        flight = prepare([log], tuned, window_s=window_s)[0]
        one = _diagnose_split(*_halves(flight), tuned, effects, 1, progress, [])
    judged = judge_flight(one, spread, flight.name, floors, tuned)
    judged["signal_delays_ms"] = flight.delays_ms
    judged["notes"].extend(delay_notes([flight]))
    if judged["outcome"] == "effect":   # one value in every regime, or not named
        _flight_consistency(judged, one, flight, tuned)
    return judged


def _flight_consistency(judged: dict, one: dict, flight: Flight, params) -> None:
    """The parameter-consistency guard (:mod:`.consistency`) on one flight (both halves)."""
    rotor = flight.fit.command is not None
    has_vbat = flight.fit.vbat is not None and bool(np.all(np.isfinite(flight.fit.vbat)))
    entry = next((e for e in one["effects"] if e["name"] == judged["verdict"]), None)
    if entry is None:
        return
    cand = next((c for c in candidates_for(params, rotor, has_vbat)
                 if c.name == judged["verdict"]
                 and c.fixed_values == entry.get("fixed", {})), None)
    if cand is None:
        return
    sigma = np.array([one["where"]["noise_scale"][k] for k in one["where"]["channels"]])
    theta = np.array([entry["params"][k] for k in cand.parameter_names])
    consistency.apply_to_flight(judged, consistency.check(
        cand, theta, consistency.judged_parameters(entry), [flight.fit], params, sigma, rotor))


def _halves(f: Flight):
    half = len(f.states.t) // 2
    out = []
    for sl in (slice(0, half), slice(half, None)):
        idx = np.arange(len(f.states.t))[sl]
        states = f.states.take(idx)
        fit_idx = np.nonzero((f.fit.t >= states.t[0]) & (f.fit.t <= states.t[-1]))[0]
        out.append(Flight(f.name, states, f.fit.take(fit_idx)))
    return [out[0]], [out[1]]


def _reference_spread(ref: list[Flight], params, effect_names, progress) -> tuple[dict, dict]:
    """Per effect, each reference flight's own fit (first half -> second half): held-out
    reduction, parameter values, 95 % half-widths, identified flags; per channel: the
    held-out RMS the nominal model leaves on each reference flight (the largest is the
    per-flight floor, in the channel's unit)."""
    spread: dict[str, list[dict]] = {}
    floors: dict[str, list[float]] = {}
    for f in ref:
        one = _diagnose_split(*_halves(f), params, effect_names, 1, progress, [])
        for e in one["effects"]:
            spread.setdefault(e["name"], []).append(
                {k: e.get(k, {}) for k in ("reduction", "params", "ci", "identifiable",
                                           "fixed")})
        for k, v in one["where"]["heldout_rms_before"].items():
            floors.setdefault(k, []).append(v)
    return spread, floors


def reference_band(key: str, references: list[dict]) -> tuple[float, float] | None:
    """``[min(r_j - c_j), max(r_j + c_j)]`` of parameter ``key`` over the reference fits
    that identified it; None when none did (they say nothing about its value)."""
    rows = [(r["params"][key], r["ci"].get(key, np.inf)) for r in references
            if r.get("identifiable", {}).get(key) and np.isfinite(r["ci"].get(key, np.inf))]
    if not rows:
        return None
    return min(v - c for v, c in rows), max(v + c for v, c in rows)


def differs_from_reference(entry: dict, references: list[dict]) -> bool:
    """True when some parameter of ``entry`` (one flight's fit of an effect) that is
    identified and significant lies outside the references' band
    (:func:`reference_band`) by more than its own 95 % half-width. A parameter no reference
    identified is compared with its "off" value only (its significance). A parameter whose
    value does not carry the effect's size (``battery_sag.full_voltage``: the sag
    (V / V_full)^2 is sized by the logged voltage, the same V_full fits a full and a flat
    battery) is not compared: the reduction excess alone decides. Only reference fits with
    the same fixed values count (a canted rotor's tilt is compared with the references'
    fits of the same rotor)."""
    fixed = entry.get("fixed", {})
    references = [r for r in references if r.get("fixed", {}) == fixed]
    for key, value in entry["params"].items():
        if not (entry["identifiable"].get(key) and entry["significant"].get(key)):
            continue
        if key in NO_OFF_VALUE:     # its size is in the logged signal (vbat), not the value
            return True
        band = reference_band(key, references)
        if band is None:
            return True
        ci = entry["ci"].get(key, np.inf)
        if value - ci > band[1] or value + ci < band[0]:
            return True
    return False


#: units shown scaled in words (SI inside): seconds as ms, kilograms as g, metres as mm.
_SHOWN = {"s": (1e3, "ms"), "kg": (1e3, "g"), "m": (1e3, "mm")}


def _band_text(entry: dict, references: list[dict], params) -> str:
    """The reference fits' band of each parameter of ``entry``, in words with units."""
    parts = []
    for key in entry["params"]:
        band = reference_band(key, references)
        if band is not None:
            unit = collinear.unit_of(key)
            scale, shown = _SHOWN.get(unit, (1.0, unit))
            parts.append(f"{key} {scale * band[0]:.3g} to {scale * band[1]:.3g} "
                         f"{shown}".rstrip())
    return "; ".join(parts) or "not identified on them"


def judge_flight(one: dict, spread: dict, name: str, floors: dict, params, *,
                 min_t: float = MIN_T, min_gain: float = MIN_GAIN, tie: float = TIE,
                 per_flight_tie: float = PER_FLIGHT_TIE) -> dict:
    """A flight's verdict from its own diagnosis ``one`` and the reference fits ``spread``
    (see the module doc for the rule)."""
    scored, shared = _classify(one["effects"], spread, min_t, min_gain)
    effects = [{k: e[k] for k in ("name", "params", "ci", "reduction")} |
               {"reference_max_reduction": max([r["reduction"]
                                                for r in spread.get(e["name"], [])] or [0.0]),
                "reference_band": {k: reference_band(k, spread.get(e["name"], []))
                                   for k in e["params"]}}
               for e in one["effects"]]
    where = one["where"]
    names = list(where["heldout_rms_before"])
    floor = np.array([max(floors.get(k, [0.0])) for k in names])
    before = np.array([where["heldout_rms_before"][k] for k in names])
    notes = []
    best, alts = None, []
    if scored:
        top = max(x for x, _ in scored)
        tied = [(x, e) for x, e in scored if x >= top - tie]
        first = min(tied, key=lambda xe: (len(xe[1]["params"]), -xe[0]))[1]
        others = [e for _, e in scored
                  if e is not first and e["reduction"] >= first["reduction"] - per_flight_tie]
        best, alts = collinear.pick_plausible(first, others, params)
        if best is None:
            notes.append(f"{first['name']} explains the gap only with an implausible magnitude "
                         f"({alts[0]['magnitude']}; {alts[0]['prior']}): flagged, not named")
            alts = []
    if best is not None and len(alts) > 1:
        notes.append(collinear.collinear_note(best["name"], alts))
    after = before if best is None else np.array(
        [best["heldout_rms_after"].get(k, before[n]) for n, k in enumerate(names)])
    channels = rule.channel_table(names, before, after, floor)
    kind = rule.outcome(best is not None, before, floor)
    floor_source = "the reference flights' own held-out residual"
    label = best["name"] if best else kind
    answer = rule.answer(kind, label, best["reduction"] if best else 0.0, alts, channels,
                         floor_source)
    if kind == "unexplained" and shared:
        common = _shared_to_floor(shared, names, floor)
        if common is not None:
            kind = label = "no_significant_gap"
            what = collinear.describe(common["name"], common["params"], common["ci"], params,
                                      common.get("fixed"))
            band = _band_text(common, spread.get(common["name"], []), params)
            answer = (f"No significant gap against the reference flights: what this flight "
                      f"shows beyond their floor is {common['name']} at the magnitude the "
                      f"reference flights share ({what}; references: {band}), a model error "
                      "common to all of them, not a difference of this vehicle.")
            notes.append(f"{common['name']} explains {100 * common['reduction']:.0f} % of this "
                         "flight's held-out gap at the references' own magnitude: shared with "
                         "the nominal flights (the model lacks it), not named")
    confusable = [a["name"] for a in alts if best and a["name"] != best["name"]]
    return {"file": name, "outcome": kind, "verdict": label, "answer": answer,
            "channels": channels, "alternatives": alts,
            "params": best["params"] if best else {}, "ci": best["ci"] if best else {},
            "fixed": best.get("fixed", {}) if best else {},
            "units": {k: collinear.unit_of(k) for k in (best["params"] if best else {})},
            "reduction": best["reduction"] if best else 0.0, "confusable_with": confusable,
            "readings": [a["name"] for a in rule.stated_readings(alts)] if best else [],
            "separate_by": collinear.separation(best["name"], confusable) if best else {},
            "effects": effects, "notes": notes}


def _classify(entries: list[dict], spread: dict, min_t: float, min_gain: float):
    """(scored, shared): the effects that differ from the references, as (excess reduction,
    entry), and those that explain a clear share at the references' own magnitude."""
    scored, shared = [], []
    for e in entries:
        if e["t_statistic"] < min_t or not parts_identified(e) or e["reduction"] < min_gain:
            continue
        refs = spread.get(e["name"], [])
        # the references can raise the bar, never lower it: an effect that makes every
        # nominal flight worse (negative reduction) must still clear MIN_GAIN on its own
        excess = e["reduction"] - max([0.0] + [r["reduction"] for r in refs])
        if excess >= min_gain and differs_from_reference(e, refs):
            scored.append((excess, e))
        else:
            shared.append(e)
    return scored, shared


def _shared_to_floor(shared: list[dict], names: list[str], floor: np.ndarray) -> dict | None:
    """The shared effect (largest reduction first) that leaves every channel at the floor."""
    for e in sorted(shared, key=lambda e: -e["reduction"]):
        after = np.array([e["heldout_rms_after"].get(k, np.inf) for k in names])
        if np.all(after <= rule.FLOOR_TOL * floor):
            return e
    return None


def per_flight_answer(flights: list[dict]) -> str:
    counts: dict[str, int] = {}
    for f in flights:
        counts[f["verdict"]] = counts.get(f["verdict"], 0) + 1
    return f"{len(flights)} flights judged against the reference flights: " + ", ".join(
        f"{n} {k}" for k, n in sorted(counts.items(), key=lambda kv: -kv[1]))
