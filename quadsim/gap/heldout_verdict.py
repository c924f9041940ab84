"""The held-out verdict from the evidence of every explanation (:mod:`.heldout`).

1. **Posterior per reading** (:func:`quadsim.gap.judge.posterior`, as per flight): training
   evidence plus held-out log-likelihood; "no difference" has the prior of all effects
   together; an explanation whose parameters the data do not determine, or determine
   within their 95 % interval of the no-difference value (:func:`differs`), counts as "no
   difference".
2. **A second effect** (``max_combination`` >= 2): when the lead leaves a systematic
   remainder (test 4b) or does not carry over to the held-out flights (4a), the lead is
   refitted with each other effect; a pair enters the
   posterior as one more reading with the prior of the lead alone split evenly among its
   partners (a second simultaneous effect is a priori no likelier than the first alone), and
   every part of it must be determined and plausible (:func:`every_part_stands`).
3. **Consistency** (:mod:`.consistency`): a named effect needs one value in slow and fast
   flight, at low and high rotor speed; otherwise ``unexplained`` with a partial explanation.
4. **Lack of fit ("not in the library")**, per channel c, on the lead reading:

   a. *Generalisation* -- the held-out flights against what the reading leaves on the
      training flights: per training flight j, l_jc = log(ms_jc / sigma_c^2); mean m_c and
      spread s pooled over channels (C (n - 1) degrees of freedom; n >= 2 pieces: with one
      training flight its halves); each held-out flight's z = (l_c - m_c) / (s sqrt(1 +
      1/n)) against the Student-t quantile at 1 - LOF_P / (C H) (Bonferroni over C channels
      and H held-out flights). The test of :func:`quadsim.gap.judge.lack_of_fit` with the
      training flights as references, with its two exemptions: a channel below its noise
      floor, and a reading that leaves at most ``FORM_ERROR`` (5 %) of the held-out flights'
      gap (the library form's error: RotorPy's CoM offset on the Crazyflie, 99.9 % of the
      held-out gap explained, was ``unexplained`` by rotor channels 1.7x the training RMS on
      a flight flown 1.3x faster). Beyond: ``unexplained`` (the reading does not carry
      over to flights it was not fitted on). A reading that does not carry over is also
      tried with a second effect (2.).
   b. *Systematic remainder* -- the slow part of the residual (0.5 s moving average,
      :func:`quadsim.gap.heldout.slow_part`) against what noise of the noise model gives
      it: for noise of scatter sigma_c and correlation time tau_c samples, a W-sample
      average has variance sigma_c^2 tau_c / W; over all flights ``ratio_c = mean(slow^2)
      / (sigma_c^2 tau_c / W)`` ~ chi2(nu) / nu with nu = N / W windows; beyond the
      quantile at 1 - LOF_P / C the channel keeps a systematic residual. With the lead
      ``no_difference`` this is ``unexplained`` (something acts that no library effect
      explains); after a named effect the name stands and the answer says what remains,
      with its size in the channel's unit ("part of the gap is outside the library").

   LOF_P = 1e-3 (:data:`quadsim.gap.judge.LOF_P`): one right model in a thousand is called
   unexplained by chance.
5. **Verdict**: the most probable reading with its probability (``tentative`` below
   :data:`quadsim.gap.judge.CONFIDENT`); readings stated: probability >=
   :data:`quadsim.gap.judge.READING_P`. A reading whose determined magnitude is outside its
   documented plausible range (:mod:`.priors`) has no prior probability: it is left out of
   the posterior before ranking, and a note names that effect with its own magnitude (a
   stand-in for something outside the library fits the data at a value no vehicle has).
   Only determined parameters are printed.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2
from scipy.stats import t as student_t

from . import collinear, consistency
from .fitting import Candidate
from .heldout import NOISE_WINDOW_S, Weighed, check, slow_part
from .judge import (CONFIDENT, LOF_P, READING_P, above_floor, channel_names, posterior,
                    reading_text, within_form_error)
from .priors import candidate_plausibility

__all__ = ["generalisation", "remainder", "rank", "readings_of", "entry_of"]


def _ms(res: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    return np.mean(res ** 2, axis=0) / sigma ** 2


def generalisation(w: Weighed, reference, null: Weighed | None = None) -> dict:
    """Channels whose held-out residual is beyond what the reading leaves on the training
    flights (module doc, 4a): channel -> (held-out RMS / training RMS, z). As per flight
    (:func:`quadsim.gap.judge.lack_of_fit`): a channel below its noise floor never lacks fit,
    and with ``null`` (the "no difference" Weighed) a reading that leaves at most
    :data:`quadsim.gap.judge.FORM_ERROR` of the held-out flights' gap (their excess mean
    square over the reading's training level, summed over channels) carries over."""
    pieces = w.train_residuals
    if len(pieces) < 2:
        pieces = [p for r in pieces for p in np.array_split(r, 2)]
    sigma = reference.sigma
    logs = np.log(np.maximum([_ms(r, sigma) for r in pieces], 1e-300))
    mean = logs.mean(axis=0)
    n, c = logs.shape
    dof = max(1, c * (n - 1))
    spread = float(np.sqrt(np.sum((logs - mean) ** 2) / dof))
    scale = max(spread * np.sqrt(1 + 1 / n), 1e-9)
    limit = float(student_t.ppf(1 - LOF_P / (c * max(1, len(w.held_residuals))), dof))
    names = channel_names(reference)
    if null is not None and null is not w and within_form_error(
            [_ms(r, sigma) for r in w.held_residuals],
            [_ms(r, sigma) for r in null.held_residuals], np.exp(mean)):
        return {}
    out = {}
    for r in w.held_residuals:
        z = (np.log(np.maximum(_ms(r, sigma), 1e-300)) - mean) / scale
        for k in np.nonzero((z > limit) & above_floor(_ms(r, sigma), reference))[0]:
            ratio = float(np.exp(0.5 * (np.log(_ms(r, sigma)[k]) - mean[k])))
            if names[k] not in out or z[k] > out[names[k]][1]:
                out[names[k]] = (ratio, float(z[k]))
    return out


def remainder(w: Weighed, reference, dt: float) -> dict:
    """Channels with a systematic residual beyond the noise model (module doc, 4b): channel
    -> (RMS of the slow part in the channel's unit, ratio of its mean square to the noise's
    expectation)."""
    res = w.train_residuals + w.held_residuals
    window = max(3, int(round(NOISE_WINDOW_S / dt)) | 1)
    slow = np.concatenate([slow_part(r, dt) for r in res])
    expected = reference.sigma ** 2 * np.minimum(reference.tau, window) / window
    ratio = np.mean(slow ** 2, axis=0) / expected
    nu = max(1.0, len(slow) / window)
    limit = float(chi2.ppf(1 - LOF_P / len(ratio), nu) / nu)
    names = channel_names(reference)
    rms = np.sqrt(np.mean(slow ** 2, axis=0))
    return {names[k]: (float(rms[k]), float(ratio[k])) for k in range(len(ratio))
            if ratio[k] > limit}


#: parameters that say no difference by themselves: a full voltage has no "off" value (the
#: sag acts for every V_full), a propeller's speed exponent acts only with a thrust change.
_NOT_A_DIFFERENCE = {"battery_sag.full_voltage", "thrust_factor.alpha"}


def differs(ev) -> dict:
    """Per parameter: determined *and* beyond its 95 % interval from the no-difference value
    (the prior's centre): a reading none of whose parameters differs predicts what "no
    difference" predicts within the data's resolution, and is counted there (as
    :func:`quadsim.gap.judge.posterior` counts an undetermined one)."""
    centre = dict(zip(ev.explanation.parameter_names, ev.explanation.mean))
    out = {}
    for q, ok in ev.determined.items():
        far = abs(ev.values[q] - centre.get(q, 0.0)) > 1.96 * ev.post_sd[q]
        out[q] = bool(ok and (far or q in _NOT_A_DIFFERENCE))
    if out and not any(v for q, v in out.items() if q not in _NOT_A_DIFFERENCE) and \
            not any(q == "battery_sag.full_voltage" for q in out):
        out = dict.fromkeys(out, False)
    return out


def rank(weighed: list[Weighed]) -> list[tuple[str, float, Weighed]]:
    """(reading, probability, its best variant), most probable first (module doc, 1)."""
    import dataclasses

    by_ev = {}
    for w in weighed:
        ev = dataclasses.replace(w.total, determined=differs(w.train))
        by_ev[id(ev)] = (w, ev)
    return [(k, p, by_ev[id(ev)][0]) for k, p, ev in posterior([e for _, e in by_ev.values()])]


def pair(lead: Weighed, other: Weighed, partners: int, train, held, reference):
    """The lead fitted together with ``other`` (module doc, 2): a Weighed or None."""
    from .evidence import Explanation, evaluate
    from .fitting import stack_states

    a, b = lead.train.explanation, other.train.explanation
    expl = Explanation(f"{a.name}+{b.name}", " ".join(v for v in (a.variant, b.variant) if v),
                       a.parts + b.parts, a.mean + b.mean, a.sd + b.sd,
                       tuple(dict.fromkeys(a.replaces + b.replaces)), None,
                       a.log_prior + b.log_prior - float(np.log(max(1, partners))))
    ev = evaluate(stack_states([s for s in train]), reference, [expl])[0]
    return check(ev, train, held, reference)


def readings_of(ranked, reference) -> list[dict]:
    """The posterior as JSON rows (the per-flight ``posterior`` shape)."""
    out = []
    for k, p, w in ranked:
        ev = w.train
        out.append({"name": k, "probability": p,
                    "magnitude": _words(reading_text(ev, reference), k == ev.name),
                    "log_evidence": w.total.log_z,
                    "params": {q: ev.values[q] for q, ok in ev.determined.items() if ok},
                    "ci": {q: 1.96 * ev.post_sd[q] for q, ok in ev.determined.items() if ok},
                    "undetermined": [q for q, ok in ev.determined.items() if not ok],
                    "fixed": ev.explanation.fixed_values, "variant": ev.explanation.variant})
    return out


def _words(text: str, own: bool) -> str:
    """Per-flight wording in held-out terms (the reference here is the parameter set)."""
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
            .replace(" (beyond the references')", "")
            .replace(" beyond the references' at their rotor-drag coefficient",
                     " at the fitted rotor-drag coefficient"))


def entry_of(w: Weighed, probability: float, before: list, reference) -> dict:
    """One ranked explanation in the ``effects`` shape (:mod:`.schema` ``_EFFECT``): only
    determined parameters are given values; ``undetermined`` names the others."""
    ev = w.train
    sigma = reference.sigma
    gap_before = float(np.mean(np.concatenate(before) ** 2))
    after = [r / sigma for r in w.held_residuals]
    gap_after = float(np.mean(np.concatenate(after) ** 2))
    det = {q for q, ok in ev.determined.items() if ok}
    off = {q: 0.0 for q in ev.values}
    names = channel_names(reference)
    rms = np.sqrt(np.mean(np.concatenate(w.held_residuals) ** 2, axis=0))
    entry = {"name": ev.name, "probability": probability, "log_evidence": w.total.log_z,
             "params": {q: ev.values[q] for q in ev.values if q in det},
             "ci": {q: 1.96 * ev.post_sd[q] for q in ev.values if q in det},
             "fixed": ev.explanation.fixed_values,
             "identifiable": {q: q in det for q in ev.values},
             "significant": {q: bool(abs(ev.values[q] - off[q]) > 1.96 * ev.post_sd[q])
                             for q in ev.values},
             "undetermined": sorted(set(ev.values) - det),
             "heldout_gap_before": gap_before, "heldout_gap_after": gap_after,
             "reduction": (gap_before - gap_after) / gap_before if gap_before > 0 else 0.0,
             "heldout_rms_after": dict(zip(names, map(float, rms))), "_w": w}
    if entry["undetermined"]:
        entry["warning"] = ("too little excitation to fit " + ", ".join(entry["undetermined"])
                            + " on these flights (posterior spread above half the prior's)")
    return entry


def plausible(entry: dict, params) -> tuple[bool, str]:
    """The prior check of the determined values (:mod:`.priors`)."""
    _, ok, text = candidate_plausibility(entry["params"], params)
    return bool(ok), text


def every_part_stands(entry: dict, params) -> bool:
    """A pair claims that each of its effects is there: every effect of it needs a parameter
    determined and significant (a wind of 0.002 +- 0.1 m/s fitted with rotor drag is rotor
    drag alone), and the determined values must be plausible (:mod:`.priors`): two effects
    cancelling each other at their bounds (every rotor -50 % thrust and the vehicle 50 %
    lighter) explain nothing about the vehicle."""
    keys = entry["identifiable"]
    parts = {q.split(".")[0] for q in keys}
    return all(any(keys[q] and entry["significant"][q] for q in keys if q.split(".")[0] == p)
               for p in parts) and plausible(entry, params)[0]


def consistent(entry: dict, flights, reference) -> dict:
    """The consistency guard on a named entry (:mod:`.consistency`); the propeller's speed
    exponent is held at its value (the library's thrust_factor has none)."""
    ev = entry["_w"].train
    parts, theta = [], []
    for name, fixed, fitted in ev.explanation.parts:
        keep = tuple(p for p in fitted if not (name == "thrust_factor" and p == "alpha"))
        parts.append((name, dict(fixed), keep))
        theta += [ev.values[f"{name}.{p}"] for p in keep]
    cand = Candidate(ev.name, tuple(parts), reference.candidate.base)
    judged = [q for q in entry["params"] if not q.endswith(".alpha")
              and entry["significant"].get(q)]
    return consistency.check(cand, np.asarray(theta, float), judged, flights,
                             reference.params, reference.sigma, reference.rotor)


def separate_by(lead: str, others: list[str]) -> dict:
    return collinear.separation(lead, others)


__all__ += ["pair", "plausible", "every_part_stands", "consistent", "separate_by", "CONFIDENT",
            "READING_P"]


def decide(weighed: list[Weighed], train, held, reference, before: list, max_combination: int,
           tick) -> dict:
    """The ranking, the lead (a pair when it earns it) and its consistency (module doc, 1-3):
    ``{"ranked", "rows", "probability", "entries", "baseline", "combination", "lead",
    "lead_name", "consistency"}`` (``lead``: the Weighed of the most probable reading)."""
    params = reference.params
    dt = float(train[0].t[1] - train[0].t[0])
    # a value outside its documented plausible range has no prior probability (:mod:`.priors`)
    implausible = []
    for w in weighed:
        values = {q: v for q, v in w.train.values.items() if w.train.determined.get(q)}
        _, ok, text = candidate_plausibility(values, params)
        if not ok:
            implausible.append((w, text))
    dropped = {id(w) for w, _ in implausible}
    ranked = rank([w for w in weighed if id(w) not in dropped])
    lead_name, _, lead = ranked[0]
    null = next((w for w in weighed if w.name == "no_difference"), None)
    combination = checked = None
    if lead_name != "no_difference":
        checked = consistent(entry_of(lead, 1.0, before, reference), train + held, reference)
    if lead_name != "no_difference" and max_combination >= 2 and checked["consistent"] \
            and (remainder(lead, reference, dt) or generalisation(lead, reference, null)):
        others = [w for k, _, w in ranked if k not in ("no_difference", lead_name)
                  and w.name == k]
        trials = []
        for other in others:
            trials.append(pair(lead, other, len(others), train, held, reference))
            tick(trials[-1].name)
        best = max(trials, key=lambda w: w.total.log_z, default=None)
        if best is not None:
            stands = every_part_stands(entry_of(best, 0.0, before, reference), params)
            with_pair = rank(weighed + [best])
            if stands and with_pair[0][2] is best:
                ranked, combination = with_pair, best
                lead_name, _, lead = ranked[0]
                checked = consistent(entry_of(lead, 1.0, before, reference), train + held,
                                     reference)
    rows = readings_of(ranked, reference)
    probability = {k: p for k, p, _ in ranked}
    entries = [entry_of(w, p, before, reference) for k, p, w in ranked if k == w.name
               and k != "no_difference"]
    seen = {e["name"] for e in entries}
    entries += [entry_of(w, 0.0, before, reference) for w in weighed
                if w.name not in seen and w.name != "no_difference" and not seen.add(w.name)]
    entries.sort(key=lambda e: (-e["probability"], -e["log_evidence"], e["name"]))
    baseline = next(e for e in entries if e["name"] == "nominal_refit") \
        if any(e["name"] == "nominal_refit" for e in entries) else None
    return {"ranked": ranked, "rows": rows, "probability": probability, "entries": entries,
            "baseline": baseline, "combination": combination, "lead": lead, "null": null,
            "lead_name": lead_name, "consistency": checked,
            "implausible": [(w.name, reading_text(w.train, reference), text)
                            for w, text in implausible]}
