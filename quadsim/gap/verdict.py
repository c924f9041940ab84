"""The verdict rule: ``no_significant_gap``, a named effect (or combination), or ``unexplained``.

The *floor* is what a model that is right leaves of the gap on data it did not see. It comes
from data, never from the sensor-noise estimate alone (a log from another simulator or a real
vehicle leaves integration, timing and filtering differences of a few times the noise):

* per-flight mode: the reference (nominal) flights' own held-out residual, per channel: the
  largest RMS that the nominal model leaves on the second half of any reference flight;
* pooled mode: the in-sample (training) residual of the model being judged, per channel
  (for the nominal model: b and d refitted, ``nominal_refit``); a held-out residual at that
  level means the model generalises and nothing more is to be learned from these flights.
  A floor above :data:`MAX_FLOOR` times the noise on some channel is itself a gap that no
  refit removes: then "no significant gap" is not claimed.

Rule (per flight in per-flight mode):

1. A candidate *explains a clear share* when the diagnosis' test passes (held-out reduction
   >= MIN_GAIN, block t >= MIN_T, a parameter identified and significant; per-flight: the
   reduction beats every reference flight's by MIN_GAIN) and its magnitude is physically
   plausible (:mod:`quadsim.gap.priors`). Then the verdict names it (the most plausible of
   its collinear alternatives), with the share and, per channel, the RMS before/after in
   units and whether what remains is at the floor (after <= FLOOR_TOL x floor).
2. Otherwise, if the nominal held-out RMS is at the floor on every channel (<= FLOOR_TOL x
   floor): ``no_significant_gap``.
3. Otherwise ``unexplained``.

FLOOR_TOL = 1.25 on RMS (1.56 on mean squares): a held-out half of one flight differs from
another flight's by the flight's own variation; 25 % in RMS is about the spread of the
nominal held-out RMS between reference flights on the Crazyflie data (measured, docs/gap.md).
"""

from __future__ import annotations

import numpy as np

from . import collinear

__all__ = ["FLOOR_TOL", "MAX_FLOOR", "OUTCOMES", "channel_table", "outcome", "unit_of_channel",
           "answer", "judge_flight", "per_flight_answer"]

FLOOR_TOL = 1.25
#: pooled mode: a training floor above this many times the noise RMS is a gap in itself.
MAX_FLOOR = 5.0
OUTCOMES = ("no_significant_gap", "effect", "unexplained")


def unit_of_channel(name: str) -> str:
    return {"F": "N", "M": "N m"}.get(name[0], "rad/s")


def channel_table(names, before, after, floor) -> dict:
    """Per channel: RMS before/after/floor (in the channel's unit) and ``at_floor``."""
    out = {}
    for k, name in enumerate(names):
        b, a, f = float(before[k]), float(after[k]), float(floor[k])
        out[name] = {"before": b, "after": a, "floor": f, "unit": unit_of_channel(name),
                     "at_floor": bool(a <= FLOOR_TOL * f)}
    return out


def outcome(clear: bool, before: np.ndarray, floor: np.ndarray) -> str:
    if clear:
        return "effect"
    return "no_significant_gap" if bool(np.all(before <= FLOOR_TOL * floor)) else "unexplained"


def answer(kind: str, name: str | None, reduction: float, alts: list[dict], channels: dict,
           floor_source: str) -> str:
    """The verdict in words a quadrotor engineer acts on."""
    if kind == "no_significant_gap":
        return (f"No significant gap: on every channel the held-out residual is within "
                f"{FLOOR_TOL:g}x the floor set by {floor_source}.")
    worst = max(channels.items(), key=lambda kv: kv[1]["after"] / max(kv[1]["floor"], 1e-300))
    worst_text = (f"{worst[0]} {worst[1]['after']:.2g} {worst[1]['unit']} RMS, "
                  f"{worst[1]['after'] / max(worst[1]['floor'], 1e-300):.1f}x the floor")
    if kind == "unexplained":
        return ("Unexplained: no library effect explains a clear, physically plausible share "
                f"of the gap; largest residual {worst_text}. The cause is outside the library, "
                "several effects at once, or the data cannot tell.")
    lead = alts[0] if alts else None
    text = f"Behaves as if {lead['magnitude']}" if lead else f"{name}"
    names = {a["name"] for a in alts}
    # the b refit repeats thrust_factor's statement (plus d): say it once
    rest = [a for a in alts[1:] if a["plausible"]
            and not (a["name"] == "nominal_refit" and "thrust_factor" in names)]
    if rest:
        text += "; or as if " + "; or as if ".join(a["magnitude"] for a in rest)
        text += f" (collinear: {rest[0].get('separate_by', 'more varied flights')})"
    flagged = [a for a in alts[1:] if not a["plausible"]]
    if flagged:
        text += ". Not named (implausible magnitude): " + "; ".join(
            f"{a['name']} ({a['magnitude']})" for a in flagged)
    text += f". Explains {100 * reduction:.0f} % of the held-out gap"
    off = [k for k, c in channels.items() if not c["at_floor"]]
    text += (", every channel at the floor." if not off else
             f"; above the floor after it: {', '.join(off)} (largest {worst_text}).")
    return text


def judge_flight(one: dict, spread: dict, name: str, floors: dict, params, *, min_t: float,
                 min_gain: float, tie: float, per_flight_tie: float) -> dict:
    """A flight's verdict. An effect *explains a clear share* when its held-out reduction
    exceeds the largest reduction the same effect achieves on any reference (nominal) flight
    by at least min_gain (effects that help every nominal flight alike, real drag or an
    imperfect motor map, are not named) and its magnitude is plausible; among those within
    tie of the largest excess, the most plausible (then fewest parameters) is named, the
    others within per_flight_tie of its reduction are listed as collinear alternatives.
    Otherwise the flight is ``no_significant_gap`` when its nominal held-out RMS is at the
    reference floor on every channel, else ``unexplained``."""
    scored = []
    for e in one["effects"]:
        ok = e["t_statistic"] >= min_t and any(
            e["identifiable"][k] and e["significant"][k] for k in e["params"])
        # the references can raise the bar, never lower it: an effect that makes every
        # nominal flight worse (negative reduction) must still clear MIN_GAIN on its own
        excess = e["reduction"] - max(0.0, *spread.get(e["name"], [0.0]))
        if ok and excess >= min_gain:
            scored.append((excess, e))
    effects = [{k: e[k] for k in ("name", "params", "ci", "reduction")} |
               {"reference_max_reduction": max(spread.get(e["name"], [0.0]))}
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
    channels = channel_table(names, before, after, floor)
    kind = outcome(best is not None, before, floor)
    floor_source = "the reference flights' own held-out residual"
    label = best["name"] if best else kind
    confusable = [a["name"] for a in alts if best and a["name"] != best["name"]]
    return {"file": name, "outcome": kind, "verdict": label,
            "answer": answer(kind, label, best["reduction"] if best else 0.0, alts,
                                  channels, floor_source),
            "channels": channels, "alternatives": alts,
            "params": best["params"] if best else {}, "ci": best["ci"] if best else {},
            "units": {k: collinear.unit_of(k) for k in (best["params"] if best else {})},
            "reduction": best["reduction"] if best else 0.0, "confusable_with": confusable,
            "separate_by": collinear.separation(best["name"], confusable) if best else {},
            "effects": effects, "notes": notes}


def per_flight_answer(flights: list[dict]) -> str:
    counts: dict[str, int] = {}
    for f in flights:
        counts[f["verdict"]] = counts.get(f["verdict"], 0) + 1
    return f"{len(flights)} flights judged against the reference flights: " + ", ".join(
        f"{n} {k}" for k, n in sorted(counts.items(), key=lambda kv: -kv[1]))
