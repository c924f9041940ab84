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

Rule (per flight in per-flight mode, where :mod:`quadsim.gap.per_flight` adds that a named
effect's magnitude must differ from the reference flights'):

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

__all__ = ["FLOOR_TOL", "MAX_FLOOR", "OUTCOMES", "channel_table", "outcome", "unit_of_channel",
           "answer", "stated_readings"]

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


def _uniform_mismatch(alt: dict) -> bool:
    """A thrust_mismatch whose rotors agree within their 95 % intervals: a uniform change."""
    keys = [k for k in alt.get("params", {}) if k.startswith("thrust_mismatch.rotor_")]
    if not keys:
        return False
    values = np.array([alt["params"][k] for k in keys])
    half = max(abs(alt.get("ci", {}).get(k) or 0.0) for k in keys)
    return bool(np.ptp(values) <= half)


def stated_readings(alts: list[dict]) -> list[dict]:
    """The readings a verdict's answer states: the named explanation (``alts[0]``) and every
    plausible collinear alternative, each once. Not repeated: the b refit
    (``nominal_refit``) and a thrust_mismatch with all rotors alike (within their 95 %
    intervals) when thrust_factor is stated; both say "the same change of thrust per
    Omega^2 on every rotor". Implausible alternatives are listed apart, never a reading."""
    if not alts:
        return []
    names = {a["name"].split("+")[0] for a in alts[1:] if a["plausible"]}
    out = [alts[0]]
    for a in alts[1:]:
        first = a["name"].split("+")[0]
        if not a["plausible"] or a["name"] == alts[0]["name"]:
            continue
        if "thrust_factor" in names and (first == "nominal_refit" or (
                first == "thrust_mismatch" and _uniform_mismatch(a))):
            continue
        out.append(a)
    return out


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
    rest = stated_readings(alts)[1:]
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
