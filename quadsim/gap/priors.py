"""What the effects' declared facts imply for a reading: plausible magnitudes of fitted
effects, with sources (what ranks collinear explanations), and each reading in words.

When two candidates explain the same forces (an added mass and a uniform loss of thrust per
Omega^2 are the same in the force balance up to drag), the data cannot choose; physics can
say which magnitude is believable. Each prior is a range of the *relative* or absolute size
that real vehicles show; a fit outside it is flagged ``implausible`` and never named.

Each range is declared by its effect beside its parameters, with its source
(``facts.ranges``, :class:`quadsim.effects.facts.PlausibleRange`); :data:`PRIORS` is a
read-only view of them, and ``docs/effects.md`` ("Diagnosis facts") tabulates them with their
reasoning.

:func:`plausibility` returns (score, plausible, text): score = |value| / bound on its side
(<= 1 plausible; the smaller, the more plausible).

Collinear explanations in words
-------------------------------
Each candidate's physical magnitude (:func:`describe`), what the torque and yaw channels
say, and what separates them (:func:`separation`).

Readings the data cannot choose between are all listed in ``verdict.alternatives``
(:mod:`quadsim.gap.diagnose`, from the held-out posterior of :mod:`quadsim.gap.diagnose`),
each with

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

from ..effects.facts import ALL, arm_length, plus_minus
from ..effects.rate_damping import momentum_rate_damping
from ..effects.thrust_curve import (  # re-exported
    CURVE_QUADRATIC_SD,
    ThrustCurve,
    curve_quadratic_bounds,
    curve_quadratic_sd,
    hover_thrust_per_speed,
)
from ..effects.translational_lift import momentum_translational_lift
from ..effects.wind import WIND_SD_MS  # re-exported: the prior spread of a steady wind (m/s)
from ..vehicle.params import VehicleParams
from .fitmodels import FIT_EFFECTS, effect_class

__all__ = [
    "CURVE_QUADRATIC_SD",
    "DETERMINED",
    "PRIORS",
    "SEPARATE",
    "WIND_SD_MS",
    "candidate_plausibility",
    "curve_quadratic_bounds",
    "curve_quadratic_sd",
    "curve_slope_sd",
    "describe",
    "hover_thrust_per_speed",
    "momentum_rate_damping",
    "momentum_translational_lift",
    "plausibility",
    "separation",
    "torque_text",
    "unit_of",
]


def _priors() -> dict:
    out = {}
    for name, cls in FIT_EFFECTS.items():
        for key, plausible in cls.facts.ranges.items():
            out[name if key == ALL else f"{name}.{key}"] = (
                plausible.lower, plausible.upper, plausible.kind, plausible.source)
    return out


#: parameter (``effect.parameter``, or ``effect`` for all its parameters) -> (lower, upper,
#: kind, source): the effects' declared plausible ranges (a read-only view). kind
#: "relative": fraction of 1; "mass": of the vehicle mass; "arm": of the arm length;
#: "absolute": in the parameter's unit; "hover", "momentum", "lift": see
#: :class:`quadsim.effects.facts.PlausibleRange`.
PRIORS = MappingProxyType(_priors())

#: score given to a parameter without a prior (ranks between well inside and at the edge).
NO_PRIOR_SCORE = 0.5


def _key(parameter: str) -> str | None:
    if parameter in PRIORS:
        return parameter
    head = parameter.split(".")[0]
    return head if head in PRIORS else None


def plausibility(parameter: str, value: float, params: VehicleParams):
    """(score, plausible, prior text) of a fitted ``value``; (0, True, "") without a prior."""
    key = _key(parameter)
    if key is None:
        return NO_PRIOR_SCORE, True, ""
    lower, upper, kind, source = PRIORS[key]
    if kind == "mass":
        value = value / params.mass
    elif kind == "hover":  # linear thrust term as a fraction of the hover thrust
        value = value / hover_thrust_per_speed(params)
    elif kind == "arm":
        value = value / arm_length(params)
    elif kind == "momentum":
        value = value / momentum_rate_damping(params)
    elif kind == "lift":
        value = value / momentum_translational_lift(params)
    bound = upper if value >= 0 else lower
    score = abs(value) / abs(bound) if bound != 0 else (0.0 if value == 0 else float("inf"))
    scale = {"relative": 100, "mass": 100, "arm": 100, "hover": 100, "absolute": 1,
             "momentum": 1, "lift": 1}[kind]
    unit = {"relative": " %", "mass": " % of the vehicle mass", "arm": " % of the arm",
            "hover": " % of the hover thrust", "absolute": "",
            "momentum": (f" x the momentum-theory damping "
                         f"{momentum_rate_damping(params):.2g} N m s/rad"),
            "lift": (f" x the momentum-theory lift "
                     f"{momentum_translational_lift(params):.2g} kg/m")}[kind]
    text = f"plausible {lower * scale:g} .. {upper * scale:g}{unit} ({source})"
    return float(score), bool(score <= 1.0), text


#: a parameter is determined when its posterior spread is below this fraction of its prior's
#: (the rule a value is printed by, and a shared thrust-curve slope kept by)
DETERMINED = 0.5


def curve_slope_sd(params: VehicleParams) -> float:
    """Prior spread (N s/rad) of a thrust curve's linear term: half the plausible range of
    :data:`PRIORS` ``thrust_curve.linear`` (a fraction of the hover thrust per rad/s), in
    SI for ``params``."""
    return ThrustCurve.facts.spread_of("linear", params)


def candidate_plausibility(values: dict, params: VehicleParams):
    """(score, plausible, text) of a whole fitted candidate: its least plausible parameter.

    A per-rotor effect's values are split into their mean (judged as the uniform parameter
    its facts name, ``uniform_as``: a mismatch's as a thrust-per-Omega^2 change,
    ``thrust_factor.change``) and each rotor's deviation from that mean (judged as the
    per-rotor effect): four rotors all 16 % weak are a uniform loss, not four damaged props."""
    values = dict(values)
    for name, cls in FIT_EFFECTS.items():
        facts = cls.facts
        if not (facts.per_rotor and facts.uniform_as):
            continue
        prefix = f"{name}.{facts.per_rotor.partition('{}')[0]}"
        rotors = {k: v for k, v in values.items() if k.startswith(prefix)}
        if len(rotors) > 1:
            mean = sum(rotors.values()) / len(rotors)
            for k, v in rotors.items():
                values[k] = v - mean
            values[facts.uniform_as] = mean
    scores = [plausibility(k, v, params) for k, v in values.items()]
    return max(scores, key=lambda s: s[0]) if scores else (NO_PRIOR_SCORE, True, "")


# --- collinear explanations in words (module doc) ---------------------------------------------


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
    return f"{name.replace('_', ' ')}: {text} {plus_minus(value, c, 1.0, '.4g')} {unit}".rstrip()


def torque_text(entry: dict) -> str:
    rms = entry.get("heldout_rms_after") or {}
    have = [(k, rms[k]) for k in ("Mx", "My", "Mz") if k in rms]
    return ", ".join(f"{k} {v:.2g} N m" for k, v in have)
