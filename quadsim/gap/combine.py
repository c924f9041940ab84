"""Greedy combinations of effects, and what a combination claims.

After the named effect, every other candidate is tried together with it (fitted jointly,
starting from both single fits); the best pair is kept when it explains a further clear
share (:func:`quadsim.gap.scoring._clear` against the single effect's gap) and *every part
stands*: each effect of the combination has a parameter identified and significant, and the
combined magnitudes are plausible (:mod:`quadsim.gap.priors`). Two effects cancelling each
other at their bounds (every rotor -50 % thrust and the vehicle 50 % lighter) explain
nothing about the vehicle. A combination's readings are its own description first, then
each collinear reading of its first effect with the rest of the combination.
"""

from __future__ import annotations

import numpy as np

from . import collinear
from .fitting import fit_candidate
from .scoring import _clear, _score

__all__ = ["parts_identified"]


def _greedy(best, ranked, train, held, params, sigma, rotor, before, dt, max_combination,
            nominal_gap, tick):
    current = best
    used = {best["name"]}
    fit_on = [f.fit for f in train]
    while len(used) < max_combination:
        trial = None
        # Every other candidate is tried, not only those that helped alone: some effects act
        # only together (the CoM height matters only through rotor-plane drag).
        for entry in ranked:
            if entry["name"] in used or set(entry["name"].split("+")) & used:
                continue
            cand = current["_fit"].candidate.combine(entry["_fit"].candidate)
            start = np.concatenate([current["_fit"].theta, entry["_fit"].theta])
            fit = fit_candidate(cand, fit_on, params, sigma, rotor_channel=rotor, start=start)
            scored = _score(fit, train, held, params, sigma, rotor, before, dt)
            tick(cand.name)
            if trial is None or scored["heldout_gap_after"] < trial["heldout_gap_after"]:
                trial = scored
        if trial is None or not _clear(trial, current["heldout_gap_after"], nominal_gap) \
                or not _every_part_stands(trial, params):
            break
        current, used = trial, used | set(trial["name"].split("+"))
    return current


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
