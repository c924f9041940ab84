"""What a combination of effects claims.

A combination (a pair weighed by evidence in :mod:`quadsim.gap.heldout_verdict`) stands only
when *every part stands*: each effect of the combination has a parameter identified and significant, and the
combined magnitudes are plausible (:mod:`quadsim.gap.priors`). Two effects cancelling each
other at their bounds (every rotor -50 % thrust and the vehicle 50 % lighter) explain
nothing about the vehicle. A combination's readings are its own description first, then
each collinear reading of its first effect with the rest of the combination.
"""

from __future__ import annotations

from . import collinear

__all__ = ["parts_identified"]


def parts_identified(entry: dict) -> bool:
    """Every effect of a fitted candidate has a parameter identified and significant (the
    ``wind`` candidate fits wind with rotor drag: a wind of 0.002 +- 0.1 m/s is rotor drag
    alone, not a second reading of the data)."""
    parts = {k.split(".")[0] for k in entry["params"]}
    return all(any(entry["identifiable"][k] and entry["significant"][k]
                   for k in entry["params"] if k.split(".")[0] == part) for part in parts)


def _every_part_stands(entry: dict, params) -> bool:
    """A combination claims that each of its effects is there: every part needs a parameter
    identified and significant, and the combined fit must be physically plausible (priors).
    Two effects that cancel each other at their bounds (every rotor -50 % thrust and the
    vehicle 50 % lighter) explain nothing about the vehicle."""
    from .priors import candidate_plausibility

    return parts_identified(entry) and bool(candidate_plausibility(entry["params"], params)[1])


def _combination_alternatives(combined: dict, best: dict, alts: list[dict], params) -> list:
    """The readings of a combination: the combined fit described first, then each collinear
    reading of its first effect (``alts`` of ``best``) with the rest of the combination."""
    rest = combined["name"][len(best["name"]) + 1:]
    keys = [k for k in combined["params"] if k.split(".")[0] in rest.split("+")]
    rest_text = collinear.describe(rest, {k: combined["params"][k] for k in keys},
                                   {k: combined["ci"].get(k) for k in keys}, params,
                                   combined.get("fixed"))
    out = collinear.alternatives(combined, [], params)
    for a in alts:
        if a["name"] != best["name"]:
            out.append({**a, "name": f"{a['name']}+{rest}",
                        "magnitude": f"{a['magnitude']}, with {rest_text}"})
    return out
