"""Reading a diagnosis verdict, and scoring benchmark cases against the hidden truth.

:func:`read_verdict` is the one place that knows the shape of a verdict in the result of
:func:`quadsim.gap.diagnose` (``result["verdict"]``) or of one flight of
:func:`quadsim.gap.diagnose_per_flight` (``result["flights"][i]``). It returns::

    {"outcome": "no_significant_gap" | "named" | "unexplained",
     "named": [library effect names in the verdict],
     "alternatives": [names listed as confusable / collinear with it],
     "confident": bool}      # a name given without a flag that it is tentative

Scores (:func:`score_case`, per case): ``named`` -- the verdict itself names the hidden
effect; ``named_or_alternative`` -- it is named or listed as a collinear alternative;
``no_gap`` -- a no-effect case got ``no_significant_gap``; ``confident_wrong`` -- a
confident name that is not the hidden effect (for out-of-library cases every name is wrong).
"""

from __future__ import annotations

import numpy as np

__all__ = ["read_verdict", "score_case", "summary_rows"]

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
    if label in _NO_GAP or effect in _NO_GAP:
        outcome, named = "no_significant_gap", []
    elif label in ("unexplained", "see flights") or effect in ("unexplained", "see flights"):
        outcome, named = "unexplained", []
    else:
        outcome, named = "named", [n for n in effect.split("+") if n]
    alternatives = _names(entry.get("confusable_with")) + _names(entry.get("alternatives")) \
        + _names(entry.get("collinear"))
    tentative = bool(entry.get("tentative") or entry.get("flagged") or entry.get("implausible"))
    return {"outcome": outcome, "named": named,
            "alternatives": sorted(set(alternatives) - set(named)),
            "confident": outcome == "named" and not tentative}


def score_case(truth: str, kind: str, verdict: dict) -> dict:
    """Per-case scores for hidden effect ``truth`` of ``kind`` library / none / outside."""
    named = truth in verdict["named"]
    return {"named": named,
            "named_or_alternative": named or truth in verdict["alternatives"],
            "no_gap": verdict["outcome"] == "no_significant_gap",
            "confident_wrong": verdict["confident"] and (kind != "library" or not named)}


def _rate(values) -> str:
    values = list(values)
    return f"{np.mean(values):.0%} ({sum(values)}/{len(values)})" if values else "-"


def summary_rows(rows: list[dict], min_gain: float) -> list[tuple[str, str, str, str, str]]:
    """Per (label, group of rows): named, named-or-alternative (observable in-library),
    no-effect -> no_significant_gap, out-of-library confident wrong names."""
    out = []
    for label, group in rows:
        lib = [r for r in group if r["kind"] == "library" and r["oracle_reduction"] >= min_gain]
        none = [r for r in group if r["kind"] == "none"]
        outside = [r for r in group if r["kind"] == "outside"]
        out.append((label, _rate(r["score"]["named"] for r in lib),
                    _rate(r["score"]["named_or_alternative"] for r in lib),
                    _rate(r["score"]["no_gap"] for r in none),
                    f"{sum(r['score']['confident_wrong'] for r in outside)}/{len(outside)}"))
    return out
