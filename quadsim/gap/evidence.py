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

The screen
----------
Linearised evidence of every explanation, and the cut that decides which ones are fitted
to convergence (:func:`quadsim.gap.evidence.evaluate`; docs/gap.md, Speed).

The full fit of an explanation (:func:`quadsim.gap.problem.full_fit`: bounded trust-region
least squares, a finite-difference Jacobian per iteration) costs 40-80 evaluations of the
flight's residual; a flight has ~20 explanations, and most of them lie hundreds of log units
of evidence below the best. So:

1. **The flight's rotor delay under the reference model** ("no difference") is fitted first
   (:func:`refined`); every other explanation carries that delay with the same prior and
   starts there (z0: its own parameters at their prior centre, theta_ref for a replaced
   shared group; a "signal_delay" reading at its cross-correlation estimate). A delay beyond
   :data:`DELAY_GRID_SDS` prior spreads absorbs a gap rather than timing the log: the others
   then start at the grid's best within that reach (:func:`delay_starts`).
2. **Screen**: one Gauss-Newton step from z0, ``r(z) ~ r(z0) + J (z - z0)``. J's columns
   (prior units): for a shared group the explanation gives a value of its own, the
   shared-parameter Jacobian the marginal needs anyway (:func:`quadsim.gap.reference.jacobian`,
   once per flight); the delay's column once per flight (:class:`Columns`); every other
   parameter one forward difference (:data:`STEP`, the full fit's ``diff_step``). The rotor
   speeds are shifted by interpolation between samples, so the residual is piecewise linear
   in the delay with a kink at every sample: the delay's column is one-sided and is taken
   again on the other side when the step goes there. The stacked cost (profiled residual,
   marginalised shifts, z) is then quadratic; its bounded minimum z1 is a small linear
   least-squares problem (:func:`linear_step`). The residual is evaluated at z1 itself: the
   *screened* evidence is the Laplace evidence (:func:`quadsim.gap.problem.laplace`) at z1
   with the Gauss-Newton precision AᵀA, and ``miss`` = |cost(z1) - predicted cost| says how
   far the linear model was off there.
3. **Cut**: an explanation whose *reach*, screened log Z + miss / 2, lies within
   :data:`SCREEN_CUT` of the best log weight so far (log Z; "no difference" with its prior,
   as in :func:`quadsim.gap.judge.posterior`) is fitted to convergence (:func:`refined`:
   projected Gauss-Newton from z1, a fresh Jacobian per step, halved steps until the cost
   falls, stopped at a cost drop below :data:`CONVERGED`), most promising first, each result
   raising the best. The others keep their screened Evidence (``screened=True``).

Why the cut does not move a verdict: a screened reading lies more than SCREEN_CUT = log(1e4)
+ 4 below the best, i.e. at posterior odds below 1e-4 against it by its screened evidence;
the judge's thresholds are posterior 0.1 (a stated reading) and 0.9 (confident). The screened
cost is that of a point the fit can reach, so a fit only lowers it, by about miss / 2 where
the linear model was off; a second local optimum the step does not see is the remaining risk
(docs/gap.md, Speed: the comparison with ``full=True``).

An explanation with a parameter that acts only through another's value (``coupled``: a
propeller's speed exponent, no effect at zero change; a wind refitted through a drag the
references lack) has a zero column at the start, so its step cannot see what it reaches: it
is fitted after the others, always, or, when it names the readings it extends or mimics
(``kin``: a payload off the centre, a centred mass, a CoM shift or a thrust curve; a
propeller change, a mass or a thrust curve), when one of them lies within the cut of the
best weight before any coupled fit (:func:`_kin_matters`), or when a second linear step from
its first reaches within the cut (:func:`_second_reach`); from the step and, where the step
raised the cost, from the prior centre too (:func:`_refined_coupled`).

The explanations that matter are fitted to convergence, not with the full fit's
40-evaluation cap, so their evidence can exceed the full path's (by up to a few log units
where that fit stopped early); at a bound, the two Jacobians' columns of the bounded value
can differ and with them the Occam factor. ``evaluate(..., full=True)`` fits every
explanation with the full fit (the reference path tests/test_screen.py compares with).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.optimize import lsq_linear

from ..core.errors import ModelError
from .calibrate import jacobian, shifted
from .explanations import (  # re-exported: the evidence's public names
    DELAY_SD_S,
    DETERMINED,
    Explanation,
    explanations_for,
    marginal_sd,
    reference_determined,
)
from .fitmodels import build_effect
from .problem import (  # re-exported: the fit of one explanation
    Evidence,
    FitInputs,
    Problem,
    flight_residual,
    full_fit,
    laplace,
    read_inside,
    shifted_view,
)
from .reference import Reference

__all__ = [
    "CONVERGED",
    "DELAY_GRID_S",
    "DELAY_GRID_SDS",
    "DELAY_SD_S",
    "DETERMINED",
    "MAX_STEPS",
    "SCREEN_CUT",
    "STEP",
    "Columns",
    "Evidence",
    "Explanation",
    "FitInputs",
    "Problem",
    "centred_is_base",
    "delay_starts",
    "evaluate",
    "explanations_for",
    "flight_residual",
    "full_fit",
    "jacobian_columns",
    "laplace",
    "linear_step",
    "linearised",
    "marginal_sd",
    "read_inside",
    "reference_determined",
    "refined",
    "screened",
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
    point of a grid of delays under their prior (:func:`delay_starts`;
    ``start_delay_s`` is one of its points).

    Each explanation is first screened by one Gauss-Newton step and fully fitted only where
    it can matter (:func:`screened`); ``full=True`` fits every one with
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


# --- the screen (module doc) --------------------------------------------------------------------

#: forward-difference step in prior units (the full fit's ``diff_step``).
STEP = 1e-3
#: log-weight margin below the best within which an explanation is fitted to convergence
#: (module doc): posterior odds 1e-4, plus 4 for the Occam factor's change from z1 to the
#: optimum and the step's own error (a few log units at most; CHANGELOG).
SCREEN_CUT = float(np.log(1e4)) + 4.0
#: Gauss-Newton steps of a refined fit at most, and the cost drop (cost units) below which
#: it has converged (a hundredth of a log-evidence unit: far below any posterior threshold).
MAX_STEPS = 8
CONVERGED = 0.02


#: spacing (s) of the rotor-delay grid the fits start from (:func:`delay_starts`): below half
#: the spacing of the timing likelihood's local optima (a few ms on logs with motor noise),
#: so each optimum's basin holds a grid point; the fit then converges within it.
DELAY_GRID_S = 0.003
#: the grid reaches this many of the shared delay's prior spreads either side of zero and of
#: the cross-correlation estimate (99.7 % of the prior's mass)
DELAY_GRID_SDS = 3.0


def delay_starts(null, signal_sd: float, hint_s: float = 0.0) -> tuple[float, float]:
    """Where the rotor delay's fits start (s): (every explanation's shared delay, the
    "signal_delay" reading's), each the best point of a grid (:data:`DELAY_GRID_S`) under its
    prior (the shared delay's, the wide ``signal_sd``, s). ``null``: the "no difference"
    :class:`~quadsim.gap.problem.Problem` (its delay under the references' tight prior);
    ``hint_s``: the flight's cross-correlation estimate against the references' (s). The
    shared start is the best of the grid within :data:`DELAY_GRID_SDS` shared spreads about
    zero and about ``hint_s`` (where the shared delay may lie, and where a delay of the
    flight's own shows in the cross-correlation); the reading's own start the best within as
    many of its own wide spreads (a log the cross-correlation cannot time may be late by
    more than the shared reach). The grid is clipped to the delay's bounds.

    Why a grid: the likelihood of a timing offset is not unimodal. A residual with a
    periodic part (motor noise, the figure-8) matches itself again one period later, so a
    local fit from zero can stop at the wrong optimum, and a wide-prior fit started elsewhere
    then "finds" a delay of its own. The profiled cost |aug|^2 + |du|^2 is the same for both
    priors at one delay: one residual per grid point."""
    sd, lo, hi = float(null.sd[-1]), float(null.lower[-1]), float(null.upper[-1])
    reach = DELAY_GRID_SDS * sd
    steps = np.arange(-reach, reach + 0.5 * DELAY_GRID_S, DELAY_GRID_S)
    wide = DELAY_GRID_SDS * max(sd, signal_sd)      # the reading's own start: its prior's reach
    own_steps = np.arange(-wide, wide + 0.5 * DELAY_GRID_S, DELAY_GRID_S)
    about_hint = hint_s + steps if abs(hint_s) > reach else []    # else inside already
    grid = np.unique(np.clip(np.concatenate([own_steps, about_hint, [0.0, hint_s]]),
                             lo + 1e-9, hi - 1e-9))
    cost = np.empty(len(grid))
    for k, d in enumerate(grid):
        z = np.array([d / sd])
        vec = null.stacked(z)
        cost[k] = float(vec @ vec) - float(z @ z)     # the profiled cost, prior term apart
    near = (np.abs(grid) <= reach + 1e-12) | (np.abs(grid - hint_s) <= reach + 1e-12)
    shared = float(grid[near][np.argmin((cost + (grid / sd) ** 2)[near])])
    own = float(grid[np.argmin(cost + (grid / signal_sd) ** 2)]) if signal_sd > 0 else hint_s
    return shared, own


class Columns:
    """Per-flight pieces every explanation's linear model shares (module doc, 2.): the
    reference residual (N C,) at theta_ref with the rotor speeds read a delay later
    (:meth:`base`), the rotor delay's column there (:meth:`delay`), and the shared Jacobian
    ``jac`` (N C, M) with ``index`` (shared parameter name -> column).

    ``inputs``: the flight's :class:`~quadsim.gap.problem.FitInputs` (its memo keeps the
    shifted states); ``null``: the "no difference" explanation, whose fixed-only parts and
    replaced groups make the shared base model (the reference model, or it under a flight's
    drag law, :mod:`quadsim.gap.drag_law`); None: the reference model. ``delay_s``: the delay
    (s) every explanation starts at (:func:`screened` sets it)."""

    def __init__(self, inputs: FitInputs, null: Explanation | None = None):
        reference = inputs.reference
        self.states, self.reference, self.jac, self.memo = (inputs.states, reference,
                                                            inputs.jac, inputs.memo)
        self.index = {n: k for k, n in enumerate(inputs.names_all)}
        self._base: dict[float, np.ndarray] = {}
        self._delay: dict[tuple, np.ndarray] = {}
        self.delay_s = 0.0          # the delay every explanation starts at (:func:`screened`)
        # the model every explanation shares at its prior's centre: the reference model, or
        # -- under a flight's drag law (.drag_law) -- the "no difference" that carries it
        # (its fixed-only parts, the groups it replaces, and its effects)
        self.fixed = tuple(p for p in getattr(null, "parts", ()) if not p[2])
        self.replaced = tuple(getattr(null, "replaces", ())) if self.fixed else ()
        self.effects = reference.effects()
        if self.fixed:      # as problem._shared_effects: the base's effects always stay
            n_base = len(reference.candidate.base)
            self.effects = (self.effects[:n_base]
                            + [e for e in self.effects[n_base:] if e.name not in self.replaced]
                            + _fixed_effects(self.fixed))

    def _residual_at(self, delay_s: float) -> np.ndarray:
        return flight_residual(shifted_view(self.states, delay_s, self.memo), self.reference,
                               self.effects, self.memo)

    def base(self, delay_s: float) -> np.ndarray:
        """The shared base model's weighted residual (N C,) with the rotor speeds read
        ``delay_s`` (s) later."""
        if delay_s not in self._base:
            self._base[delay_s] = self._residual_at(delay_s)
        return self._base[delay_s]

    def delay(self, delay_s: float, sd: float, sign: float) -> np.ndarray:
        """d r / d z (N C,) of the rotor delay at ``delay_s`` (prior spread ``sd``, s),
        one-sided towards ``sign`` (module doc, 2.: a kink at every sample)."""
        key = (delay_s, sd, sign)
        if key not in self._delay:
            h = sign * STEP
            moved = self._residual_at(delay_s + h * sd)
            self._delay[key] = (moved - self.base(delay_s)) / h
        return self._delay[key]


def centred_is_base(expl: Explanation, cols: Columns) -> bool:
    """Whether ``expl`` at its prior's centre is the shared base model of ``cols`` (the
    reference model, or it under the flight's drag law): its fixed-only parts are the
    base's, and each group it replaces is one it fits or the base replaces. Not so for a
    wind through the references' drag taken as quadratic (the rotor drag replaced by a body
    drag it fits): its centre's residual is its own, not the base's."""
    fits = {name for name, _, fitted in expl.parts if fitted}
    fixed = tuple(p for p in expl.parts if not p[2])
    return fixed == cols.fixed and set(expl.replaces) <= fits | set(cols.replaced)


def _fixed_effects(parts) -> list:
    return [build_effect(name, dict(fixed)) for name, fixed, _ in parts]


def _shared_point(prob: Problem, cols: Columns, z: np.ndarray) -> float | None:
    """The delay (s) at ``z`` when ``z`` is the reference model there (no own value moved
    and the delay one the per-flight pieces hold), else None."""
    own = len(z) - (1 if prob.expl.shift else 0)
    if np.any(z[:own]) or prob.expl.name == "signal_delay" or not centred_is_base(
            prob.expl, cols):
        return None
    if not prob.expl.shift:
        return 0.0
    delay = float(prob.mean[-1] + prob.sd[-1] * z[-1])
    return cols.delay_s if abs(delay - cols.delay_s) <= 1e-12 else None


def _base(prob: Problem, cols: Columns, z: np.ndarray) -> np.ndarray:
    delay = _shared_point(prob, cols, z)
    return prob.residual(z) if delay is None else cols.base(delay)


def jacobian_columns(prob: Problem, cols: Columns, start: np.ndarray, base: np.ndarray,
                     signs: np.ndarray, *, which=None, out: np.ndarray | None = None
                     ) -> np.ndarray:
    """The weighted residual's Jacobian (N C, P) in z at ``start`` (module doc, 2.);
    one-sided differences of :data:`STEP` towards ``signs`` (P,) (turned round at a bound);
    ``base``: the residual at ``start``; only the columns ``which`` (bool (P,), default all)
    into ``out`` (default a new array). At the reference model the shared parts serve: the
    delay's column, and a replaced group's from the shared Jacobian (taken without the
    delay: a column of the linear model only, the cost is evaluated at the step)."""
    expl, delay = prob.expl, _shared_point(prob, cols, start)
    jac = np.empty((base.size, len(start))) if out is None else out
    for k, key in enumerate(expl.parameter_names):
        if which is not None and not which[k]:
            continue
        group = key.split(".")[0]
        if delay is not None and key == "delay.rotor":
            jac[:, k] = cols.delay(delay, float(prob.sd[k]), signs[k])
        elif delay is not None and group in expl.replaces:
            jac[:, k] = cols.jac[:, cols.index[key]] * prob.sd[k]
        else:
            z = start.copy()
            h = signs[k] * STEP
            if not prob.z_lo[k] <= z[k] + h <= prob.z_hi[k]:
                h = -h
            z[k] += h
            jac[:, k] = (prob.residual(z) - base) / h
    return jac


def linear_step(prob: Problem, start: np.ndarray, base: np.ndarray, jac: np.ndarray):
    """The bounded minimum of the linear model ``r(z) ~ base + jac (z - start)`` of the
    stacked cost: (z1 (P,), its predicted cost, the stacked Jacobian A (N C + K + P, P), the
    count of values at a bound)."""
    n = len(start)
    aug0, du0 = prob.marg.profile(base)
    aug, du = prob.marg.profile(jac)
    a = np.vstack([aug, du, np.eye(n)])
    b = np.concatenate([aug0, du0, start])
    # one Householder QR of [A b] (R only): R of A, Q^T b in the last column and
    # |b - Q Q^T b| in the corner -- no Q of the tall matrix is formed
    rb = np.linalg.qr(np.column_stack([a, b]), mode="r")
    r, qb, rest = rb[:n, :n], rb[:n, n], float(rb[n, n] ** 2)
    lower, upper = prob.z_lo - start, prob.z_hi - start
    # lsq_linear's own first step: the unconstrained solution, returned when inside the
    # bounds (the same numbers, without its checks and wrappers)
    x = np.linalg.lstsq(r, -qb, rcond=-1)[0]
    if np.all((x >= lower) & (x <= upper)):
        active = 0
    else:
        step = lsq_linear(r, -qb, bounds=(lower, upper), method="bvls")
        x, active = step.x, int(np.count_nonzero(step.active_mask))
    predicted = rest + float(np.sum((qb + r @ x) ** 2))
    return start + x, predicted, a, active


def linearised(prob: Problem, cols: Columns, start: np.ndarray
               ) -> tuple[Evidence, np.ndarray, float]:
    """One Gauss-Newton step of ``prob`` from ``start`` (module doc, 2.): (Evidence at the
    step, the step z1, how far the linear model's cost there was off, cost units). A
    one-sided column (the rotor delay's kink) that the step leaves on the other side is
    recomputed on that side."""
    base = _base(prob, cols, start)
    z1, predicted, a, active = _signed_step(prob, cols, start, base)
    vec = prob.stacked(z1)
    miss = abs(float(vec @ vec) - predicted)
    return prob.evidence(z1, vec, a.T @ a, active), z1, miss


def _second_reach(prob: Problem, cols: Columns, z1: np.ndarray) -> float:
    """What a coupled explanation with kin (module doc, 3.) can reach by a second
    Gauss-Newton step from its first one ``z1``, where the parameter another acts through
    has moved and the other's column is no longer zero: the screened evidence there plus
    half its miss (-inf where the step fails). Taken only where neither its own reach nor
    its kin has it fitted already; it only decides whether the explanation is fitted, and
    the fit starts from ``z1`` as before."""
    try:
        ev, _, miss = linearised(prob, cols, z1)
    except (ModelError, np.linalg.LinAlgError):
        return -np.inf
    return ev.log_z + 0.5 * miss if np.isfinite(miss) else -np.inf


def _signed_step(prob: Problem, cols: Columns, start: np.ndarray, base: np.ndarray):
    signs = np.ones(len(start))
    jac = jacobian_columns(prob, cols, start, base, signs)
    z1, predicted, a, active = linear_step(prob, start, base, jac)
    flip = (z1 < start) & (signs > 0)
    flip &= np.array([k == "delay.rotor" for k in prob.expl.parameter_names])
    if np.any(flip):
        signs[flip] = -1.0
        jac = jacobian_columns(prob, cols, start, base, signs, which=flip, out=jac)
        z1, predicted, a, active = linear_step(prob, start, base, jac)
    return z1, predicted, a, active


def refined(prob: Problem, cols: Columns, z: np.ndarray) -> Evidence:
    """The MAP fit of ``prob`` from ``z`` by projected Gauss-Newton steps (Jacobian by
    forward differences at each iterate, the bounded linear step, halved up to 4 times until
    the cost falls), until the cost falls by less than :data:`CONVERGED` or after
    :data:`MAX_STEPS` steps; the Laplace evidence at the optimum with the last Jacobian."""
    vec = prob.stacked(z)
    cost = float(vec @ vec)
    a = None
    for _ in range(MAX_STEPS):
        base = prob.residual(z)
        z_new, _, a, active = _signed_step(prob, cols, z, base)
        for _ in range(4):                       # backtrack: a step must lower the cost
            vec_new = prob.stacked(z_new)
            new = float(vec_new @ vec_new)
            if new <= cost:
                break
            z_new = 0.5 * (z + z_new)
        else:
            break
        drop = cost - new
        z, vec, cost = z_new, vec_new, new
        if drop < CONVERGED:
            break
    # the posterior precision from the last Jacobian (at the iterate before the converged
    # step, which moved the cost by less than CONVERGED)
    if a is None:
        base = prob.residual(z)
        _, _, a, active = linear_step(prob, z, base, jacobian_columns(
            prob, cols, z, base, np.ones(len(z))))
    else:
        active = int(np.count_nonzero((z <= prob.z_lo) | (z >= prob.z_hi)))
    return prob.evidence(z, vec, a.T @ a, active)


def _refined_coupled(prob: Problem, cols: Columns, z1: np.ndarray, delay_s: float
                     ) -> Evidence:
    """:func:`refined` of a coupled explanation from the linear step ``z1`` and, where that
    step raised the cost above the prior centre's, from the centre too (the shared rotor
    delay kept at ``z1``'s): the better evidence. Why: the step cannot see what a coupled
    parameter reaches, and a wrong start leads the Gauss-Newton steps into another basin;
    some explanations need the step's start, others the centre's."""
    first = refined(prob, cols, z1)
    centre = prob.start(delay_s)
    if prob.expl.shift and prob.expl.name != "signal_delay":
        centre[-1] = z1[-1]
    a, b = prob.stacked(z1), prob.stacked(centre)
    if float(b @ b) >= float(a @ a):
        return first
    second = refined(prob, cols, centre)
    return second if second.log_z > first.log_z else first


def _kin_matters(expl: Explanation, explanations: list, screening: Screening, best: float
                 ) -> bool:
    """Whether a coupled explanation is fitted: always without ``kin``; else when one of the
    readings it extends or mimics (their refined evidence, or their screened reach) lies
    within :data:`SCREEN_CUT` of the best. Why it is safe: a payload off the centre moves
    what a centred mass and a CoM shift move, and its position acts only through its mass;
    a propeller change moves the vertical force as a mass or a thrust curve does: where
    none of those can matter, neither can it. A reading whose kin is its own name extends
    that effect's plain reading of fewer parameters (one rotor's propeller with its speed
    per command): only that one counts."""
    if not expl.kin:
        return True
    rows, reach = screening.rows, screening.reach
    mine = set(expl.parameter_names)
    for j, other in enumerate(explanations):
        if other.name == expl.name and not set(other.parameter_names) < mine:
            continue                      # its own kin: the plain reading it extends only
        if other.name in expl.kin and not other.coupled and rows[j] is not None:
            value = reach[j] if rows[j].screened else rows[j].log_z   # refined: exact
            if value >= best - SCREEN_CUT:
                return True
    return False


@dataclasses.dataclass
class Screening:
    """The screen's pass over one flight's explanations, one entry per explanation:
    ``rows`` its Evidence (None where the step failed), ``starts`` the step z1 a refined fit
    starts from (None: exact already, or no step), ``weight`` the log weight it counts with
    towards the best (log Z; "no difference" plus its prior), ``reach`` what a fit could
    reach (screened log Z + miss / 2; inf where the step failed)."""

    rows: list
    starts: list
    weight: list
    reach: list

    def add(self, row, start, weight: float, reach: float) -> None:
        self.rows.append(row)
        self.starts.append(start)
        self.weight.append(weight)
        self.reach.append(reach)


def _null_fit(inputs: FitInputs, cols: Columns, null: Explanation, shared_start: float
              ) -> Evidence:
    """Step 1 of the module doc: "no difference" with the flight's rotor delay, fitted to
    convergence from ``shared_start``; sets ``cols.delay_s`` to its delay, or to
    ``shared_start`` where the delay lies beyond :data:`DELAY_GRID_SDS` prior spreads (there
    it absorbs a gap rather than timing the log)."""
    prob = inputs.problem(null)
    fitted = refined(prob, cols, prob.start(shared_start))
    cols.delay_s = fitted.values["delay.rotor"]
    if abs(cols.delay_s - prob.mean[-1]) > DELAY_GRID_SDS * prob.sd[-1]:
        cols.delay_s = shared_start
    return fitted


def _screen_all(inputs: FitInputs, cols: Columns, explanations: list, null, fitted,
                starts_s: tuple) -> Screening:
    """Step 2 of the module doc: each explanation's screened Evidence, step and reach."""
    shared_start, start_delay_s = starts_s
    effects = {e.name for e in explanations} - {"no_difference"}
    prior_null = float(np.log(max(1, len(effects))))
    out = Screening([], [], [], [])
    for expl in explanations:
        prob = inputs.problem(expl)
        delay = start_delay_s if expl.name == "signal_delay" else shared_start
        if expl is null:
            out.add(fitted, None, fitted.log_z + prior_null, fitted.log_z + prior_null)
            continue
        if not len(prob.mean):                        # nothing to fit: exact already
            row = full_fit(inputs, expl, delay)
            out.add(row, None, row.log_z + prior_null, row.log_z + prior_null)
            continue
        start = prob.start(delay)
        if expl.shift and expl is not null and expl.name != "signal_delay":
            start[-1] = np.clip((cols.delay_s - prob.mean[-1]) / prob.sd[-1],
                                prob.z_lo[-1], prob.z_hi[-1])
        try:
            ev, z1, miss = linearised(prob, cols, start)
        except (ModelError, np.linalg.LinAlgError):
            ev, z1, miss = None, None, np.inf
        # what a fit could reach: the screened evidence plus half the linear model's miss
        out.add(ev, z1, -np.inf if ev is None else ev.log_z,
                np.inf if ev is None or not np.isfinite(miss) else ev.log_z + 0.5 * miss)
    return out


def _matters(inputs: FitInputs, cols: Columns, explanations: list, k: int,
             screening: Screening, cut: tuple[float, float | None]) -> bool:
    """Step 3 of the module doc: whether explanation ``k`` is fitted to convergence, with
    ``cut`` = (the best log weight so far, the best before any coupled fit)."""
    best, before = cut
    expl, row, start = explanations[k], screening.rows[k], screening.starts[k]
    if row is None or screening.reach[k] >= best - SCREEN_CUT:
        return True
    if expl.coupled and _kin_matters(expl, explanations, screening, before):
        return True
    return bool(expl.coupled and expl.kin and start is not None and _second_reach(
        inputs.problem(expl), cols, start) >= best - SCREEN_CUT)


def _fit_to_convergence(inputs: FitInputs, cols: Columns, expl: Explanation,
                        start: np.ndarray | None, delay: float) -> Evidence:
    """:func:`refined` (coupled: :func:`_refined_coupled`) from the step ``start``; the full
    fit (:func:`~quadsim.gap.problem.full_fit`) where there is no step or the refined fit
    meets a non-physical vehicle."""
    row = None
    if start is not None:
        prob = inputs.problem(expl)
        try:
            row = _refined_coupled(prob, cols, start, delay) if expl.coupled else \
                refined(prob, cols, start)
        except (ModelError, np.linalg.LinAlgError):   # a non-physical vehicle met
            row = None
    if row is None:                                   # the full fit walls it off
        row = full_fit(inputs, expl, delay)
    return row


def screened(inputs: FitInputs, explanations: list[Explanation],
             starts_s: tuple[float, float] = (0.0, 0.0)) -> list[Evidence]:
    """Every explanation's Evidence on the flight of ``inputs``, in the order of
    ``explanations``: screened, and fitted to convergence where it can matter (module doc,
    steps 1-3; ``screened=True`` marks the rows left at their screened evidence).
    ``starts_s`` (s): where the shared rotor delay and the "signal_delay" reading start
    (:func:`delay_starts`)."""
    if inputs.memo is None:
        inputs = dataclasses.replace(inputs, memo={})
    start_delay_s = starts_s[1]
    cols = Columns(inputs, next((e for e in explanations if e.name == "no_difference"), None))
    # the flight's own rotor delay under the reference model first (every explanation
    # carries it with the same prior): the others start there
    null = next((e for e in explanations if e.name == "no_difference" and e.shift), None)
    fitted = None if null is None else _null_fit(inputs, cols, null, starts_s[0])
    screening = _screen_all(inputs, cols, explanations, null, fitted, starts_s)
    rows = screening.rows
    # most promising first: each refined fit can only raise the best weight, and with it
    # the cut for those after it. A coupled explanation's step cannot see what it reaches
    # (a parameter acting only through another's value has a zero column at the start): it
    # is always fitted, last, so that the cut of the others is the one their own order gives
    best = max(screening.weight)
    order = sorted(range(len(explanations)),
                   key=lambda k: (explanations[k].coupled, -screening.reach[k]))
    before = None        # the best weight before any coupled fit: their kin are judged by it
    for k in order:
        expl = explanations[k]
        if expl is null or (rows[k] is not None and screening.starts[k] is None):
            continue
        if expl.coupled and before is None:
            before = best
        if _matters(inputs, cols, explanations, k, screening, (best, before)):
            delay = start_delay_s if expl.name == "signal_delay" else cols.delay_s
            rows[k] = _fit_to_convergence(inputs, cols, expl, screening.starts[k], delay)
            best = max(best, rows[k].log_z)
        else:
            rows[k].screened = True
    return rows
