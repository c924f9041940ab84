"""Reading a diagnosis verdict, and scoring benchmark cases against the hidden truth.

:func:`read_verdict` is the one place that knows the shape of a verdict in the result of
:func:`quadsim.gap.diagnose` (``result["verdict"]``) or of one flight of
:func:`quadsim.gap.diagnose_per_flight` (``result["flights"][i]``). It returns::

    {"outcome": "no_significant_gap" | "named" | "unexplained" | "refused",
     "lead": [effects of the verdict's first reading],
     "named": [effects of every reading the verdict's answer states],
     "readings": int,         # how many readings the answer states
     "alternatives": [names listed as confusable / collinear, not stated as a reading],
     "probability": float | None,   # of the verdict's reading (evidence verdicts)
     "confident": bool}      # a name given without a flag that it is tentative (evidence
                             # verdicts: probability >= quadsim.gap.judge.CONFIDENT)

A *reading* is one explanation the answer states: the named effect ("behaves as if +58 g
heavier") and every collinear alternative that ties with it on held-out data and is
physically plausible ("; or as if -6.5 % thrust per Omega^2 on all 4 rotors"). Data that
cannot separate two causes get a verdict that names both with their magnitudes (the issue's
"+90 g, or -10 % thrust per Omega^2; weigh it to tell"); an implausible alternative is
listed ("not named") but is not a reading.

Scores (:func:`score_case`, per case): ``named`` -- a reading of the verdict names the hidden
effect; ``lead`` -- the first reading does (the priors' pick among collinear readings);
``named_or_alternative`` -- named or listed at all; ``no_gap`` -- a no-effect case got
``no_significant_gap``; ``confident_wrong`` -- a confident name that is not the hidden effect
(for out-of-library cases every name is wrong).
"""

from __future__ import annotations

import numpy as np

__all__ = ["joined_kind", "names_truth", "read_verdict", "score_case", "summary_rows"]

_NO_GAP = ("no_significant_gap", "no_gap", "none")


def _names(items) -> list[str]:
    out = []
    for item in items or []:
        if isinstance(item, str):
            out.append(item)
        elif isinstance(item, dict):
            name = item.get("name") or item.get("effect")
            if name:
                out.append(str(name))
    return [n for part in out for n in part.split("+")]


def read_verdict(entry: dict) -> dict:
    """Normalise a held-out ``verdict`` dict or a per-flight flight dict (see module doc)."""
    effect = entry.get("effect", entry.get("verdict"))
    if isinstance(effect, dict):
        effect = effect.get("name") or effect.get("effect")
    effect = str(effect or "unexplained")
    label = str(entry.get("outcome") or effect)
    if label == "refused" or effect == "refused":
        outcome, named = "refused", []
    elif label in _NO_GAP or effect in _NO_GAP:
        outcome, named = "no_significant_gap", []
    elif label in ("unexplained", "see flights") or effect in ("unexplained", "see flights"):
        outcome, named = "unexplained", []
    else:
        outcome, named = "named", [n for n in effect.split("+") if n]
    lead, readings = list(named), 1 if named else 0
    if outcome == "named":
        stated = entry.get("readings")
        if stated is None:      # results without the field: the plausible alternatives
            stated = [effect] + [a["name"] for a in entry.get("alternatives") or []
                                 if isinstance(a, dict) and a.get("plausible")
                                 and a.get("name") != effect]
        readings = max(1, len(stated))
        named += [n for n in _names(stated) if n not in named]
    alternatives = _names(entry.get("confusable_with")) + _names(entry.get("alternatives")) \
        + _names(entry.get("collinear"))
    tentative = bool(entry.get("tentative") or entry.get("flagged") or entry.get("implausible"))
    probability = entry.get("probability")
    return {"outcome": outcome, "lead": lead, "named": named, "readings": readings,
            "alternatives": sorted(set(alternatives) - set(named)),
            "probability": None if probability is None else float(probability),
            "confident": outcome == "named" and not tentative}


def joined_kind(name: str, kind: str, joined) -> str:
    """The kind a case is scored as today: ``library`` when its effect ``name`` is among
    ``joined`` -- effects the library gained after the case was flown as outside it (each
    source's ``JOINED_LIBRARY``; the flights, case list and cache keys stay) -- else the
    ``kind`` it was flown as."""
    return "library" if name in joined else kind


#: a case's truth under a source's own name -> the library effect that names it (RotorPy's
#: ``flapping`` moment is the library's ``blade_flapping``, benchmarks.draws.library_equivalent)
LIBRARY_NAME = {"flapping": "blade_flapping"}


def names_truth(truth: str, names) -> bool:
    """Whether ``names`` (effect names of a verdict) name ``truth`` (or its
    :data:`LIBRARY_NAME`); a logged signal's delay (truth ``rotor_delay``) is named by any
    name that contains ``delay``."""
    if truth == "rotor_delay":
        return any("delay" in str(n) for n in names)
    return LIBRARY_NAME.get(truth, truth) in names


def score_case(truth: str, kind: str, verdict: dict) -> dict:
    """Per-case scores for hidden effect ``truth`` of ``kind`` library / none / outside."""
    named = names_truth(truth, verdict["named"])
    return {"named": named, "lead": names_truth(truth, verdict.get("lead", verdict["named"])),
            "readings": verdict.get("readings", 1 if verdict["named"] else 0),
            "named_or_alternative": named or names_truth(truth, verdict["alternatives"]),
            "no_gap": verdict["outcome"] == "no_significant_gap",
            "confident_wrong": verdict["confident"] and (kind != "library" or not named)}


def _rate(values) -> str:
    values = list(values)
    return f"{np.mean(values):.0%} ({sum(values)}/{len(values)})" if values else "-"


def summary_rows(rows: list[dict], min_gain: float) -> list[tuple[str, ...]]:
    """Per (label, group of rows), over the observable in-library cases: a reading names it,
    the lead reading names it, named or listed, mean readings per named verdict; then
    no-effect -> no_significant_gap and out-of-library confident wrong names."""
    out = []
    for label, group in rows:
        lib = [r for r in group if r["kind"] == "library" and r["oracle_reduction"] >= min_gain]
        none = [r for r in group if r["kind"] == "none"]
        outside = [r for r in group if r["kind"] == "outside"]
        counts = [r["score"].get("readings", 1) for r in lib if r["score"].get("readings", 1)]
        out.append((label, _rate(r["score"]["named"] for r in lib),
                    _rate(r["score"].get("lead", r["score"]["named"]) for r in lib),
                    _rate(r["score"]["named_or_alternative"] for r in lib),
                    f"{np.mean(counts):.1f}" if counts else "-",
                    _rate(r["score"]["no_gap"] for r in none),
                    f"{sum(r['score']['confident_wrong'] for r in outside)}/{len(outside)}"))
    return out
