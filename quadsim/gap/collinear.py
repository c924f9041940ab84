"""Collinear explanations in words: each candidate's physical magnitude (:func:`describe`),
what the torque and yaw channels say, and what separates them (:func:`separation`).

Readings the data cannot choose between are all listed in ``verdict.alternatives``
(:mod:`quadsim.gap.diagnose`, from the held-out posterior of
:mod:`quadsim.gap.heldout_verdict`), each with

* ``magnitude``: the fitted parameters as a physical statement with units ("+4.0 ± 0.2 g
  (+10.8 % of the vehicle mass)", "-9.7 ± 0.5 % thrust per Omega^2 on all 4 rotors");
* ``torque_yaw``: the held-out RMS of Mx, My, Mz (N m) that the candidate leaves, so a
  reader sees whether the torque channels prefer one (a thrust-per-Omega^2 change from the
  air also scales the yaw drag torque; an added mass at the CoM leaves torques alone);
* ``separate_by``: the measurement or manoeuvre that would tell them apart;
* ``plausible`` / ``plausibility``: the prior check of :mod:`quadsim.gap.priors` (score
  <= 1 plausible). An implausible candidate is flagged and never named.
"""

from __future__ import annotations

from types import MappingProxyType

from ..effects.facts import number, plus_minus
from ..vehicle.params import VehicleParams
from .fitmodels import FIT_EFFECTS, effect_class

__all__ = ["SEPARATE", "describe", "separation", "torque_text", "unit_of"]


def _separate() -> dict:
    out: dict = {}
    for name, cls in FIT_EFFECTS.items():
        for other, text in cls.facts.separate_from.items():
            pair = frozenset({name, other})
            if out.get(pair, text) != text:
                raise ValueError(f"{name} and {other}: two texts on what separates them")
            out[pair] = text
    return out


#: known collinear pairs and what data would separate them: a read-only view of the effects'
#: declared ``facts.separate_from`` (each pair declared by one of the two)
SEPARATE = MappingProxyType(_separate())


def separation(best: str, others: list[str]) -> dict:
    """What tells reading ``best`` from each of ``others`` (:data:`SEPARATE`; a generic
    advice for a pair without one)."""
    return {other: SEPARATE.get(frozenset({best.split("+")[0], other.split("+")[0]}),
                                "more varied flights (speeds, heights, attitudes)")
            for other in others}


def unit_of(parameter: str) -> str:
    """Unit of ``effect.parameter`` (from the effect's declaration)."""
    name, _, p = parameter.partition(".")
    try:
        specs = {s.name: s for s in effect_class(name).parameters}
    except KeyError:
        return ""
    if p in specs:
        return specs[p].unit
    return "1" if p.startswith("rotor_") else ""


def describe(name: str, values: dict, ci: dict, params: VehicleParams,
             fixed: dict | None = None) -> str:
    """Physical statement (with units) of a fitted candidate (``values``, ``ci``: the fitted
    ``effect.parameter`` values and 95 % half-widths; ``fixed``: the values held fixed in
    the fit, e.g. ``canted_rotor.rotor``): each effect's declared wording
    (:class:`quadsim.effects.facts.Words`, ``phrase``; parameters worded together first,
    ``facts.together``), its nuisance parameters left out, a parameter without a phrase
    stated with its declared meaning and unit (:func:`_worded`); ``name`` where nothing is
    left."""
    fixed = fixed or {}
    parts, together = [], set()
    for effect in dict.fromkeys(key.partition(".")[0] for key in values):
        facts = _facts(effect)
        if facts is None or facts.together is None:
            continue
        keys = [f"{effect}.{p}" for p in facts.together.parameters]
        together |= set(keys)
        if all(k in values for k in keys):
            own = _own(effect, values)
            parts.append(facts.together.phrase(own, _own(effect, ci), params,
                                               _own(effect, fixed)))
    for key, value in values.items():
        effect, _, p = key.partition(".")
        facts = _facts(effect)
        if key in together or (facts is not None and p in facts.nuisance):
            continue
        words = facts.words_of(p) if facts is not None else None
        c = ci.get(key)
        if words is not None and words.phrase is not None:
            parts.append(words.phrase(p, value, c, params))
        else:
            parts.append(_worded(key, value, c, params))
    return ", ".join(parts) if parts else name


def _facts(effect: str):
    cls = FIT_EFFECTS.get(effect)
    return None if cls is None else cls.facts


def _own(effect: str, table: dict) -> dict:
    """``table``'s entries of ``effect``, keyed by its parameter names."""
    prefix = effect + "."
    return {k[len(prefix):]: v for k, v in table.items() if k.startswith(prefix)}


def _worded(key: str, value: float, c: float | None, params: VehicleParams) -> str:
    """A parameter without a declared phrase, stated with its declared meaning and unit
    (never as a bare ``effect.parameter = value``)."""
    name, _, p = key.partition(".")
    try:
        spec = {s.name: s for s in effect_class(name).parameters}[p]
        text, unit = spec.doc, spec.unit
    except KeyError:
        text, unit = p.replace("_", " "), unit_of(key)
    return f"{name.replace('_', ' ')}: {text} {_pm(value, c, 1.0, '.4g')} {unit}".rstrip()


def torque_text(entry: dict) -> str:
    rms = entry.get("heldout_rms_after") or {}
    have = [(k, rms[k]) for k in ("Mx", "My", "Mz") if k in rms]
    return ", ".join(f"{k} {v:.2g} N m" for k, v in have)


_torque_text = torque_text  # alias for other modules until integration
_pm = plus_minus  # alias for other modules until integration
_num = number  # alias for other modules until integration
