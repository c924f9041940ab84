"""Readings and verdicts in words: what a user reads in ``answer`` and ``magnitude``.

Pure text over the judgment's data (:mod:`quadsim.gap.judge`); nothing here decides.

* :func:`reading_text`: a reading's magnitude (determined values only, each with its 95 %
  interval and unit, :func:`quadsim.gap.fitting.describe`); a shared parameter given a
  value of its own is set beside the references' value (:func:`reference_text`); wind is
  worded as the steady air force it exerts, with the wind speed at the references' drag.
* :func:`nominal_words`: the same text where the reference model is the parameter set
  (held-out mode: "no difference from the nominal model", no references' values; held out
  against nominal reference flights the per-flight text).
* :func:`answer`: the one answer writer of both modes. Its sentences name what the lack
  of fit was measured against (:attr:`quadsim.gap.judge.Baseline.against`):
  ``"references"`` (per flight: "Not in the library: ... beyond the reference flights'") or
  ``"training"`` (held out: "Unexplained: ... does not carry over"; a systematic
  remainder beyond the noise model, or against nominal references beyond their own slow
  parts, is worded with its size in the channel's unit).
* :func:`timing_words`: per flight, a rotor timing stated as a delay or a lag where the
  data cannot separate the two forms.
* :func:`batch_answer`: the per-flight result's one line (verdict counts).
* :func:`residual_text`: a judged flight's residual against the references' before and after
  its answer (the report's and the summary's line, the JSON's ``residual.text``).

Probabilities print as whole percent (``> 99 %`` from 0.995 in held-out wording).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..effects.thrust_factor import SESSION_SPREAD
from .explanations import reference_determined
from .fitting import FIT_EFFECTS, describe
from .logcheck import TIMING_WORDS  # defined there: logcheck imports no gap module
from .residual import channel_unit

__all__ = ["across_sessions", "answer", "asserted", "batch_answer", "nominal_words",
           "grown_words", "outside_words", "reach_words", "reading_text", "reference_text",
           "residual_text",
           "session_text", "stand_in_words", "timing_words", "total_mass", "weighed_keys",
           "TIMING_WORDS", "bound_words", "left_out_words", "refit_words"]


def total_mass(ev) -> dict | None:
    """A reading's added mass in all where it has two or more determined mass parts (a
    payload's part fixed to the frame and its part on a cable: what a scale weighs):
    {"mass": the sum (kg), "ci": its 95 % half-interval (kg), 1.96 sqrt(1'C 1) over the
    parts' posterior covariance C (``ev.post_cov``, as stated: :func:`quadsim.gap.judge.
    as_stated`)}; None with fewer parts or without the covariance."""
    keys = list(ev.values)
    parts = [k for k in keys if k.endswith(".mass") and ev.determined.get(k)]
    cov = getattr(ev, "post_cov", None)
    if len(parts) < 2 or cov is None or np.shape(cov) != (len(keys), len(keys)):
        return None
    idx = [keys.index(k) for k in parts]
    var = float(np.sum(np.asarray(cov, float)[np.ix_(idx, idx)]))
    return {"mass": float(sum(ev.values[k] for k in parts)),
            "ci": 1.96 * float(np.sqrt(max(0.0, var)))}


def weighed_keys(ev) -> list[str]:
    """The determined parameters of ``ev`` read through the gravity balance (each effect's
    :attr:`~quadsim.effects.facts.EffectFacts.weighed`), in ``ev.values`` order."""
    out = []
    for key in ev.values:
        effect, _, parameter = key.partition(".")
        cls = FIT_EFFECTS.get(effect)
        if cls is not None and parameter in cls.facts.weighed and ev.determined.get(key):
            out.append(key)
    return out


def across_sessions(ev, vehicle_mass: float, spread: float | None = None) -> dict:
    """The stated sizes of ``ev``'s weighed masses (:func:`weighed_keys`) if the judged
    flight's session has another thrust per Omega^2 than the references' (issue 47).

    The rotors weigh the vehicle: at hover M g = b sum Omega^2, and the fit reads the whole
    weighed mass M = ``vehicle_mass`` (the model's, kg: what the references' b was
    calibrated with) + the added masses in units of the references' b. A flight whose b is
    (1 + c) times theirs carries M (1 + c), so the added mass read as m is m + c M: the
    error multiplies the whole weighed mass, not the payload alone (a 6.6 g payload on a
    37 g vehicle at c = 2.8 % is 1.2 g off, not 0.19 g). ``spread``: the 95 % half-width of
    c (relative; default :data:`quadsim.effects.thrust_factor.SESSION_SPREAD`). Its part,
    ``spread`` M, and the stated within-session half-width ``ci`` (noise, and beyond the
    references' reach their bias bound: ``ev`` as stated) are independent 95 % half-widths
    and add in quadrature: sqrt(ci^2 + (spread M)^2). The balance does not say how c M
    splits between two mass parts (a fixed and a swinging one), so each part carries it in
    full, as their sum does.

    -> {"thrust_spread": spread, "ci": {key: that half-width, kg}, "total_ci": the sum's
    (kg; only where :func:`total_mass` states one)}; {} without a determined weighed mass.
    The within-session ``ci`` (``Reading.ci``, ``total["ci"]``) stay as they are: flights
    of one session (the references' and a flight flown with them) share their b, and only
    those compare at that width; a scale's reading compares with these."""
    keys = weighed_keys(ev)
    if not keys:
        return {}
    s = SESSION_SPREAD.relative if spread is None else float(spread)
    weighed = float(vehicle_mass) + sum(float(ev.values[k]) for k in keys)
    part = s * abs(weighed)
    out = {"thrust_spread": s,
           "ci": {k: float(np.hypot(1.96 * ev.post_sd[k], part)) for k in keys}}
    total = total_mass(ev)
    if total is not None:
        out["total_ci"] = float(np.hypot(total["ci"], part))
    return out


def session_text(across: dict) -> str:
    """The words of :func:`across_sessions`: "± 1.3 g on another session's air (its thrust
    per Ω² ± 2.8 %: 20-26 °C, pressure ± 2 %)" (the sum's where it has one, else the one
    weighed part's); "" without one."""
    if not across:
        return ""
    ci = across.get("total_ci", max(across["ci"].values()))
    low, high = (t - 273.15 for t in SESSION_SPREAD.temperature_k)
    return (f"± {1e3 * ci:.2g} g on another session's air (its thrust per Ω² ± "
            f"{100 * across['thrust_spread']:.2g} %: {low:.0f}-{high:.0f} °C, pressure ± "
            f"{100 * SESSION_SPREAD.pressure_swing:.0f} %)")


def asserted(ev, key: str, off: float = 0.0) -> bool:
    """Whether ``ev`` asserts parameter ``key``: its value is determined and its 95 %
    interval (1.96 posterior spreads) excludes the ``off`` value."""
    return bool(ev.determined.get(key)) and abs(ev.values[key] - off) > 1.96 * ev.post_sd[key]


def _value_text(key: str, value: float, sd: float, params) -> str:
    return describe(key.split(".")[0], {key: value}, {key: 1.96 * sd}, params)


#: why a shared value stops at a bound of the references' fit (calibrate.fit_bounds)
_BOUND_WHY = {"motor_lag.time_constant": "a quarter of a fit sample, a shorter lag is not "
                                          "resolved"}


def reference_text(key: str, value: float, sd: float, reference) -> str:
    """The references' value of a shared parameter in words; where their fit stopped at a
    bound, the value without a spread and that it is a bound (the data say only "at or
    beyond"), e.g. "the rotors lag their commands by +2.5 ms (time constant) or less (their
    fit's lower bound: a quarter of a fit sample, a shorter lag is not resolved)"."""
    side = getattr(reference, "at_bound", {}).get(key)
    if side is None:
        return _value_text(key, value, sd, reference.params)
    why = _BOUND_WHY.get(key, "the end of its physical range")
    return (describe(key.split(".")[0], {key: value}, {}, reference.params)
            + f" or {'less' if side == 'lower' else 'more'} (their fit's {side} bound: {why})")


def bound_words(reference) -> str:
    """One sentence naming the shared parameters at which the references' calibrated model
    stops at a bound of its fit (``reference.at_bound``: parameter -> "lower"/"upper",
    :func:`quadsim.gap.calibrate.bounded`), each with its value in words
    (:func:`describe`) and why the bound is there; "" where none is. The reference flights
    would take such a value further than the library's form allows (a trait they share that
    it does not take: a real vehicle's roll response beyond +200 % inertia, docs/gap.md,
    "Known limits") or than the data resolve (a motor lag below a quarter of a fit sample);
    every judged flight is compared with the model at that bound, so the user is told, not
    only the JSON (``reference_model.at_bound``)."""
    at = dict(getattr(reference, "at_bound", {}) or {})
    if not at:
        return ""
    values = reference.values()
    groups: dict[str, dict] = {}
    for key in at:
        groups.setdefault(key.split(".")[0], {})[key] = values[key]
    parts = []
    for name, vals in groups.items():
        try:
            text = describe(name, vals, {}, reference.params)
        except (KeyError, ValueError):          # a fit form of the diagnosis, not an effect
            text = ", ".join(f"{k} {v:.3g}" for k, v in vals.items())
        why = sorted({f"at its bound: {_BOUND_WHY[k]}" if k in _BOUND_WHY else
                      f"at the {at[k]} end of its range" for k in vals})
        parts.append(f"{text}, {'; '.join(why)}")
    return ("the reference model's fit stops at a bound: " + "; ".join(parts) + ". The "
            "reference flights would take it further than the library's form allows or the "
            "data resolve; each flight is judged against the model at that bound "
            "(docs/gap.md, Known limits)")


def refit_words(reference) -> str:
    """One sentence where the reference flights' weight balance needs a thrust per Omega^2 (b)
    further from the parameter set's, at the set's mass, than two sessions' air can move it
    (``nominal_refit.thrust`` beyond :data:`quadsim.effects.thrust_factor.SESSION_SPREAD`'s
    95 % half-width, 2.8 %); "" otherwise. The balance m g = b sum(Omega^2) fixes only b / m:
    the set's b or its mass is off, which the flights cannot tell apart; a mass a flight
    reads is m times its share of the thrust, so where the set's mass is what is off, every
    mass reading is off by the same factor (docs/own-vehicle.md)."""
    x = reference.values().get("nominal_refit.thrust")
    if x is None or abs(x) <= SESSION_SPREAD.relative:
        return ""
    mass = 1e3 * reference.params.mass
    return (f"the reference flights' weight balance needs {1 + x:.3g}x the parameter set's "
            f"thrust per Omega^2 (b) at its mass of {mass:.3g} g, beyond the "
            f"{100 * SESSION_SPREAD.relative:.1f} % another session's air can give: the set's "
            "b or its mass is off, which the balance cannot tell apart; a mass a flight reads "
            "is stated in the set's mass, so if that is what is off every mass reading is off "
            f"by the same factor ({100 * x:+.0f} %): put the vehicle's weighed mass in the set "
            "to state masses in its grams")


def left_out_words(reference) -> str:
    """One sentence naming the references left out of the reference model
    (``reference.left_out``: (name, verdict, channels), :func:`quadsim.gap.calibrate.
    odd_references`) with how the self-check judged each against the others, and that the
    flights are judged against the rest; "" where none was."""
    left = tuple(getattr(reference, "left_out", ()) or ())
    if not left:
        return ""
    kept = len(getattr(reference, "names", ()) or ())
    each = "; ".join(f"{Path(n).name} ({v}{', on ' + ', '.join(c[:3]) if c else ''})"
                     for n, v, c in left)
    return (f"left out of the references: {each}. Judged against the others "
            f"{'it is' if len(left) == 1 else 'they are'} unlike them beyond their own "
            "spread, stated as confident (a flight with a change given as a reference?), so "
            f"what {'it carries' if len(left) == 1 else 'they carry'} would pass for normal; "
            f"every flight is judged against the other {kept}, calibrated and checked again "
            "without it (docs/gap.md, \"The self-check\")")


def reading_text(ev, reference) -> str:
    """The magnitude of a reading in words (determined values only). A weighed mass is
    stated at the references' thrust per Omega^2 and, beside it, on another session's air
    (:func:`across_sessions`, :func:`session_text`)."""
    params, name = reference.params, ev.name
    keys = [k for k, ok in ev.determined.items() if ok]
    if name == "no_difference":
        return "no difference from the reference flights"
    if name == "signal_delay":
        mean = 1e3 * reference.rotor_shift_s      # the references' fitted rotor timing
        d = 1e3 * ev.values["delay.rotor"]
        if not keys:
            return f"the {TIMING_WORDS} with a delay of their own (size not determined)"
        ci = 1.96e3 * ev.post_sd["delay.rotor"]
        return (f"the {TIMING_WORDS} {abs(d):.0f} ± {ci:.0f}"
                f" ms {'later' if d > 0 else 'earlier'} than on the reference flights "
                f"(references: {mean:+.1f} ms against the logged motion, fitted)")
    if name == "wind":
        return _wind_text(ev, reference)
    if not keys:
        return f"{name.replace('_', ' ')} (size not determined by this flight)"
    calm = _calm_refit(ev)
    values = {k: ev.values[k] for k in keys if not k.endswith(".alpha") and k not in calm}
    ci = {k: 1.96 * ev.post_sd[k] for k in values}
    text = describe(name, values, ci, params, ev.explanation.fixed_values)
    total = total_mass(ev)
    across = session_text(across_sessions(ev, params.mass))
    if total is not None:
        text += (f"; in all {1e3 * total['mass']:+.2g} ± {1e3 * total['ci']:.2g} g "
                 "(on the cable and fixed to the frame together: what a scale weighs) at "
                 f"the reference flights' thrust per Ω², {across}")
    elif across:
        text += f" at the reference flights' thrust per Ω²; {across}"
    if calm and all(ev.determined.get(k) for k in calm):
        text += (f"; in calm air (the wind refitted with it, within ±"
                 f"{max(1.96 * ev.post_sd[k] for k in calm):.2g} m/s)")
    if ev.explanation.replaces:
        # the references' own values, where their flights determine them
        ref, known_ref = reference.values(), reference_determined(reference)
        s_ref = dict(zip(reference.candidate.parameter_names, reference.s_ref))
        # only the groups it gives values of its own: a reading on top of a shared group
        # (the flight's thrust curve about zero speed on the references' slope about their
        # hover) is another quantity than the references' value of the same name
        # nor a group the flight's drag law stands in for (its own drag is on top of the law)
        law = {"rotor_drag", "body_drag"} if any(
            n == "drag_law" for n, _, _ in ev.explanation.parts) else set()
        known = [k for k in values if known_ref.get(k, False)
                 and k.split(".")[0] in set(ev.explanation.replaces) - law]
        if known:
            text += " (references: " + "; ".join(
                reference_text(k, ref[k], s_ref[k], reference) for k in known) + ")"
    if ev.explanation.variant and ev.explanation.variant not in text:
        text = f"{ev.explanation.variant}: {text}"
    return text + _spin_text(name, ev, values, reference)


def _spin_text(name: str, ev, values: dict, reference) -> str:
    """A propeller reading's speed per command, (1 + change)^-alpha, where alpha was fitted
    (held out it is not: the training flights' map has it): "the rotors would spin +2.1 %
    per command" (all rotors) or "rotor 4 would spin +0.9 % per command" (one)."""
    alpha = ev.values.get(f"{name}.alpha")
    if not reference.rotor or alpha is None or name not in ("thrust_factor", "thrust_mismatch"):
        return ""
    keys = [k for k in values if k == "thrust_factor.change"
            or k.startswith("thrust_mismatch.rotor_")]
    if not keys:
        return ""
    who = ("the rotors" if name == "thrust_factor"
           else f"rotor {keys[0].rsplit('_', 1)[1]}")
    spin = 100 * ((1 + ev.values[keys[0]]) ** -alpha - 1)
    return f"; {who} would spin {spin:+.1f} % per command (lighter load torque)"


def _calm_refit(ev) -> list[str]:
    """The wind keys a drag or lift reading refits (:func:`quadsim.gap.explanations.with_wind`)
    when no component's 95 % interval excludes calm air (as :func:`reading_name` decides):
    the answer then says "in calm air" instead of printing a wind of 1e-5 ± 0.03 m/s."""
    if ev.name == "wind" or not any(part == "wind" and fitted
                                    for part, _, fitted in ev.explanation.parts):
        return []
    keys = [k for k in ("wind.vx", "wind.vy") if k in ev.values]
    if any(asserted(ev, k) for k in keys):
        return []
    return keys


def _wind_text(ev, reference) -> str:
    force = ev.air_force if ev.air_force is not None else np.zeros(3)
    horiz = force[:2]
    size = float(np.hypot(*horiz))
    axis = int(np.argmax(np.abs(horiz)))
    sign = "+" if horiz[axis] >= 0 else "-"
    text = (f"a steady air force (beyond the references') of {size:.3g} N along "
            f"{sign}{'xy'[axis]} (world; "
            f"{100 * size / reference.params.weight:.2g} % of the weight), growing with "
            "airspeed")
    keys = [k for k in ("wind.vx", "wind.vy") if ev.determined.get(k)]
    if keys:
        ref = reference.values()
        speed = float(np.hypot(ev.values["wind.vx"] - ref.get("wind.vx", 0.0),
                               ev.values["wind.vy"] - ref.get("wind.vy", 0.0)))
        drag = ev.values.get("body_drag.cd_area")
        if drag is not None:        # explanations.WIND_DRAG: the drag's law taken quadratic
            size = (f" (C_d A {1e4 * drag:.3g} cm^2)" if ev.determined.get("body_drag.cd_area")
                    else "")
            law = ("a quadratic drag on each body axis"
                   if ev.explanation.fixed_values.get("body_drag.per_axis", 0.0) >= 0.5
                   else "a quadratic airframe drag")
            text += (f": wind of ~{speed:.2g} m/s beyond the references', through their "
                     f"drag as {law}{size}")
        else:
            text += (f": wind of ~{speed:.2g} m/s beyond the references' at their rotor-drag "
                     "coefficient")
    else:
        text += " (drag coefficient x wind speed fixed by the data, not each factor)"
    return text


def nominal_words(text: str, own: bool, *, references: bool = False) -> str:
    """A reading's text (:func:`reading_text`) in held-out terms, where the reference model
    is the parameter set: "no difference from the nominal model", the references' values
    (there are none: "off", no spread) left out. ``own``: whether the text is the reading's
    own (False: an undetermined explanation counted as "no difference"). ``references``:
    held out against nominal reference flights, whose model is the reference: the text as
    per flight ("no difference from the reference flights", their values kept)."""
    if references:
        return text if own else "no difference from the reference flights"
    if not own:
        return "no difference from the nominal model"
    cut = text.find(" (references: ")     # the nominal model's values: "off", no spread
    if cut >= 0:
        depth, end = 0, len(text)
        for k in range(cut + 1, len(text)):
            depth += {"(": 1, ")": -1}.get(text[k], 0)
            if depth == 0:
                end = k + 1
                break
        text = text[:cut] + text[end:]
    return (text.replace("no difference from the reference flights",
                         "no difference from the nominal model")
            .replace("the reference flights' thrust per Ω²", "the model's thrust per Ω²")
            .replace(" (beyond the references')", "")
            .replace(" beyond the references' at their rotor-drag coefficient",
                     " at the fitted rotor-drag coefficient"))


def _pct(p: float) -> str:
    """A probability as whole percent; ``> 99 %`` from 0.995."""
    return f"{100 * p:.0f} %" if p < 0.995 else "> 99 %"


def outside_words(p_out: float, share: float, within: float, *,
                  gap: str = "the gap") -> str:
    """The sentence beside a name that leaves something beyond the references'
    (:func:`quadsim.gap.judge.with_outside`): ``p_out`` the probability that the name stands
    in for an effect outside the library, ``share`` the share of the flight's gap the name
    leaves, ``within`` the name's probability among the library's readings alone; ``gap``
    whose gap that is in words (held out against references: "the training flights' gap")."""
    source = f", from the {100 * share:.1f} % of {gap} the name leaves" \
        if np.isfinite(share) else ""
    return (f" Of its {_pct(within)} among the library's readings, {100 * p_out:.0f} % is "
            f"that it stands in for an effect outside the library{source}.")


def grown_words(grown: dict) -> str:
    """The sentence of a residual between the references' straight lines and their growth
    law (:func:`quadsim.gap.judge.grown_lack`): ``grown`` channel -> (RMS over the typical
    RMS the straight line expects there, z); "" where none. E.g. " Not sure: this flight
    drives Fz harder than every reference, and its residual there (2.1x the references'
    straight-line trend) ..."."""
    if not grown:
        return ""
    where = ", ".join(f"{k} {v[0]:.2g}x" for k, v in grown.items())
    return (f" Not sure: this flight drives {', '.join(grown)} harder than every reference, "
            f"and its residual there ({where} what the references' straight-line trend of it "
            "expects) lies within what the reference model's own error may grow to so far "
            "beyond them (noise plus an error in proportion to the signal): that growth "
            "cannot be told from a difference of this flight.")


def reach_words(reach, moved: dict, *, outcome: str, bias: float = 0.0) -> str:
    """The sentence of a flight beyond its references' reach (:func:`quadsim.gap.judge.
    beyond_reach`): ``reach`` its :class:`quadsim.gap.reference.Reach`; ``moved`` reading ->
    (its probability among the library's readings, the share f of its evidence over no
    difference that the model's own error could produce there,
    :func:`quadsim.gap.judge.extrapolation_share`, its reading in words or "" where the
    answer states it already); ``outcome`` the verdict's; ``bias``: the named reading's
    bias bound in standard errors that its stated intervals include
    (:func:`quadsim.gap.judge.reach_bias`; 0: none said). E.g. "Flown 7.3x above your references'
    RMS variation of the specific force's size, 39 times their own spread in it: ..."."""
    from .reference import COORDINATES

    what = next(co[2] for co in COORDINATES if co[0] == reach.coordinate)
    times = (f", {reach.ratio:.0f} times their own spread in it" if np.isfinite(reach.ratio)
             else ", in which they do not spread")
    side = "above" if reach.above else "below"
    parts = "; ".join(f"{k} ({_pct(p)} among the library's readings{': ' + m if m else ''}): "
                      f"{100 * f:.0f} % of its evidence over no difference that error could "
                      "produce" for k, (p, f, m) in moved.items())
    tail = (": no difference of the vehicle is the more probable reading, not sure"
            if outcome == "no_significant_gap" else
            ": that share of its weight counts as no difference of the vehicle")
    # which law's error: growing where the flight drives a channel harder than every
    # reference, not shrinking where it drives one more gently ("Below the references")
    grow = ("a model error growing in proportion to how hard the flight drives each "
            "channel")
    under = getattr(reach, "allowance_under", None)
    shrink = under is not None and bool(np.any(np.asarray(under, float) > 0))
    laws = [grow] if np.any(np.asarray(reach.allowance, float) > 0) or not shrink else []
    if shrink:
        laws.append("a model error that need not shrink where the flight drives a channel "
                    "more gently than every reference")
    where = (f"{np.exp(reach.excess):.2g}x {side} your references' {what}" if reach.above
             else f"at {np.exp(-reach.excess):.2g}x the lowest of your references' {what}")
    sizes = (f" The sizes stated include the bias that error could cause: up to "
             f"{bias:.2g} standard errors beside the noise's 1.96." if bias > 0 else "")
    return (f" Flown {where}{times}: "
            "they cannot show how the reference model extrapolates so far, and its own "
            f"error there ({'; or '.join(laws)}) "
            f"could produce the readings: {parts}{tail}.{sizes}")


def stand_in_words(name: str, within: float, magnitude: str, share: float,
                   p_out: float, *, gap: str = "the flight's gap") -> str:
    """The answer where the outside hypothesis is more probable than the name it
    weighs (:func:`quadsim.gap.judge.with_outside`, outcome ``unexplained``): ``name`` the
    library's most probable reading, ``within`` its probability among the library's readings
    alone, ``magnitude`` its reading in words, ``share`` the share of the flight's gap it
    leaves, ``p_out`` the probability that it stands in for an effect outside the library;
    ``gap``: whose gap, in words (held out against references: "the training flights' gap",
    each of them against the references)."""
    left = f" leaves {100 * share:.0f} % of {gap}," if np.isfinite(share) \
        else " leaves"
    return (f"Not in the library: the most probable of the library's readings ({name}, "
            f"{_pct(within)} among them: {magnitude}){left} more than the reference flights "
            f"leave, so it more probably stands in for an effect outside the library "
            f"({100 * p_out:.0f} %) than it is the cause ({100 * (within - p_out):.0f} %).")


def _remains_text(remains: dict, normal: str = "the noise's") -> str:
    """A systematic remainder (channel -> (slow RMS in the channel's unit, ratio of its mean
    square to its normal's typical one, :func:`quadsim.gap.judge.remainder`)) in words;
    ``normal``: that normal's words."""
    return ", ".join(f"{k} {v[0]:.2g} {channel_unit(k)} ({v[1] ** 0.5:.1f}x {normal})"
                     for k, v in remains.items())


def answer(outcome: str, lead: dict, *, stated: list, lack: dict, against: str,
           remains: dict | None = None, tentative: bool = False,
           reduction: float | None = None, separate: list | dict = (),
           references: bool = False) -> str:
    """The verdict in words a quadrotor engineer acts on.

    ``outcome``: the verdict's outcome; ``lead``: the most probable reading (a posterior
    row: name, probability, magnitude); ``stated``: the other readings stated with it (rows,
    "no difference" excluded held out); ``lack``: the lack of fit (channel -> (ratio, z));
    ``against``: ``"references"`` (per flight) or ``"training"`` (held out, the baseline of
    :func:`quadsim.gap.judge.lack_of_fit`); ``remains``: the systematic remainder (held
    out); ``tentative``: the name is tentative; ``reduction``: the share of the held-out gap
    the named reading explains; ``separate``: per flight the channels on which the two
    leaders differ most, held out ``{reading: how to separate it from the lead}``;
    ``references``: held out against nominal reference flights (the reference model and
    the systematic remainder's normal are theirs, :func:`quadsim.gap.judge.remainder`):
    "no difference from the reference flights", a remainder beyond the references' slow
    parts, and a named ``signal_delay``'s share of the gap is said not to be its size (no
    difference reads each flight at its own rotor timing there,
    :meth:`quadsim.gap.diagnose.Against.check`); False: "from the nominal model", beyond the
    noise."""
    if against == "references":
        return _against_references(outcome, lead, stated=stated, lack=lack, separate=separate,
                                   tentative=tentative)
    remains = remains or {}
    nominal, noise = ("the reference flights", "the reference flights' own") if references \
        else ("the nominal model", "the noise")
    normal = "the references'" if references else "the noise's"
    if outcome == "no_significant_gap":
        nxt = stated[0] if stated else None
        return (f"No significant gap: no difference from {nominal} is the most "
                f"probable reading ({_pct(lead['probability'])}) and the residual is within "
                f"{noise} on every channel." + (f" Next: {nxt['name']} "
                                                  f"({_pct(nxt['probability'])}: "
                                                  f"{nxt['magnitude']})." if nxt else ""))
    if outcome == "unexplained":
        if lack:
            where = ", ".join(f"{k} at {v[0]:.2g}x" for k, v in lack.items())
            return (f"Unexplained: the most probable reading ({lead['name']}, "
                    f"{_pct(lead['probability'])}: {lead['magnitude']}) leaves the held-out "
                    f"flights beyond what it leaves on the training flights ({where} their "
                    "RMS): it does not carry over; the cause is outside the library, several "
                    "effects at once, or the data cannot tell.")
        if lead["name"] != "no_difference":
            return (f"Unexplained: the most probable reading ({lead['name']}: "
                    f"{lead['magnitude']}) needs an implausible magnitude; the cause is "
                    "outside the library.")
        return ("Unexplained: no library effect explains the residual (no difference from "
                f"{nominal} is the most probable reading, {_pct(lead['probability'])}"
                f"), yet a systematic residual stays beyond {noise}: "
                f"{_remains_text(remains, normal)} (slow part, RMS). The cause is outside the "
                "library.")
    text = f"Behaves as if {lead['magnitude']} ({_pct(lead['probability'])})"
    if stated:
        text += "; or as if " + "; or as if ".join(
            f"{r['magnitude']} ({_pct(r['probability'])})" for r in stated)
        text += f" (to separate them: {dict(separate).get(stated[0]['name'], '')})"
    if tentative:
        text += ". Tentative"
    text += f". Explains {100 * (reduction or 0.0):.0f} % of the held-out gap"
    if references and lead["name"] == "signal_delay":
        text += (" (against the reference flights no difference reads each flight at its own "
                 "rotor timing too, so a delay's share of the gap is not its size: its "
                 "evidence is)")
    if remains:
        text += (f"; beyond it a systematic residual stays above {noise} on "
                 f"{_remains_text(remains, normal)}: part of the gap is outside the library.")
    else:
        text += f", the residual within {noise} on every channel after it."
    return text


def _against_references(outcome: str, lead: dict, *, stated: list, lack: dict, separate,
                        tentative: bool) -> str:
    """Per-flight sentences (:func:`answer`); ``stated`` excludes ``lead``."""
    alt = "; ".join(f"or {r['name']} ({100 * r['probability']:.0f} %: {r['magnitude']})"
                    for r in stated)
    if outcome == "unexplained":
        where = ", ".join(f"{k} at {v[0]:.2g}x" for k, v in lack.items())
        return (f"Not in the library: after the most probable reading ({lead['name']}, "
                f"{100 * lead['probability']:.0f} %: {lead['magnitude']}) the residual stays "
                f"beyond the reference flights' on {where} their typical RMS.")
    if outcome == "no_significant_gap":
        text = (f"No difference from the reference flights "
                f"({100 * lead['probability']:.0f} %).")
        return text + (f" Next: {alt}." if alt else "")
    text = f"{lead['name']} ({100 * lead['probability']:.0f} %): {lead['magnitude']}."
    if tentative:
        text += " Tentative."
    if alt:
        text += f" {alt[0].upper()}{alt[1:]}."
        if separate:
            text += f" They differ most on {', '.join(separate)}."
    return text


def timing_words(lead, rival) -> str:
    """The sentence a per-flight answer adds where the flight does not separate its rotor
    timing readings (:func:`quadsim.gap.judge.timing_rival`): both stated, ``lead`` and
    ``rival`` (posterior rows: name, magnitude), neither a single confident name."""
    return (f" The rotors' timing differs from the reference flights': {lead['magnitude']} "
            f"({lead['name']}), or {rival['magnitude']} ({rival['name']}); the data cannot "
            "separate them: the evidence's margin between the two is within what it is on "
            "the reference flights, each judged against the others (the rotor law's form "
            "error, not noise), so it is not the cause's.")


def batch_answer(flights: list) -> str:
    """The per-flight result's answer: how many flights got which verdict, and the refused
    count (``flights``: verdicts or their JSON, each with ``verdict``); "No flight judged
    against the reference flights: 2 refused ..." when every flight was refused."""
    counts: dict[str, int] = {}
    for f in flights:
        counts[f["verdict"]] = counts.get(f["verdict"], 0) + 1
    refused = counts.get("refused", 0)
    judged = len(flights) - refused
    if not judged:
        return (f"No flight judged against the reference flights: {refused} refused (see each "
                "flight's reason)")
    text = f"{judged} flights judged against the reference flights: " + ", ".join(
        f"{n} {k}" for k, n in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
        if k != "refused")
    return text + (f"; {refused} refused (see each flight's reason)" if refused else "")


def residual_text(share, outcome: str) -> str:
    """A flight's residual against the references' level in words
    (:class:`quadsim.gap.result.GapShare`; ``outcome`` its verdict's): the largest channel
    before and after the answer, as RMS over the references' RMS, and the share of the
    excess the answer removes, e.g. "Residual up to 16.6x the references' RMS (Fz) before
    the answer, 5.1x (Fy) after it: it removes 87 % of the excess". A flight with no
    significant gap gets the largest channel only (its small excess is noise)."""
    first = int(np.argmax(share.before))
    last = int(np.argmax(share.after))
    text = (f"Residual up to {share.before[first]:.2g}x the references' RMS "
            f"({share.channels[first]})")
    if outcome == "no_significant_gap" or outcome == "refused":
        return text + "."
    text += f" before the answer, {share.after[last]:.2g}x ({share.channels[last]}) after it"
    if share.removed is None:
        return text + "."
    return text + f": it removes {100 * share.removed:.0f} % of the excess."
