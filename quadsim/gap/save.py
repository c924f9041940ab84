"""Store a diagnosed model: the effects a diagnosis fitted, as an effect file.

``python -m quadsim.gap ... --write-effects OUT.toml [--add NAME]`` writes the effects the
model started from (``--effects-file``, their sources kept) followed by one fitted candidate
of this diagnosis -- the named effect (the verdict's effect or combination) by default, or
the ranked candidate ``NAME`` -- every parameter with its unit and a source that says which
logs it was fitted on, its 95 % interval and how much of the held-out gap it explains. The
next round of the diagnosis then starts from that file (``--effects-file OUT.toml``): the
user's loop "diagnose, add what is named, diagnose again" (docs/gap.md).

Only library parameters are stored: a candidate fitted in another parametrisation (the
canted rotor's ``tilt_x``, ``tilt_y``) or an effect already in the starting model is refused
in one line (an effect file holds each effect once).

Example::

    >>> entries = added_effects(result, "rotor_drag", logs="9 training logs")
    >>> entries[0][0], sorted(entries[0][1])
    ('rotor_drag', ['axial_coefficient', 'coefficient'])
"""

from __future__ import annotations

from ..core.errors import InputError
from ..effects import EFFECTS

__all__ = ["added_effects", "named_candidate"]


def named_candidate(result: dict) -> str | None:
    """The candidate the verdict named (a combination's name when one was kept), or None."""
    verdict = result.get("verdict", {})
    if verdict.get("outcome") != "effect":
        return None
    combined = result.get("combination")
    return combined["name"] if combined else verdict.get("effect")


def added_effects(result: dict, name: str | None, *, logs: str,
                  base: tuple[str, ...] = ()) -> list[tuple[str, dict]]:
    """[(effect, {parameter: (value, source)})] of the candidate ``name`` (default: the named
    one) of a ``quadsim.gap/3`` result; ``logs`` words the fitting data for the sources;
    ``base``: effect names already in the model (refused again)."""
    name = name or named_candidate(result)
    if name is None:
        raise InputError("--write-effects: the diagnosis named no effect; choose a ranked "
                         "candidate with --add NAME")
    entries = list(result.get("effects", []))
    if result.get("combination"):
        entries.append(result["combination"])
    entry = next((e for e in entries if e["name"] == name), None)
    if entry is None:
        raise InputError(f"--add: {name!r} is not a fitted candidate of this diagnosis; "
                         f"fitted: {', '.join(e['name'] for e in entries)}")
    share = 100.0 * float(entry["reduction"])
    out: dict[str, dict] = {}
    for key, value in entry["params"].items():
        effect, _, parameter = key.partition(".")
        if effect in base:
            raise InputError(f"--add: {effect} is already in --effects-file (an effect file "
                             "holds each effect once)")
        declared = {p.name for p in EFFECTS[effect].parameters} if effect in EFFECTS else set()
        if parameter not in declared:
            raise InputError(f"--add: {name}: {key} is fitted in the diagnosis' own "
                             "parametrisation, not a library parameter; write it by hand")
        ci = entry["ci"].get(key)
        flag = "" if entry.get("identifiable", {}).get(key, True) else \
            "; not identified (at a bound or CI wider than half the plausible range)"
        out.setdefault(effect, {})[parameter] = (float(value), (
            f"python -m quadsim.gap on {logs}: {name} candidate, {value:.4g} +- {ci:.2g} "
            f"(95 % CI){flag}; {share:.1f} % of the held-out gap"))
    return list(out.items())
