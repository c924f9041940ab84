"""Held-out scoring of fitted candidates: the gap, its reduction, the block t test, the
"clear share" test the diagnosis names effects by.

The *gap* of a set of flights is the mean squared residual per sample and channel, each
channel divided by its noise scale (1 = noise level). A candidate's *reduction* is
``(gap_nominal - gap_candidate) / gap_nominal`` on the held-out flights; it explains a
*clear share* when the reduction is at least :data:`MIN_GAIN`, the per-block (1 s) t
statistic of the reduction at least :data:`MIN_T`, and a parameter is identified and
significantly away from "off". Candidates whose held-out gaps lie within :data:`TIE` of the
nominal gap of each other are collinear (the data cannot choose).

Used by :mod:`quadsim.gap.diagnose` (ranking, the verdict) and :mod:`quadsim.gap.combine`
(greedy combinations). Plain functions over lists of (N, C) arrays; no I/O.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ModelError
from ..vehicle.params import VehicleParams
from .fitting import Fit, fit_candidate, residuals
from .residual import CHANNELS

__all__ = ["MIN_GAIN", "MIN_T", "TIE"]

#: an effect must cut the held-out gap by this fraction of the nominal gap ...
MIN_GAIN = 0.05
#: ... with this block-wise t statistic (1 s blocks of held-out data; a consistency check,
#: effects acting only in some regimes, e.g. near the ground, improve few blocks) ...
MIN_T = 1.0
#: ... and effects whose held-out gap is within this fraction of the best are confusable.
TIE = 0.02


def _scaled(flights: list, params, effects, sigma, rotor: bool, *, full=False):
    return [residuals(f.states if full else f.fit, params, effects, rotor_channel=rotor) / sigma
            for f in flights]


def _gap(scaled: list[np.ndarray]) -> float:
    """Mean squared scaled residual per sample and channel (1 = noise level)."""
    return float(np.mean(np.concatenate(scaled) ** 2))


def _block_t(before: list[np.ndarray], after: list[np.ndarray], dt: float) -> float:
    """t statistic of the per-block (1 s) reduction of the squared gap; blocks shrink to
    half the shortest held-out part when that is under 2 s (at least two blocks, e.g. the
    second half of a 4 s flight once its last EDGE_S are dropped)."""
    block = max(1, min(int(round(1.0 / dt)), min(len(b) for b in before) // 2))
    diffs = []
    for b, a in zip(before, after):
        d = np.sum(b ** 2, axis=1) - np.sum(a ** 2, axis=1)
        for k in range(0, len(d) - block + 1, block):
            diffs.append(float(np.mean(d[k:k + block])))
    if len(diffs) < 2:
        return 0.0
    diffs = np.asarray(diffs)
    se = diffs.std(ddof=1) / np.sqrt(len(diffs))
    return float(diffs.mean() / se) if se > 0 else (np.inf if diffs.mean() > 0 else 0.0)


def _channel_rms(scaled: list[np.ndarray], sigma: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.concatenate(scaled) ** 2, axis=0)) * sigma


def _channels(rotor: bool, params: VehicleParams) -> list[str]:
    names = list(CHANNELS)
    if rotor:
        names += [f"rotor_{i + 1}" for i in range(params.rotor_count)]
    return names


def _score(fit: Fit, train, held, params, sigma, rotor, before, dt) -> dict:
    try:
        after = _scaled(held, params, fit.effects(), sigma, rotor)
    except ModelError as exc:  # the fit stopped on a non-physical vehicle: no improvement
        names = fit.candidate.parameter_names
        return {"name": fit.candidate.name, "params": fit.params(), "ci": fit.ci(),
                "fixed": fit.candidate.fixed_values,
                "identifiable": dict.fromkeys(names, False),
                "significant": dict.fromkeys(names, False),
                "heldout_gap_before": _gap(before), "heldout_gap_after": _gap(before),
                "reduction": 0.0, "t_statistic": 0.0, "heldout_rms_after": {},
                "warning": f"fit left the physical range: {exc}", "_fit": fit}
    gap_before, gap_after = _gap(before), _gap(after)
    rms = _channel_rms(after, sigma)
    return {
        "name": fit.candidate.name, "params": fit.params(), "ci": fit.ci(),
        "fixed": fit.candidate.fixed_values,
        "identifiable": dict(zip(fit.candidate.parameter_names, fit.identifiable)),
        "significant": dict(zip(fit.candidate.parameter_names, fit.significant)),
        "heldout_gap_before": gap_before, "heldout_gap_after": gap_after,
        "reduction": (gap_before - gap_after) / gap_before if gap_before > 0 else 0.0,
        "t_statistic": _block_t(before, after, dt),
        "heldout_rms_after": dict(zip(_channels(rotor, params), map(float, rms))),
        "_fit": fit,
    }


def _fit_score(cand, train, held, params, sigma, rotor, before, dt) -> dict:
    return _score(fit_candidate(cand, [f.fit for f in train], params, sigma, rotor_channel=rotor),
                  train, held, params, sigma, rotor, before, dt)


def _clear(entry: dict, reference_gap: float, nominal_gap: float) -> bool:
    gain = (reference_gap - entry["heldout_gap_after"]) / nominal_gap if nominal_gap > 0 else 0
    # At least one parameter must be both identified (CI narrower than half its plausible
    # range) and significantly away from the value that switches the effect off.
    useful = any(entry["identifiable"][k] and entry["significant"][k] for k in entry["params"])
    return gain >= MIN_GAIN and entry["t_statistic"] >= MIN_T and useful
