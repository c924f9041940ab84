"""The residual of one judged flight over time, before and after its answer: the arrays the
report's plots (:mod:`quadsim.gap.plots`) and the rerun recording draw.

*Before* is the flight's residual (N, C) under the reference model as calibrated (theta_ref,
the references' rotor timing, less the centre of what the references share beyond the
library, :mod:`quadsim.gap.discrepancy`). *After* is its residual as the judgment weighed the most
probable reading: the reading's own effects at their fitted values (its rotor delay where it
fits one), the shared groups it does not replace at theta_ref, plus the linear step of the
shared parameters and of the discrepancy term its evidence profiles within the references'
spread (:class:`quadsim.gap.problem.Marginal`): the residual whose per-channel mean square is the
reading's ``ms``, which the lack-of-fit test reads. Channels: Fx Fy Fz (N), Mx My Mz (N m),
then rotor_1..R (rad/s) where the reference has rotor channels
(:func:`quadsim.gap.problem.flight_residual`).

How much of the gap an answer removes: :meth:`quadsim.gap.result.Series.share`.
"""

from __future__ import annotations

import numpy as np

from .explanations import marginal_sd
from .judge import channel_names, posterior
from .problem import FitInputs, flight_residual
from .reference import Reference, jacobian
from .result import Series

__all__ = ["flight_series"]


def flight_series(states, reference: Reference, rows, *, name: str,
                  memo: dict | None = None) -> Series:
    """The :class:`~quadsim.gap.result.Series` of one judged flight (module doc).

    ``states``: the flight's fit states aligned to the references' timing
    (:meth:`~quadsim.gap.reference.Reference.align`); ``reference``: the reference model it
    was judged against (at the flight's place); ``rows``: every explanation's
    :class:`~quadsim.gap.problem.Evidence` (the lead is taken by
    :func:`quadsim.gap.judge.posterior`); ``name``: the flight's file; ``memo``: the residual
    parts and Jacobian the evidence kept for this flight (:func:`quadsim.gap.evidence.
    evaluate`), None to compute them."""
    lead = posterior(rows)[0][2]
    expl = lead.explanation
    chans = len(reference.sigma)
    before = (flight_residual(states, reference, reference.effects(), memo).reshape(-1, chans)
              / np.sqrt(reference.weights))
    prob = FitInputs(states, reference, _jacobian(states, reference, memo),
                     marginal_sd(reference), memo).problem(expl)
    theta = np.array([lead.values[k] for k in expl.parameter_names], float)
    z = (theta - prob.mean) / prob.sd
    weighted, _ = prob.marg.profile(prob.residual(z))
    after = (weighted[:len(states.t) * chans].reshape(-1, chans)
             * np.sqrt(reference.tau) * reference.sigma)
    return Series(np.asarray(states.t, float), before, after, tuple(channel_names(reference)),
                  name, states, reference.params, tuple(prob.shared),
                  np.asarray(reference.sigma, float))


def _jacobian(states, reference: Reference, memo: dict | None) -> np.ndarray:
    """The weighted residual's Jacobian in the shared parameters: the one
    :func:`quadsim.gap.evidence.evaluate` kept in ``memo`` for these states and reference,
    else computed (:func:`quadsim.gap.reference.jacobian`)."""
    kept = (memo or {}).get("evidence.jacobian")
    if kept is not None and kept[0] is states and kept[1] is reference:
        return kept[2]
    names = reference.candidate.parameter_names
    return jacobian(states, reference, list(range(len(names))), reference.candidate.effects,
                    memo=memo)
