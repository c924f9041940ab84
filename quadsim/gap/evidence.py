"""Explanations of one flight against the calibrated reference model, weighed by evidence.

An *explanation* says how this flight differs from the reference flights
(:class:`quadsim.gap.calibrate.Reference`): a library effect with free parameters and a prior
(centre, spread, source), or a shared parameter group at a value of its own (a motor lag of
its own instead of the references' 7 ms), or a logged signal's delay of its own.
"No difference" has no free parameter of its own.

Likelihood (all channels, the references' noise model)::

    -2 log L(theta) = sum_c sum_t r_c(t; theta)^2 / (sigma_c^2 tau_c) + const

(r_c the residual of channel c, sigma_c its RMS and tau_c its correlation time on the
reference flights: N / tau_c effective samples, so a long flight with correlated residuals
does not out-vote physics). The shared parameters theta_s are not fixed: every explanation
carries them with the references' prior N(theta_ref, s_ref^2) (s_ref tempered by the
physical prior of a difference, :func:`~quadsim.gap.explanations.marginal_sd`), marginalised
in closed form around theta_ref (linear in theta_s, Jacobian J_s of the weighted residual): with
u = (theta_s - theta_ref) / s_ref, Ĵ = J_s diag(s_ref) and A = I + ĴᵀĴ the profile is
``|r + Ĵ du|^2 + |du|^2`` at ``du = -A^-1 Ĵᵀ r`` and the marginal adds ``-1/2 log det A``.
An explanation that gives a shared group a value of its own takes that group out of the
marginal and fits it with the wider prior N(theta_ref, s_ref^2 + w^2) (w: the prior spread
of a difference, :func:`quadsim.gap.explanations.prior_spreads`). The rotor speeds' logging
delay is shared as well, but not linear at all over a few ms: every explanation fits it, with
the references' spread (:func:`quadsim.gap.explanations.reference_delay_sd`) as its prior;
the reading "signal_delay" fits it with the wide prior N(0, s^2 + (20 ms)^2).

Evidence (Laplace at the bounded least-squares optimum, parameters in units of their prior
spread, z = (theta - mu) / sd)::

    log Z = -1/2 (|aug(z)|^2 + |z|^2) - 1/2 log det H - 1/2 log det A + log pi

with H = JᵀJ of the stacked residual (the posterior precision in z units; -1/2 log det H is
the Occam factor log(posterior volume / prior volume); a value at a bound of its parameter
keeps half the volume, log 2 less) and pi the model prior: equal per
effect, split evenly among an effect's variants (one per rotor for a weak or canted rotor);
"no difference" is weighed against them in :func:`quadsim.gap.judge.posterior`. A parameter
is *determined* by the data when its posterior spread is below half its prior spread
(:data:`quadsim.gap.explanations.DETERMINED`); only determined values are ever printed.

The explanations, their priors and the propeller coupling: :mod:`quadsim.gap.explanations`.

Example::

    >>> rows = evaluate(flight.fit, reference, explanations_for(reference, flight.fit))
    >>> [(e.name, e.log_z) for e in rows]
"""

from __future__ import annotations

from .calibrate import jacobian, shifted
from .explanations import (  # re-exported: the evidence's public names
    DELAY_SD_S,
    DETERMINED,
    Explanation,
    explanations_for,
    marginal_sd,
    reference_determined,
)
from .problem import (  # re-exported: the fit of one explanation
    Evidence,
    FitInputs,
    Problem,
    flight_residual,
    full_fit,
    laplace,
    read_inside,
)
from .reference import Reference
from .screen import delay_starts, screened

__all__ = [
    "DELAY_SD_S",
    "DETERMINED",
    "Evidence",
    "Explanation",
    "FitInputs",
    "Problem",
    "evaluate",
    "explanations_for",
    "flight_residual",
    "full_fit",
    "laplace",
    "marginal_sd",
    "read_inside",
    "reference_determined",
    "shifted",
]


def evaluate(states, reference: Reference, explanations: list[Explanation],
             start_delay_s: float = 0.0, *, full: bool = False,
             memo: dict | None = None) -> list[Evidence]:
    """Log evidence of every explanation on one flight: one :class:`Evidence` per entry of
    ``explanations``, in their order.

    ``states``: the flight's (decimated) fit states aligned to the references' timing
    (:meth:`quadsim.gap.reference.Reference.align`); ``reference``: the reference model;
    ``start_delay_s`` (s): the flight's rotor delay against the references' by
    cross-correlation (0 without one).

    With a rotor-delay reading, every explanation fits the flight's rotor delay too: with
    the references' prior (:func:`~quadsim.gap.explanations.reference_delay_sd`) as a shared
    parameter, or with the wide prior as the reading "signal_delay". Both start at the best
    point of a grid of delays under their prior (:func:`quadsim.gap.screen.delay_starts`;
    ``start_delay_s`` is one of its points).

    Each explanation is first screened by one Gauss-Newton step and fully fitted only where
    it can matter (:func:`quadsim.gap.screen.screened`); ``full=True`` fits every one with
    :func:`quadsim.gap.problem.full_fit`. ``memo``: the residual parts and the shared
    Jacobian kept from an earlier call on the same flight and reference
    (:func:`quadsim.gap.drag_law.choose`)."""
    names = list(reference.candidate.parameter_names)
    s_all = marginal_sd(reference)
    memo = {} if memo is None else memo   # residual parts shared by evaluations on this flight
    kept = memo.get("evidence.jacobian")
    if kept is None or kept[0] is not states or kept[1] is not reference:
        kept = memo["evidence.jacobian"] = (states, reference, jacobian(
            states, reference, list(range(len(names))), reference.candidate.effects, memo=memo))
    inputs = FitInputs(states, reference, kept[2], s_all, memo)
    starts = (0.0, start_delay_s)
    null = next((e for e in explanations if e.name == "no_difference" and e.shift), None)
    wide = next((e for e in explanations if e.name == "signal_delay"), None)
    if null is not None:
        starts = delay_starts(inputs.problem(null),
                              float(wide.sd[-1]) if wide is not None else 0.0, start_delay_s)
    if not full:
        return screened(inputs, explanations, starts)
    return [full_fit(inputs, e, starts[1] if e.name == "signal_delay" else starts[0])
            for e in explanations]

