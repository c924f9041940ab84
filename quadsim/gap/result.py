"""The result types of the gap diagnosis: :class:`Reading`, :class:`Verdict`, :class:`Diagnosis`.

Both modes return a :class:`Diagnosis` (``mode`` ``"per-flight"`` or ``"held-out"``): per
flight it holds one :class:`Verdict` per flight (``flights``), held out one :class:`Verdict`
for the held-out flights (``verdict``). A verdict's ``outcome`` is one of :data:`OUTCOMES`:
``effect`` (its ``name`` is the reading, e.g. ``"mass_offset"``), ``no_significant_gap``,
``unexplained`` or ``refused`` (a flight that could not be judged, with its ``reason``).

``to_json()`` gives the ``quadsim.gap/3`` JSON object (:data:`quadsim.gap.GAP_SCHEMA`): plain
dicts, lists, str, float, bool and None, the same keys as before these types existed. The
types are also read-only mappings over that JSON (``result["verdict"]["effect"]``,
``flight["probability"]``), so code written against the dict results keeps working. Arrays
for plots and recordings (:class:`Series`) are a named field that ``to_json`` leaves out by
design: they are not part of the result file.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

__all__ = ["OUTCOMES", "Diagnosis", "GapShare", "Reading", "Series", "Verdict", "plain"]

#: a verdict's outcomes (``refused``: per flight only).
OUTCOMES = ("effect", "no_significant_gap", "unexplained", "refused")


def plain(value):
    """``value`` with numpy scalars as Python numbers, tuples as lists, non-finite floats as
    None (JSON has no NaN), recursively through dicts and lists."""
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


class _JsonView(Mapping):
    """Read-only mapping access to ``to_json()`` (computed once)."""

    @cached_property
    def _json(self) -> dict:
        return self.to_json()

    def __getitem__(self, key):
        return self._json[key]

    def __iter__(self):
        return iter(self._json)

    def __len__(self) -> int:
        return len(self._json)

    __hash__ = None   # mutable JSON inside: not a dict key


@dataclass(frozen=True, eq=False)
class Reading(_JsonView):
    """One reading of the posterior: ``name`` (an effect, a pair ``a+b``, or
    ``no_difference``), its posterior ``probability``, its ``magnitude`` in words (determined
    values only), ``log_evidence`` (natural log), the determined ``params`` with their 95 %
    half-interval ``ci`` (parameter units, :func:`quadsim.gap.fitting.unit_of`), the
    ``undetermined`` parameter names, the ``fixed`` values and the explanation's ``variant``."""

    name: str
    probability: float
    magnitude: str
    log_evidence: float
    params: Mapping = field(default_factory=dict)
    ci: Mapping = field(default_factory=dict)
    undetermined: tuple = ()
    fixed: Mapping = field(default_factory=dict)
    variant: str = ""
    #: the added mass in all with its 95 % half-interval ({"mass", "ci"}, kg) where the
    #: reading has two or more mass parts (:func:`quadsim.gap.words.total_mass`); {} else
    total: Mapping = field(default_factory=dict)
    #: the bias bound (standard errors) its ``ci`` include beyond the references' reach
    #: (:func:`quadsim.gap.judge.reach_bias`); 0 within it
    bias: float = 0.0
    #: its weighed masses' 95 % half-intervals on another session's air ({"thrust_spread",
    #: "ci", "total_ci"}: :func:`quadsim.gap.words.across_sessions`; JSON
    #: ``across_sessions``); {} without one. ``ci`` and ``total`` stay the within-session
    #: ones (flights of the references' session compare at them)
    across: Mapping = field(default_factory=dict)
    #: the log units where the prior centres its values takes from ``log_evidence``
    #: (:attr:`quadsim.gap.evidence.Evidence.prior_pull`; 0 where not measured); not in
    #: the JSON
    prior_pull: float = 0.0

    def to_json(self) -> dict:
        out = {"name": self.name, "probability": self.probability,
               "magnitude": self.magnitude, "log_evidence": self.log_evidence,
               "params": dict(self.params), "ci": dict(self.ci),
               "undetermined": list(self.undetermined), "fixed": dict(self.fixed),
               "variant": self.variant}
        if self.total:
            out["total"] = dict(self.total)
        if self.bias > 0:
            out["bias_se"] = self.bias
        if self.across:
            out["across_sessions"] = dict(self.across)
        return plain(out)


#: JSON keys of a held-out verdict beyond the common ones (the field of the same name).
_HELDOUT_KEYS = ("floor_source", "channels", "alternatives", "best_candidate",
                 "heldout_channel_gap_after", "reduction", "heldout_gap_before",
                 "heldout_gap_after", "probability_within_library", "outside_library")
#: JSON keys of a judged flight beyond the common ones.
_FLIGHT_KEYS = ("differ_on", "symptom", "drag_law", "signal_delays_ms", "form_remainder",
                "self_check_clean", "probability_within_library", "outside_library")


@dataclass(frozen=True, eq=False, repr=False)
class Verdict(_JsonView):
    """The judgment of one flight (``file`` set) or of the held-out flights (``file`` None).

    Common: ``outcome`` (:data:`OUTCOMES`); ``name``: the reading named when ``outcome`` is
    ``effect``, else the outcome (JSON key ``verdict`` per flight, ``effect`` held out);
    ``answer`` in words (:mod:`quadsim.gap.words`); ``probability`` of the lead reading
    (None when refused; an ``unexplained`` name that more probably stands in for an effect
    outside the library: that hypothesis's, ``outside_library``);
    ``tentative``; ``probability_within_library``, ``outside_library``; ``posterior``
    (every :class:`Reading`, most probable first); ``readings``
    (names stated with the named one, probability >= READING_P);
    ``lack_of_fit`` (channel -> RMS over the baseline's typical RMS, channels beyond it
    only); the named reading's ``params``/``ci``/``fixed``/``units``; ``confusable_with``
    and ``separate_by``; ``notes``; ``consistency``/``partial`` (:mod:`.consistency`, held
    out, when a name was checked).

    Per flight: ``reason`` (refused), ``differ_on``, ``symptom``, ``drag_law``, ``envelope``,
    ``signal_delays_ms``, ``form_remainder``, ``self_check_clean``; JSON ``residual`` (with
    a ``series``): the RMS per channel before and after the answer over the references'
    RMS, the share of the excess removed and its words (:class:`GapShare`,
    :func:`quadsim.gap.words.residual_text`). Held out: ``floor_source``, ``channels`` (RMS
    before/after/floor per channel, units), ``alternatives``, ``best_candidate``,
    ``reduction`` and the gaps (mean squared residual over sigma^2, 1 = noise).
    ``series``: per flight, the residual before and after the answer
    (:func:`quadsim.gap.page.flight_series`), not in the JSON."""

    outcome: str
    name: str
    answer: str
    probability: float | None = None
    tentative: bool = False
    posterior: tuple = ()
    readings: tuple = ()
    lack_of_fit: Mapping = field(default_factory=dict)
    params: Mapping = field(default_factory=dict)
    ci: Mapping = field(default_factory=dict)
    fixed: Mapping = field(default_factory=dict)
    units: Mapping = field(default_factory=dict)
    #: the named reading's added mass in all ({"mass", "ci"}, kg; :attr:`Reading.total`)
    total: Mapping = field(default_factory=dict)
    #: the named reading's weighed masses on another session's air (:attr:`Reading.across`)
    across: Mapping = field(default_factory=dict)
    confusable_with: tuple = ()
    separate_by: Mapping = field(default_factory=dict)
    notes: tuple = ()
    consistency: Mapping | None = None
    partial: Mapping | None = None
    # per flight
    file: str | None = None
    reason: str | None = None
    differ_on: tuple = ()
    symptom: Mapping = field(default_factory=dict)
    drag_law: str | None = None
    envelope: Mapping | None = None
    signal_delays_ms: Mapping = field(default_factory=dict)
    # held out
    floor_source: str = ""
    channels: Mapping = field(default_factory=dict)
    alternatives: tuple = ()
    best_candidate: str | None = None
    heldout_channel_gap_after: Mapping = field(default_factory=dict)
    reduction: float | None = None
    heldout_gap_before: float | None = None
    heldout_gap_after: float | None = None
    #: per flight: what a tentatively named reading leaves (channel -> RMS over the
    #: references' typical RMS; :data:`quadsim.gap.judge.FORM_ERROR_TENTATIVE`)
    form_remainder: Mapping = field(default_factory=dict)
    #: per flight: whether the references judge themselves clean
    #: (:class:`quadsim.gap.calibrate.SelfCheck`); None without a self-check
    self_check_clean: bool | None = None
    #: the lead reading's probability among the library's readings only (their
    #: posterior sums to 1; before the "outside the library" hypothesis); ``probability`` is
    #: the name's: this less ``outside_library`` (a stand-in's: ``outside_library``)
    probability_within_library: float | None = None
    #: P(the name stands in for an effect outside the library) beside a name that leaves
    #: something beyond the references' (:func:`quadsim.gap.judge.with_outside`; held out
    #: against references only); 0 else
    outside_library: float = 0.0
    #: the lead reading's quasi-likelihood dispersion (:func:`quadsim.gap.judge.
    #: overdispersion`; 1 where the flight's residual after it lies within the references'):
    #: the factor by which its log-evidence margins exceed what the data carry; the scale on
    #: which a declared confusable pair counts as told apart
    #: (:func:`quadsim.gap.logcheck.confusable_note`); not in the JSON
    dispersion: float = 1.0
    #: per flight: the residual before and after the answer (:mod:`.page`; not in the JSON)
    series: Series | None = None

    def __repr__(self) -> str:
        where = f"{self.file!r}, " if self.file is not None else ""
        return f"Verdict({where}{self.outcome!r}, {self.name!r}, p={self.probability})"

    def to_json(self) -> dict:
        out = {"outcome": self.outcome, "answer": self.answer,
               "probability": self.probability, "readings": list(self.readings),
               "posterior": [r.to_json() if isinstance(r, Reading) else r
                             for r in self.posterior],
               "notes": list(self.notes)}
        if self.file is not None:
            out.update(file=self.file, verdict=self.name)
            if self.outcome == "refused":
                out["reason"] = self.reason
                return plain(out)
        else:
            out["effect"] = self.name
            del out["notes"]            # held out: the notes are the result's
        out.update(tentative=self.tentative, lack_of_fit=dict(self.lack_of_fit),
                   params=dict(self.params), ci=dict(self.ci), fixed=dict(self.fixed),
                   **({"total": dict(self.total)} if self.total else {}),
                   **({"across_sessions": dict(self.across)} if self.across else {}),
                   units=dict(self.units), confusable_with=list(self.confusable_with),
                   separate_by=dict(self.separate_by))
        for key in ("consistency", "partial"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        keys = _FLIGHT_KEYS if self.file is not None else _HELDOUT_KEYS
        out.update({k: getattr(self, k) for k in keys})
        if self.file is not None and self.envelope is not None:
            out["envelope"] = self.envelope
        if self.file is not None and self.series is not None and self.series.sigma is not None:
            from .words import residual_text

            share = self.series.share()
            out["residual"] = dict(share.to_json(), text=residual_text(share, self.outcome))
        return plain(out)


@dataclass(frozen=True, eq=False, repr=False)
class Series:
    """Arrays for plots and recordings (not in the JSON): held out over each held-out
    flight (``Diagnosis.held_series``; ``Diagnosis.series`` the first), per flight over each
    judged flight (:func:`quadsim.gap.page.flight_series`).
    ``t`` (N,) s; ``before``/``after`` (N, C) residuals in channel units (N, N m, rad/s)
    under the reference (held out: nominal) model and with the answer; ``channels`` (C
    names); ``flight`` its name; ``states`` (:class:`quadsim.gap.residual.FlightStates`),
    ``params`` and ``effects`` (the model with the answer); ``sigma`` (C,) the references'
    residual RMS per channel at this flight (channel units; None held out)."""

    t: np.ndarray
    before: np.ndarray
    after: np.ndarray
    channels: tuple
    flight: str
    states: object
    params: object
    effects: tuple = ()
    sigma: np.ndarray | None = None

    def share(self, sigma=None) -> GapShare:
        """:class:`GapShare` against ``sigma`` (C,; default ``self.sigma``)."""
        sigma = np.asarray(self.sigma if sigma is None else sigma, float)
        before = np.mean(self.before ** 2, axis=0) / sigma ** 2
        after = np.mean(self.after ** 2, axis=0) / sigma ** 2
        excess = float(np.sum(np.maximum(before - 1.0, 0.0)))
        left = float(np.sum(np.maximum(after - 1.0, 0.0)))
        return GapShare(tuple(self.channels), np.sqrt(before), np.sqrt(after),
                        None if excess <= 0 else 1.0 - left / excess)


@dataclass(frozen=True, eq=False)
class GapShare:
    """A flight's residual against the references' level: ``before`` and ``after`` (C,) the
    RMS per channel over the references' RMS sigma_c (1 = a reference flight's level),
    ``removed`` the share of the excess mean square the answer removes, 1 - sum_c
    max(0, after_c^2 - 1) / sum_c max(0, before_c^2 - 1) (None: no excess before)."""

    channels: tuple
    before: np.ndarray
    after: np.ndarray
    removed: float | None

    def to_json(self) -> dict:
        return plain({"rms_before": dict(zip(self.channels, map(float, self.before))),
                      "rms_after": dict(zip(self.channels, map(float, self.after))),
                      "removed": self.removed})


@dataclass(frozen=True, eq=False, repr=False)
class Diagnosis(_JsonView):
    """The whole result of :func:`quadsim.gap.diagnose` (``mode`` ``"held-out"``) or
    :func:`quadsim.gap.diagnose_per_flight` (``"per-flight"``).

    ``schema`` (``quadsim.gap/3``), ``model`` (parameter-set name), ``verdict`` (held out:
    the :class:`Verdict` of the held-out flights; per flight None, the JSON's ``verdict`` is
    the batch answer ``answer``), ``flights`` (per flight: one :class:`Verdict` each, in
    input order), ``train``/``holdout``/``reference`` (flight names), ``reference_model``
    and ``reference_refit`` (per flight: the calibrated reference as JSON), ``noise_model``,
    ``where`` (:mod:`.judge`), ``effects``/``baseline``/``combination`` (held out: every
    ranked explanation as JSON), ``checks`` (:func:`quadsim.gap.logcheck.vehicle_check`),
    ``base_effects`` (the effects already in the model, either mode) and ``effects_file``
    (the file they came from, as given to the CLI; None: none), ``notes``,
    ``reference_file`` (the stored reference judged against, :mod:`quadsim.gap.reffile`;
    None: none); ``series`` (not in the JSON)."""

    schema: str
    model: str
    mode: str
    verdict: Verdict | None = None
    flights: tuple = ()
    answer: str = ""
    train: tuple = ()
    holdout: tuple = ()
    reference: tuple = ()
    reference_model: Mapping | None = None
    reference_refit: Mapping | None = None
    noise_model: Mapping | None = None
    where: Mapping = field(default_factory=dict)
    effects: tuple = ()
    baseline: Mapping | None = None
    combination: Mapping | None = None
    checks: Mapping = field(default_factory=dict)
    base_effects: tuple = ()
    effects_file: str | None = None
    notes: tuple = ()
    #: the stored reference judged against (:func:`quadsim.gap.reffile.describe`), or None
    reference_file: Mapping | None = None
    series: Series | None = None
    #: held out: every held-out flight's :class:`Series`, in order (``series`` is the first)
    held_series: tuple = ()

    def __repr__(self) -> str:
        judged = self.verdict if self.verdict is not None else f"{len(self.flights)} flights"
        return f"Diagnosis({self.mode!r}, {self.model!r}, {judged!r})"

    def to_json(self) -> dict:
        out = {"schema": self.schema, "model": self.model, "where": dict(self.where),
               "effects": list(self.effects), "checks": self.checks,
               "notes": list(self.notes)}
        if self.base_effects:
            out["base_effects"] = list(self.base_effects)
        if self.effects_file is not None:
            out["effects_file"] = self.effects_file
        if self.reference_file is not None:
            out["reference_file"] = dict(self.reference_file)
        if self.mode == "per-flight":
            flights = [f.to_json() for f in self.flights]
            out.update(mode="per-flight", reference=list(self.reference),
                       reference_model=self.reference_model,
                       reference_refit=self.reference_refit, flights=flights,
                       verdict={"outcome": "effect" if any(f.outcome == "effect"
                                                           for f in self.flights)
                                else "unexplained", "effect": "see flights",
                                "answer": self.answer, "reduction": None,
                                "confusable_with": []})
            return plain(out)
        out.update(train=list(self.train), holdout=list(self.holdout),
                   baseline=self.baseline or {}, verdict=self.verdict.to_json(),
                   noise_model=self.noise_model)
        if self.reference:      # held out against nominal references: as per flight
            out.update(reference=list(self.reference), reference_model=self.reference_model)
            if not self.baseline:       # no refit of the bare set's b and d: none to state
                del out["baseline"]
        if self.combination is not None:
            out["combination"] = self.combination
        return plain(out)
