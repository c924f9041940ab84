"""Parameter consistency: a named effect must have *one* value in every regime it was fitted on.

A real effect has one value (a payload weighs the same slow and fast, a weak rotor is weak at
every speed). A library effect standing in for something outside the library needs different
values in different regimes: e.g. a thrust gain that grows with airspeed (translational lift)
is fitted as a linear thrust-curve term, large in fast flight and small near hover. The
guard refits the named candidate (its own parameters, started at the pooled fit) on two
halves of the data and compares:

* ``airspeed``: samples below / above the median in-plane ground speed |v_xy| (m/s) of all
  flights (aerodynamic effects the library lacks grow with it);
* ``rotor_speed``: samples below / above the median mean rotor speed (rad/s) (effects that
  depend on thrust or on Omega in a way the candidate does not).

A parameter is *inconsistent* on a split when the two values differ by more than their
combined 95 % interval, sqrt(ci_a^2 + ci_b^2) (statistically different), **and** by more
than :data:`MATERIAL` times the larger of the two magnitudes (materially different: a real
effect fitted on independent data or with a slightly wrong floor moves by a few %, not by
half its value). Only parameters that the pooled fit identified and found significant are
judged, and only on a half where the refit identifies them too (CI < half the range); a
parameter too weakly excited in one half cannot disagree.

A parameter whose halves differ beyond their combined interval but by less than
:data:`MATERIAL` *shifts* with the regime: the name stands, marked ``tentative`` (field
``verdict.tentative``, a note and a sentence in the answer): it
describes how the vehicle behaved over the flown range, but the value depends on airspeed or
rotor speed, so it may stand in for an effect outside the library (a thrust gain growing with
airspeed reads as a small thrust-curve term over a narrow speed range); flights over a wider
range of speeds tell.

If any judged parameter is inconsistent, the verdict is not a confident name: outcome
``unexplained``, and the candidate is reported as a *partial explanation*
(``verdict.partial``: name, share of the held-out gap it explains, parameters, and the
split values) with the words "explains N % but needs <p> = a in slow flight and b in fast
flight: a stand-in for an effect outside the library". The test uses only the data and
the candidate's own fit; nothing in it names an effect.

Units: parameter values and CIs in the parameter's own unit (``verdict.units``); split
thresholds in m/s (airspeed) and rad/s (rotor speed).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ModelError
from .fitting import Candidate, fit_candidate
from .residual import FlightStates

__all__ = ["MATERIAL", "MIN_SAMPLES", "SPLITS", "check", "inconsistent_note", "partial_text",
           "split_masks", "standing", "tentative_note", "tentative_text"]

#: relative difference (of the larger magnitude) above which two values are materially
#: different. 0.5: the two halves ask for values a factor >= 2 apart.
MATERIAL = 0.5
#: a half with fewer samples (after decimation) is not fitted.
MIN_SAMPLES = 200
SPLITS = ("airspeed", "rotor_speed")
_LABELS = {"airspeed": ("slow flight", "fast flight"),
           "rotor_speed": ("low rotor speed", "high rotor speed")}


def split_masks(flights: list[FlightStates]) -> dict[str, tuple[float, list[np.ndarray]]]:
    """Per split: (threshold, per-flight boolean masks of the *upper* half)."""
    speed = [np.linalg.norm(f.velocity[:, :2], axis=1) for f in flights]
    rotor = [np.mean(f.rotor_speed, axis=1) for f in flights]
    out = {}
    for name, values in zip(SPLITS, (speed, rotor)):
        threshold = float(np.median(np.concatenate(values)))
        out[name] = (threshold, [v > threshold for v in values])
    return out


def _fit_half(candidate, parts: list, *, params, sigma, rotor, start):
    """``candidate`` refitted on ``parts`` (the half's samples of each flight) from
    ``start``; None when the half is too small or the fit fails."""
    parts = [p for p in parts if len(p.t) > 10]
    if sum(len(p.t) for p in parts) < MIN_SAMPLES:
        return None
    try:
        return fit_candidate(candidate, parts, params, sigma, rotor_channel=rotor, start=start)
    except (ModelError, ValueError, np.linalg.LinAlgError):
        return None


def check(candidate: Candidate, theta: np.ndarray, judged: list[str],
          flights: list[FlightStates], *, params, sigma: np.ndarray, rotor: bool) -> dict:
    """Refit ``candidate`` (pooled values ``theta``) on each split's halves of ``flights``
    under ``params`` with noise scale ``sigma`` (rotor channels when ``rotor``); judge the
    parameters named in ``judged``.

    Returns ``{"consistent": bool, "splits": {split: {"threshold", "unit", "params": {p:
    {"low", "high", "ci_low", "ci_high", "consistent"}}}}, "inconsistent": [text, ...]}``."""
    names = candidate.parameter_names
    out: dict = {"consistent": True, "splits": {}, "inconsistent": [], "shifted": []}
    for split, (threshold, masks) in split_masks(flights).items():
        low, high = (_fit_half(candidate, [f.take(np.nonzero(m if upper else ~m)[0])
                                           for f, m in zip(flights, masks)],
                               params=params, sigma=sigma, rotor=rotor, start=theta)
                     for upper in (False, True))
        if low is None or high is None:
            continue
        entry = {"threshold": threshold, "unit": "m/s" if split == "airspeed" else "rad/s",
                 "params": {}}
        for k, p in enumerate(names):
            if p not in judged:
                continue
            a, b = float(low.theta[k]), float(high.theta[k])
            ca, cb = 1.96 * float(low.stderr[k]), 1.96 * float(high.stderr[k])
            both = bool(low.identifiable[k] and high.identifiable[k])
            diff = abs(a - b)
            differs = both and diff > np.hypot(ca, cb)
            ok = not (differs and diff > MATERIAL * max(abs(a), abs(b)))
            entry["params"][p] = {"low": a, "high": b, "ci_low": ca, "ci_high": cb,
                                  "consistent": ok}
            lo_label, hi_label = _LABELS[split]
            text = (f"{p} = {a:.3g} ± {ca:.2g} in {lo_label} and {b:.3g} ± {cb:.2g} in "
                    f"{hi_label} (split at {threshold:.3g} {entry['unit']})")
            if not ok:
                out["consistent"] = False
                out["inconsistent"].append(text)
            elif differs:
                out["shifted"].append(text)
        out["splits"][split] = entry
    return out


def standing(result: dict) -> str:
    """What ``result`` (:func:`check`) does to a name: ``"stands"`` (one value in every
    regime), ``"shifted"`` (a value moves beyond its interval by less than
    :data:`MATERIAL`: the name stands, tentative) or ``"inconsistent"`` (beyond
    :data:`MATERIAL`: ``unexplained``, a partial explanation)."""
    if not result["consistent"]:
        return "inconsistent"
    return "shifted" if result["shifted"] else "stands"


def partial_text(name: str, reduction: float, result: dict) -> str:
    """The answer for an inconsistent name: a partial explanation."""
    return (f"Unexplained: {name} explains {100 * reduction:.0f} % of the held-out gap but "
            f"needs different values in different regimes ({'; '.join(result['inconsistent'])})"
            f": a stand-in for an effect outside the library (or several effects), not a "
            f"cause. It is given as a partial explanation only.")


def inconsistent_note(name: str, result: dict) -> str:
    """The result's note for an inconsistent name."""
    return (f"{name} not named: its parameters are inconsistent between regimes ("
            + "; ".join(result["inconsistent"]) + ")")


def tentative_text(result: dict) -> str:
    """The sentence appended to the answer of a shifted name."""
    return (" Tentative: its value shifts with the regime (" + "; ".join(result["shifted"])
            + "), so it may stand in for an airspeed- or speed-dependent effect outside the "
            "library; flights over a wider range of speeds would tell.")


def tentative_note(result: dict) -> str:
    """The result's note for a shifted name."""
    return ("tentative name: the fitted value shifts with the regime ("
            + "; ".join(result["shifted"]) + ")")
