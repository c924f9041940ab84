"""The references judged against each other: the self-check, and what a reading's size is
compared with (practical significance).

Every run judges each reference flight against the other references (leave one out): the
calibrated shared parameters are reused (one flight moves them by about 1/n of its own
difference), while the two things fitted from the flights' residuals -- the discrepancy term
(:meth:`quadsim.gap.discrepancy.Discrepancy.without`) and the lack-of-fit baseline
(``lof_mean``, ``lof_sd``: :func:`quadsim.gap.moderated.moderated_spread`) -- are refitted
without it (:func:`leave_one_out`). What comes out:

- **false alarms**: the references that do not come out ``no_significant_gap``, with their
  verdict and the channels that drive it (the lack-of-fit channels, else the channels the
  reading differs most on from "no difference");
- **the references' own readings**: every explanation's fitted values on each reference
  flight (:class:`Spread`: per parameter, their mean and between-flight standard deviation).

**Practical significance** (:func:`negligible`): a reading on a judged flight is a
difference only when, on at least one of its own determined parameters, its 95 % interval
(1.96 posterior spreads) lies beyond :data:`PRACTICAL_Z` between-flight standard deviations
of the same reading on the references: ``|v - mean_ref| - 1.96 sd_post > 2 sd_ref``. A
reading that does not is what the references themselves show flight to flight (a real
vehicle's rotor that reads -3 % on one reference and +2 % on the next): it counts as "no
difference" (:func:`quadsim.gap.judge.posterior`), as an undetermined reading does. The
nuisance parameters (a signal's delay, a cable's swing at the first sample and its
damping, a propeller's speed exponent) are never a difference on their own.

A set of references that does not judge itself clean -- more than :data:`FALSE_ALARM_SHARE`
of them not ``no_significant_gap`` -- is marked in every answer ("your references disagree
with each other on Mx: ..."), and no verdict on it is stated as confident.

Example::

    >>> check = self_check(ref_flights, reference)
    >>> check.false_alarms, check.clean
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .envelope import envelope_of
from .moderated import moderated_spread

__all__ = [
    "FALSE_ALARM_SHARE",
    "NUISANCE",
    "PRACTICAL_Z",
    "PerFlight",
    "SelfCheck",
    "Spread",
    "against_text",
    "leave_one_out",
    "negligible",
    "self_check_of",
    "spreads",
]

#: a reading's interval must lie beyond this many between-flight standard deviations of the
#: same reading on the references: their 95 % band (two-sided, normal)
PRACTICAL_Z = 2.0
#: the share of references a set may judge as not ``no_significant_gap`` and still be clean:
#: the rate the diagnosis promises on flights that differ in nothing (90 % clear)
FALSE_ALARM_SHARE = 0.1
#: parameter names (their ``.parameter`` part, or the whole name) that are never a
#: difference on their own: the rotor speeds' delay, a cable's swing at the first sample and
#: its damping, a propeller's speed exponent
NUISANCE = ("delay.rotor", "lean_x", "lean_y", "rate_x", "rate_y", "swing_damping", "alpha")


@dataclass(frozen=True)
class PerFlight:
    """Each reference flight's own fit, kept by the calibration
    (:func:`quadsim.gap.calibrate.calibrate`) so that the self-check can leave one out of
    what is built from them: ``coords`` (n, 3) the flights' envelope coordinates
    (:func:`quadsim.gap.envelope.coordinates`), ``values`` and ``se`` (n, M) each flight's
    own shared values and their standard errors (one Gauss-Newton step from theta_ref),
    ``identified`` (M,) bool, ``info`` (n, M) the inverse information per sample (or
    None)."""

    coords: np.ndarray
    values: np.ndarray
    se: np.ndarray
    identified: np.ndarray
    info: np.ndarray | None

    def scatter(self) -> np.ndarray:
        """(M,) method-of-moments between-flight spread of the shared values (their sample
        variance less the mean squared standard error, floored at 0)."""
        if len(self.values) < 2:
            return np.zeros(self.values.shape[1])
        return np.sqrt(np.clip(self.values.var(axis=0, ddof=1)
                               - (self.se ** 2).mean(axis=0), 0, None))

    def envelope(self, log_ms: np.ndarray):
        """The flights' :func:`quadsim.gap.envelope.envelope_of`."""
        return envelope_of(self.coords, self.values, self.se, self.identified, log_ms,
                           self.info)

    def without(self, j: int) -> PerFlight:
        """The same without flight ``j``."""
        return PerFlight(np.delete(self.coords, j, 0), np.delete(self.values, j, 0),
                         np.delete(self.se, j, 0), self.identified,
                         None if self.info is None else np.delete(self.info, j, 0))


@dataclass(frozen=True)
class Spread:
    """One parameter of one reading on the references: ``mean`` and ``sd`` (the
    between-flight standard deviation, ddof 1) of its fitted values over ``count``
    reference flights (the parameter's SI unit)."""

    mean: float
    sd: float
    count: int


@dataclass(frozen=True)
class SelfCheck:
    """The references judged against each other (module doc).

    ``flights``: the reference names; ``verdicts``: each one's verdict (same order);
    ``false_alarms``: (name, verdict, channels) of those not ``no_significant_gap``;
    ``spreads``: (explanation name, variant) -> parameter -> :class:`Spread`."""

    flights: tuple
    verdicts: tuple
    false_alarms: tuple
    spreads: dict

    @property
    def clean(self) -> bool:
        """Whether at most :data:`FALSE_ALARM_SHARE` of the references are false alarms."""
        return len(self.false_alarms) <= FALSE_ALARM_SHARE * len(self.flights)

    def channels(self) -> list[str]:
        """The channels that drive the false alarms, most frequent first."""
        count: dict[str, int] = {}
        for _, _, chans in self.false_alarms:
            for c in chans:
                count[c] = count.get(c, 0) + 1
        return sorted(count, key=lambda c: (-count[c], c))

    def text(self) -> str:
        """The self-check in words (one sentence)."""
        n, k = len(self.flights), len(self.false_alarms)
        if not k:
            return f"Self-check: each of the {n} reference flights judged against the others " \
                   "comes out no_significant_gap."
        which = ", ".join(f"{name} ({verdict})" for name, verdict, _ in self.false_alarms[:4])
        more = f" and {k - 4} more" if k > 4 else ""
        chans = self.channels()
        on = f" on {', '.join(chans[:3])}" if chans else ""
        if self.clean:
            return (f"Self-check: {k} of the {n} reference flights judged against the others "
                    f"is not no_significant_gap: {which}{more}.")
        return (f"Your references disagree with each other{on}: {k} of the {n}, judged "
                f"against the others, are not no_significant_gap ({which}{more}); verdicts "
                "against them are not stated as confident.")

    def to_json(self) -> dict:
        """The self-check as JSON: flights, verdicts, false alarms, clean, and each
        reading's spread on the references."""
        return {"flights": list(self.flights), "verdicts": list(self.verdicts),
                "false_alarms": [{"flight": n, "verdict": v, "channels": list(c)}
                                 for n, v, c in self.false_alarms],
                "clean": self.clean, "channels": self.channels(),
                "spreads": {f"{name}{' (' + variant + ')' if variant else ''}":
                            {p: [s.mean, s.sd, s.count] for p, s in params.items()}
                            for (name, variant), params in self.spreads.items()}}


def leave_one_out(reference, j: int):
    """``reference`` without its ``j``-th flight where it is fitted from the flights'
    residuals (module doc): the discrepancy term, the lack-of-fit baseline, the
    between-flight scatter and the envelope (:class:`PerFlight`); the pooled shared
    parameters reused. ``reference`` itself where it keeps no per-flight data."""
    log_ms = getattr(reference, "log_ms", None)
    if log_ms is None or len(log_ms) < 3:
        return reference
    kept = np.delete(log_ms, j, axis=0)
    spread, dof, pooled = moderated_spread(kept)
    disc = reference.discrepancy
    out = dataclasses.replace(
        reference, discrepancy=None if disc is None else disc.without(j),
        lof_mean=kept.mean(axis=0), lof_sd=spread, lof_dof=dof, lof_pooled=pooled,
        log_ms=kept, names=[n for k, n in enumerate(reference.names) if k != j],
        self_check=None)
    per = getattr(reference, "per_flight", None)
    if per is not None:         # the between-flight scatter and the envelope without it
        per = per.without(j)
        out = dataclasses.replace(out, per_flight=per, scatter=per.scatter(),
                                  envelope=per.envelope(kept))
    return out


def _own(key: str) -> bool:
    """Whether parameter ``key`` (``effect.parameter``) can be a difference on its own."""
    return key not in NUISANCE and key.split(".")[-1] not in NUISANCE


def readings(rows) -> dict:
    """(name, variant) -> parameter -> value of one flight's Evidence ``rows``: the
    explanations' own parameters that flight determines (an undetermined value sits at its
    prior's centre on every flight: no spread of the references' own), of the readings
    fitted to convergence (a screened one keeps its one linear step from the prior's centre,
    :mod:`quadsim.gap.evidence`: not the flight's value), nuisance ones left out."""
    return {(ev.name, ev.explanation.variant): {k: float(v) for k, v in ev.values.items()
                                               if _own(k) and ev.determined.get(k)}
            for ev in rows if ev.name != "no_difference" and not getattr(ev, "screened", False)}


def spreads(per_flight: list[dict]) -> dict:
    """(name, variant) -> parameter -> :class:`Spread` over flights' :func:`readings`
    (at least two flights per parameter)."""
    out: dict = {}
    for key in {k for r in per_flight for k in r}:
        params: dict = {}
        for p in {q for r in per_flight for q in r.get(key, {})}:
            values = np.array([r[key][p] for r in per_flight if p in r.get(key, {})])
            if len(values) >= 2:
                params[p] = Spread(float(values.mean()), float(values.std(ddof=1)),
                                   len(values))
        if params:
            out[key] = params
    return out


def negligible(ev, check: SelfCheck | None) -> bool:
    """Whether reading ``ev`` (an Evidence) is no difference that matters (module doc): none
    of its own determined parameters lies, with its 95 % interval, beyond
    :data:`PRACTICAL_Z` between-flight standard deviations of the same reading on the
    references. False without a self-check or without the reading's spread on the
    references (nothing to compare with: the statistical rule alone)."""
    if check is None or ev.name == "no_difference":
        return False
    spread = check.spreads.get((ev.name, ev.explanation.variant))
    if not spread:
        return False
    compared = False
    for key, ok in ev.determined.items():
        if not ok or not _own(key) or key not in spread:
            continue
        s = spread[key]
        compared = True
        if abs(ev.values[key] - s.mean) - 1.96 * ev.post_sd[key] > PRACTICAL_Z * s.sd:
            return False
    return compared


def against_text(ev, check: SelfCheck | None, unit_of=lambda key: "") -> str:
    """The size of reading ``ev`` against the references' own readings of it, in words
    (module doc): per own determined parameter with a spread on the references, "mass
    +0.0066 kg against the references' +1e-05 ± 3e-05 kg (220 SDs)"; "" where there is
    nothing to compare with. ``unit_of(key)``: the parameter's unit."""
    if check is None:
        return ""
    spread = check.spreads.get((ev.name, ev.explanation.variant), {})
    parts = []
    for key, ok in ev.determined.items():
        if not ok or not _own(key) or key not in spread:
            continue
        s, unit = spread[key], unit_of(key)
        unit = f" {unit}" if unit and unit != "1" else ""
        size = abs(ev.values[key] - s.mean) / s.sd if s.sd > 0 else float("inf")
        parts.append(f"{key.split('.', 1)[1]} {ev.values[key]:+.3g}{unit} against the "
                     f"references' {s.mean:+.2g} ± {s.sd:.2g}{unit} ({size:.3g} SDs)")
    return "; ".join(parts)


def self_check_of(names: list, rows_list: list, judge_fn) -> SelfCheck:
    """The :class:`SelfCheck` of reference flights ``names`` from each one's Evidence rows
    against the leave-one-out reference (``rows_list[j]``: flight j's rows, or None where it
    could not be judged). ``judge_fn(j, check)`` judges flight j with ``check`` (the
    references' readings without flight j) and returns its
    :class:`~quadsim.gap.result.Verdict` (``outcome``, ``name``, ``lack_of_fit``,
    ``differ_on``)."""
    per = [readings(rows) if rows is not None else {} for rows in rows_list]
    verdicts, alarms = [], []
    for j, name in enumerate(names):
        if rows_list[j] is None:
            verdicts.append("refused")
            continue
        others = SelfCheck(tuple(names), (), (), spreads(per[:j] + per[j + 1:]))
        verdict = judge_fn(j, others)
        verdicts.append(verdict.name)
        if verdict.outcome != "no_significant_gap":
            chans = tuple(verdict.lack_of_fit or {}) or tuple(verdict.differ_on or ())
            alarms.append((name, verdict.name, chans))
    return SelfCheck(tuple(names), tuple(verdicts), tuple(alarms), spreads(per))
