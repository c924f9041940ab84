"""The law of the references' air drag, as a flight shows it: chosen once per flight by the
evidence of "no difference", and every reading judged under it.

Why. The reference model fits the horizontal air drag its flights share as a rotor drag,
linear in the air velocity (:mod:`quadsim.effects.rotor_drag`). An airframe's drag is
quadratic (:mod:`quadsim.effects.body_drag`), under one of two laws: on the air speed,
``-1/2 rho C_d A |v| v``, or each body axis on its own, ``-1/2 rho C_d A |v_i| v_i`` (a box's
faces taken apart: l2f's, PyFlyt's and multirotor's drag). At the references' ~1 m/s the
three give the same force; a flight flown faster, or in a wind, shows which one the vehicle
has. The law is the vehicle's, the references' as much as the flight's: it is no reading of
its own, and every reading must be judged under the same one. Measured, before:

- with the quadratic laws only inside the wind reading, two nominal multirotor flights
  outside the references' envelope gained 5-10 log units from the law per axis at a wind of
  0.2-0.6 m/s, and one was named ``wind`` at 0.80;
- with "no difference" alone given the laws, an l2f roll/pitch inertia error of +34 % (a
  flight at 1.3x the references' speed) became ``no_significant_gap`` at 0.97: the inertia
  reading kept the linear law and lost 10 log units on Fx and Fy to it.

How (:func:`choose`). "No difference" is fitted under each law: the references' own, and
each quadratic law with its C_d A held at the references' equivalent
(:func:`quadsim.gap.explanations.quadratic_laws`,
:func:`quadsim.gap.calibrate.quadratic_equivalent`: least squares of the two laws'
horizontal force over the reference flights). The law of the highest evidence is the
flight's (equal prior odds; on a flight at the references' speeds the laws tie, and either
choice predicts the same). Every explanation is then built under it (:func:`under`): the
references' rotor drag replaced by the airframe drag :class:`DragLaw`, a pseudo-effect fixed
at that C_d A (no parameter of its own, never part of an answer); a body-drag reading adds
drag under the same law; a rotor-drag reading adds a linear drag to it (its prior centred
at 0, the references' linear drag being the law now); the wind reading keeps only its
variant through that law, with C_d A fitted (:func:`quadsim.gap.explanations.wind_readings`).
Held fixed in "no difference", not fitted: a C_d A free within its prior would let "no
difference" absorb part of a drag change, which a drag reading must explain.

A choice by the maximum, not a sum over the laws: the laws enter every reading, and a sum
would fit every reading three times (the per-flight time). The choice is a model selection on
a nuisance with two or three values, by the flight's own evidence, and the entry states it
(``drag_law`` in the per-flight JSON).

Example::

    >>> law = choose(states, reference, start_delay_s=0.0)     # None: the references' law
    >>> rows = evaluate(states, reference, under(explanations_for(reference, states), law))
"""

from __future__ import annotations

import dataclasses

from .evidence import evaluate
from .explanations import Explanation, explanations_for, law_replaces, quadratic_laws
from .fitmodels import DragLaw  # declared with the diagnosis' other effects
from .reference import Reference

__all__ = ["DragLaw", "choose", "under"]



def nulls(reference: Reference, states) -> list[Explanation]:
    """"No difference" under the references' own drag and under each quadratic law, with
    the flight's rotor delay as :func:`quadsim.gap.explanations.explanations_for` gives it."""
    plain = next(e for e in explanations_for(reference, states, names=())
                 if e.name == "no_difference")
    return [plain] + [dataclasses.replace(plain, variant=_variant(variant),
                                          parts=(("drag_law", dict(fixed, cd_area=drag), ()),),
                                          replaces=law_replaces(fixed))
                      for variant, fixed, drag in quadratic_laws(reference)]


def _variant(wind_variant: str) -> str:
    return "the references' drag as " + wind_variant.split(" drag as ")[-1]


def choose(states, reference: Reference, start_delay_s: float = 0.0,
           memo: dict | None = None) -> Explanation | None:
    """The flight's drag law (module doc): the "no difference" of the highest evidence
    among :func:`nulls`; None where that is the references' own law (or they have no
    horizontal drag to take as quadratic). ``memo``: kept for the flight's evaluation."""
    candidates = nulls(reference, states)
    if len(candidates) < 2:
        return None
    rows = evaluate(states, reference, candidates, start_delay_s=start_delay_s, memo=memo)
    best = max(rows, key=lambda ev: ev.log_z)
    return best.explanation if best.explanation.parts else None


def under(explanations: list[Explanation], law: Explanation | None) -> list[Explanation]:
    """``explanations`` built under the flight's drag law ``law`` (module doc); unchanged
    where it is None."""
    if law is None:
        return list(explanations)
    part = law.parts[0]
    axes = _per_axis(part[1])
    out = []
    for e in explanations:
        drag = next((fixed for n, fixed, _ in e.parts if n == "body_drag"), None)
        if e.name == "no_difference":
            out.append(dataclasses.replace(e, variant=law.variant, parts=law.parts,
                                           replaces=law.replaces))
        elif e.name == "wind" and drag is not None:
            if _per_axis(drag) == axes:                  # the wind through this law only
                out.append(dataclasses.replace(e, log_prior=0.0))
        elif e.name == "wind":
            continue                                     # through the linear law: not this one
        else:
            out.append(_with_law(e, part, law.replaces))
    return out


def _per_axis(fixed: dict) -> bool:
    """Whether a body drag's fixed values take the law per body axis."""
    return fixed.get("per_axis", 0.0) >= 0.5


def _with_law(e: Explanation, part: tuple, replaced: tuple = ("rotor_drag",)) -> Explanation:
    per_axis = {k: v for k, v in part[1].items() if k == "per_axis"}
    parts = tuple((n, dict(fixed, **per_axis), fitted) if n == "body_drag" and fitted
                  else (n, fixed, fitted) for n, fixed, fitted in e.parts)
    mean = e.mean
    if "rotor_drag" in e.replaces and any(n == "rotor_drag" for n, _, _ in e.parts):
        # a rotor drag of the flight's own, on top of the law: centred on none
        names = e.parameter_names
        mean = tuple(0.0 if k == "rotor_drag.coefficient" else m for k, m in zip(names, mean))
    replaces = e.replaces + tuple(g for g in replaced if g not in e.replaces)
    return dataclasses.replace(e, parts=parts + (part,), mean=mean, replaces=replaces)
