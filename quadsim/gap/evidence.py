"""Weighing explanations of one flight against the reference model: one explanation's fit
and its Laplace evidence, every explanation of a flight weighed, and the drag law a flight is
judged under.

One explanation: its fit and evidence
-------------------------------------

One explanation's fit on one flight, and its Laplace evidence.

The pieces both ways of weighing an explanation share -- the full fit
(:func:`full_fit`, bounded trust-region least squares) and the screen's linearised step and
refined fit (:mod:`quadsim.gap.screen`) -- so that neither calls back into the other:
:mod:`quadsim.gap.evidence` imports both, :mod:`quadsim.gap.screen` imports this module, and
this module imports neither.

Types:

- :class:`FitInputs`: what every explanation's fit on one flight shares (the flight's
  states, the reference model, the shared-parameter Jacobian and spreads, the memo).
- :class:`Problem`: one explanation's fit on that flight: the stacked residual whose squared
  norm is the fit's cost, the bounds in prior units, the marginal of the shared parameters.
- :class:`Evidence`: its result (MAP values, spreads, log evidence, per-channel mean square).

The likelihood, the marginal of the shared parameters and the Laplace evidence are defined in
the module doc of :mod:`quadsim.gap.evidence`; :func:`laplace` computes the latter.

Example::

    >>> inputs = FitInputs(states, reference, jac, marginal_sd(reference), memo={})
    >>> ev = full_fit(inputs, explanation, start_delay_s=0.0)
    >>> ev.log_z, ev.values

Every explanation of a flight
-----------------------------

Explanations of one flight against the calibrated reference model, weighed by evidence.

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
to convergence (:func:`quadsim.gap.evidence.evaluate`).

The full fit of an explanation (:func:`quadsim.gap.evidence.full_fit`: bounded trust-region
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
   speeds are read later by a Fourier phase shift (:func:`quadsim.gap.reference.read_later`;
   linear interpolation on a non-uniform time base, piecewise linear in the delay with a
   kink at every sample), so the delay's column is one-sided and is taken again on the other
   side when the step goes there. The stacked cost (profiled residual,
   marginalised shifts, z) is then quadratic; its bounded minimum z1 is a small linear
   least-squares problem (:func:`linear_step`). Where z1 gives a vehicle no rigid body is
   (an inertia error's moments across the triangle inequality I_a + I_b >= I_c, linear in
   the errors: :class:`InertiaWall`), z1 is the same quadratic's minimum on that wall
   (:func:`quadsim.gap.fitting.plane_step`, closed form with one active equality), and the
   wall counts as a bound in the Laplace volume (half of it, as a value at a bound); a
   forward difference that would cross it is taken the other way. Without it the step's
   residual failed and the explanation fell back to the full fit, whose finite differences
   across the wall meet the non-physical penalty (:meth:`Problem.stacked`) and inflate its
   Occam factor (measured in CHANGELOG). The residual is evaluated at z1 itself: the
   *screened* evidence is the Laplace evidence (:func:`quadsim.gap.evidence.laplace`) at z1
   with the Gauss-Newton precision AᵀA, and ``miss`` = |cost(z1) - predicted cost| says how
   far the linear model was off there.
3. **Cut**: an explanation whose *reach*, screened log Z + miss / 2, lies within
   :data:`SCREEN_CUT` of the best log weight so far (log Z; "no difference" with its prior,
   as in :func:`quadsim.gap.judge.posterior`) is fitted to convergence (:func:`refined`:
   projected Gauss-Newton from z1, a fresh Jacobian per step, halved steps until the cost
   falls, stopped at a cost drop below :data:`CONVERGED`), most promising first, each result
   raising the best. The others keep their screened Evidence (``screened=True``). Within
   the cut, a step whose linear model was exact (miss at most :data:`STEP_MISS`) on a
   reading too light to move a probability by 0.005 is kept as the fit
   (``step_converged=True``; :func:`converged_steps` states the bound and its margin).
   Where the linear model missed by more than the cut itself (miss > :data:`SCREEN_CUT`:
   the reach's own error exceeds the margin it is compared with) and the reach lies
   within twice the cut (the second steps kept to readings near the cut: their cost), a
   second step from z1 decides (:func:`_second_reach`): fitted where its reach lies
   within the cut. Why: a reading strongly nonlinear in its values (a payload's swing in
   its cable's length) takes a poor first step from its prior's centre (the case that
   showed it: CHANGELOG.md, "A screened step whose linear model missed by more than the
   cut").

Why the cut does not move a verdict: a screened reading lies more than SCREEN_CUT = log(1e4)
+ 4 below the best, i.e. at posterior odds below 1e-4 against it by its screened evidence;
the judge's thresholds are posterior 0.1 (a stated reading) and 0.9 (confident). The screened
cost is that of a point the fit can reach, so a fit only lowers it, by about miss / 2 where
the linear model was off; a second local optimum the step does not see is the remaining risk
(``full=True`` below; the last comparison: benchmarks/HISTORY.md, 22.2 s per flight-minute,
the same verdict on all 26 mixed flights).

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

The drag law
------------

The law of the references' air drag, as a flight shows it: chosen once per flight by the
evidence of "no difference", and every reading judged under it.

Why. The reference model fits the horizontal air drag its flights share as a rotor drag,
linear in the air velocity (:mod:`quadsim.effects.rotor_drag`). An airframe's drag is
quadratic (:mod:`quadsim.effects.body_drag`), under one of two laws: on the air speed,
``-1/2 rho C_d A |v| v``, or each body axis on its own, ``-1/2 rho C_d A |v_i| v_i`` (a box's
faces taken apart: l2f's, PyFlyt's and multirotor's drag). At the references' ~1 m/s the
three give the same force; a flight flown faster, or in a wind, shows which one the vehicle
has. The law is the vehicle's, the references' as much as the flight's: it is no reading of
its own, and every reading must be judged under the same one: a law given to one reading
alone (the wind, or "no difference") wins that reading the law's evidence, and the flight
its name (CHANGELOG.md: Docstrings as contracts).

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
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, get_lapack_funcs
from scipy.optimize import least_squares, lsq_linear

from ..core.errors import ModelError, refuse_moved
from ..effects.base import EffectSet
from ..vehicle.params import TRIANGLE_RTOL
from .calibrate import jacobian
from .explanations import (  # re-exported: the evidence's public names
    DELAY_SD_S,
    DETERMINED,
    Explanation,
    explanations_for,
    law_replaces,
    marginal_sd,
    own_effects,
    quadratic_laws,
    reference_determined,
)
from .fitting import DragLaw, build_effect, plane_step, residuals
from .fitting import parameter_bounds as fit_bounds
from .lsq import wall_jacobian  # re-exported: the full fit's (fitted_jacobian)
from .reference import Reference, centre_term, columns, rotor_spectra, shifted
from .residual import flight_memo, memoised, min_time_constant

__all__ = ["DELAY_BOUND_S", "FULL_FIT_EVALUATIONS", "FULL_FIT_STEP", "ChannelBlocks", "Evidence",
           "FitInputs",
           "Marginal", "Problem", "flight_residual", "full_fit", "laplace", "parameter_bounds",
           "posterior_cov", "inside_reads", "shifted_view", "wall_jacobian",
           "fitted_jacobian",
           "CONVERGED", "PendingEvidence", "idle_parameters", "log_evidence",
           "THROUGH_SDS", "unidentified",
           "DELAY_GRID_S", "DELAY_GRID_SDS",
           "DELAY_SD_S", "DETERMINED", "MAX_STEPS", "SCREEN_CUT", "STEP", "Columns", "Explanation",
           "centred_is_base", "delay_starts", "evaluate", "explanations_for", "jacobian_columns",
           "linear_step", "linearised", "marginal_sd", "reference_determined", "refined",
           "screen_step", "screened", "shared_effects", "shifted", "DragLaw", "choose", "under",
           "slow_ms", "slow_window"]


#: bounds (s) of a fitted signal delay (``Explanation.shift``): the lag window of
#: :data:`quadsim.logs.delays.MAX_LAG_S`, the widest offset the cross-correlation looks at.
DELAY_BOUND_S = 0.1
#: the full fit's evaluations of the stacked residual at most (scipy ``max_nfev``): enough
#: for the 1-6 parameters of an explanation from its prior centre; the screen's refined fit
#: (:mod:`quadsim.gap.screen`) runs to convergence instead.
FULL_FIT_EVALUATIONS = 40
#: the full fit's finite-difference step in prior units (scipy ``diff_step``)
FULL_FIT_STEP = 1e-3


@dataclass
class Evidence:
    """One explanation's result on one flight.

    ``values``, ``post_sd``, ``prior_sd``: parameter name (``effect.parameter``, or
    ``delay.rotor`` in s) -> MAP value, posterior and prior spread (the parameter's SI unit);
    ``determined``: name -> whether the posterior spread is below
    :data:`~quadsim.gap.explanations.DETERMINED` times the prior's (only the explanation's
    own parameters; the shared rotor delay is not one of its own); ``log_z``: log evidence
    (natural log, model prior included); ``ms`` (C,): per-channel mean squared residual over
    sigma_c^2 (dimensionless, 1 = the references' level); ``mean`` (C,): per-channel mean
    residual (N, N m, rad/s); ``air_force`` (3,): mean air force of a wind reading beyond the
    references' wind (world, N), else None; ``shared_shift``: shared parameter -> its
    profiled shift from theta_ref (its SI unit); ``screened``: True where the value is the
    screen's linearised evidence (:mod:`quadsim.gap.screen`), not a converged fit;
    ``step_converged``: True where it is the screen's step taken as the converged fit
    (:func:`converged_steps`: the flight's value to within its stated margin)."""

    explanation: Explanation
    values: dict
    post_sd: dict
    prior_sd: dict
    determined: dict
    log_z: float
    ms: np.ndarray
    mean: np.ndarray | None = None
    air_force: np.ndarray | None = None
    shared_shift: dict = field(default_factory=dict)
    #: True: the linearised evidence of :mod:`.screen` (no full fit: it cannot matter)
    screened: bool = False
    #: True: the screen's step taken as the converged fit (its linear model exact to
    #: :data:`STEP_MISS`, the reading too light to move a probability: :func:`converged_steps`)
    step_converged: bool = False
    #: (C,) mean square of the residual's slow part (its :data:`SLOW_WINDOW_S` moving
    #: average) over sigma_c^2 (dimensionless); None: states without a time base
    slow: np.ndarray | None = None
    #: the samples W that moving average spans (:func:`slow_window`); None: no slow part
    slow_window: int | None = None
    #: (P, P) posterior covariance of ``values`` in their SI units, rows and columns in
    #: ``values``' order (sd_i sd_j (H^+)_ij, :func:`laplace`); None: not kept. A size that
    #: sums parameters (a payload's fixed and swinging parts) takes its spread from it.
    post_cov: np.ndarray | None = None
    #: 1/2 |z|^2 at the MAP (z the explanation's values in prior spreads from the prior's
    #: centre, :class:`Problem`): the log units that where the prior centres the values takes
    #: from ``log_z`` (its -1/2 |vec|^2 holds it); log_z + prior_pull is the evidence with
    #: every value counted at its prior's centre, the data's fit and the Occam volume only
    #: (:func:`quadsim.gap.logcheck.confusable_note`). 0 where not measured.
    prior_pull: float = 0.0

    @property
    def name(self) -> str:
        return self.explanation.name


@dataclass(frozen=True)
class FitInputs:
    """What every explanation's fit on one flight shares.

    ``states``: the flight's (decimated, aligned) fit states
    (:class:`quadsim.gap.residual.FlightStates`, N samples); ``reference``: the reference
    model; ``jac`` (N C, M): the weighted residual's Jacobian in the M shared parameters at
    theta_ref (:func:`quadsim.gap.reference.jacobian`, columns in
    ``reference.candidate.parameter_names`` order, per unit of each parameter's SI value);
    ``s_all`` (M,): the spread each shared parameter is marginalised with
    (:func:`quadsim.gap.explanations.marginal_sd`); ``memo``: residual parts kept across the
    evaluations on this flight (:func:`quadsim.gap.fitting.residuals`), None for none."""

    states: object
    reference: Reference
    jac: np.ndarray
    s_all: np.ndarray
    memo: dict | None = field(default=None, compare=False)

    @property
    def names_all(self) -> list[str]:
        """The shared parameters' names, in the Jacobian's column order."""
        return list(self.reference.candidate.parameter_names)

    def problem(self, expl: Explanation) -> Problem:
        """``expl``'s :class:`Problem` on this flight, sharing the memo."""
        return Problem(self.states, self.reference, expl, self.jac, self.s_all, self.memo)


@dataclass(frozen=True)
class ChannelBlocks:
    """Marginalised columns each of which lies in one channel's rows (the discrepancy's:
    channel c's features, :func:`quadsim.gap.reference.columns`): column e is zero outside
    the rows n C + ch[e] (C = ``channels``) and ``x[:, e]`` (N,) its values there.
    :class:`Marginal` takes their products over those N rows only, not over the N C rows of
    their zeros (a tenth of the rows with ten channels): the same sums without their zero
    terms, round-off apart (the additions' order differs)."""

    ch: np.ndarray
    x: np.ndarray
    channels: int

    @classmethod
    def of(cls, extra: np.ndarray | None, channels: int) -> ChannelBlocks | None:
        """The blocks of ``extra`` (N C, E); None where a column spans several channels
        or none, there are no columns, or the rows are not N C for ``channels``."""
        if extra is None or extra.shape[1] == 0 or channels < 2 or \
                extra.shape[0] % channels:
            return None
        n = extra.shape[0] // channels
        cube = extra.reshape(n, channels, extra.shape[1])
        nonzero = np.any(cube != 0.0, axis=0)                   # (C, E)
        if not np.all(np.count_nonzero(nonzero, axis=0) == 1):
            return None
        ch = np.argmax(nonzero, axis=0)
        return cls(ch, np.ascontiguousarray(cube[:, ch, np.arange(extra.shape[1])]),
                   int(channels))

    def dense(self) -> np.ndarray:
        """The columns as (N C, E), zeros included."""
        n, e = self.x.shape
        out = np.zeros((n, self.channels, e))
        out[:, self.ch, np.arange(e)] = self.x
        return out.reshape(n * self.channels, e)


class Marginal:
    """The shared parameters not fitted by an explanation, marginalised linearly
    (:mod:`quadsim.gap.evidence`, module doc): ``j`` = [J_s diag(s_ref), extra] (N C, K; the
    ``extra`` columns, N C x E, at unit spread), ``chol`` the Cholesky factor of
    A = I + jᵀj, ``logdet`` = log det A. ``blocks``: ``extra`` as :class:`ChannelBlocks`
    (then ``extra`` itself may be None): the products over its columns read N rows each,
    not N C (:meth:`jt`); ``j`` is then formed only when asked for."""

    def __init__(self, jac: np.ndarray, s_ref: np.ndarray, extra: np.ndarray | None = None,
                 *, blocks: ChannelBlocks | None = None):
        # column-major: the profile's two products over j (jᵀ r, j du) run about a third
        # faster on these tall, thin matrices than on the row-major copy (the same values,
        # summed in another order: round-off apart). Written column-major at once, the
        # unit-spread ``extra`` columns (N C, E) after jac's: the same numbers as
        # ``np.hstack([jac, extra]) * np.concatenate([s_ref, ones])``, without the copies
        k = jac.shape[1]
        self._blocks = blocks
        if blocks is not None:
            dense = np.empty(jac.shape, order="F")
            np.multiply(jac, s_ref, out=dense)
            self._dense, self._j = dense, None
            self.shape = (jac.shape[0], k + blocks.x.shape[1])
        else:
            extra = np.zeros((jac.shape[0], 0)) if extra is None else extra
            j = np.empty((jac.shape[0], k + extra.shape[1]), order="F")
            np.multiply(jac, s_ref, out=j[:, :k])
            j[:, k:] = extra
            self._dense, self._j = j[:, :k], j
            self.shape = j.shape
        self._k = k
        a = np.eye(self.shape[1]) + self._gram()
        self.chol = cho_factor(a)
        self.logdet = 2.0 * float(np.sum(np.log(np.diag(self.chol[0]))))
        # cho_solve's own LAPACK call (the same numbers), without its per-call checks and
        # batch wrapper: most of its cost on these small systems, called thousands of times
        self._potrs = get_lapack_funcs(("potrs",), (self.chol[0],))[0] if self.shape[1] \
            else None
        self._last: tuple | None = None
        self._moment: tuple = ()

    @property
    def j(self) -> np.ndarray:
        """[J_s diag(s_ref), extra] (N C, K), column-major (formed on first use where the
        extra columns are kept as blocks)."""
        if self._j is None:
            j = np.empty(self.shape, order="F")
            j[:, :self._k] = self._dense
            j[:, self._k:] = self._blocks.dense()
            self._j = j
        return self._j

    def _gram(self) -> np.ndarray:
        """jᵀj (K, K); with blocks, a block column's products with the dense columns and
        with the block columns of its own channel over that channel's N rows (zero across
        channels)."""
        blocks, dense, k = self._blocks, self._dense, self._k
        if blocks is None:
            return self._j.T @ self._j
        x, ch, chans = blocks.x, blocks.ch, blocks.channels
        out = np.zeros((self.shape[1], self.shape[1]))
        out[:k, :k] = dense.T @ dense
        rows = dense.reshape(x.shape[0], chans, k, order="C")
        for c in np.unique(ch):
            cols = np.flatnonzero(ch == c)
            own = x[:, cols]
            out[np.ix_(k + cols, k + cols)] = own.T @ own
            cross = rows[:, c, :].T @ own
            out[:k, k + cols] = cross
            out[k + cols, :k] = cross.T
        return out

    def jt(self, r: np.ndarray) -> np.ndarray:
        """jᵀ ``r``: (K,) of a residual vector (N C,), (K, P) of columns (N C, P); with
        blocks, their rows only (class doc)."""
        blocks = self._blocks
        if blocks is None:
            return self._j.T @ r
        x, ch, chans = blocks.x, blocks.ch, blocks.channels
        dense = self._dense.T @ r
        n, e = x.shape
        if r.ndim == 1:
            own = (x.T @ r.reshape(n, chans))[np.arange(e), ch]
        else:
            p = r.shape[1]
            own = (x.T @ r.reshape(n, chans * p)).reshape(e, chans, p)[np.arange(e), ch]
        return np.concatenate([dense, own])

    def j_times(self, u: np.ndarray) -> np.ndarray:
        """j ``u``: (N C,) of a (K,) vector, (N C, P) of (K, P) columns; with blocks, their
        rows only (class doc)."""
        blocks, k = self._blocks, self._k
        if blocks is None:
            return self._j @ u
        x, ch, chans = blocks.x, blocks.ch, blocks.channels
        n, e = x.shape
        dense = self._dense @ u[:k]
        if u.ndim == 1:
            y = np.zeros((e, chans))
            y[np.arange(e), ch] = u[k:]
            return dense + (x @ y).reshape(-1)
        p = u.shape[1]
        y = np.zeros((e, chans, p))
        y[np.arange(e), ch] = u[k:]
        return dense + (x @ y.reshape(e, chans * p)).reshape(n * chans, p)

    def moment(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(b, A^-1 b) with b = jᵀ ``r`` of a residual vector (N C,); the last two vectors'
        kept (the profile, the one-pass cost and the linear step's Gram matrix of one
        residual share them; the screen's steps all start from the flight's base residual,
        each followed by the profile at its own step: the same numbers, one pass over j;
        residuals are not written to)."""
        kept = self._moment
        for entry in kept:
            if entry[0] is r:
                return entry[1], entry[2]
        rhs = self.jt(r)
        x = self.solve(rhs)
        self._moment = ((r, rhs, x),) + kept[:1]
        return rhs, x

    def profile(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(r + j du, du) at the profiled shift du = -A^-1 jᵀ r of the weighted residual
        ``r`` (N C,) or of each of its columns (N C, P). The last residual vector's answer is
        kept (a fit's linear step profiles the residual its cost has just profiled; the
        residuals of :meth:`Problem.residual` are not written to): the arrays returned are
        shared, not to be written to either."""
        last = self._last
        if last is not None and last[0] is r:
            return last[1]
        out = self._profile(r)
        if r.ndim == 1:
            self._last = (r, out)
        return out

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A^-1 ``rhs`` ((K,) or (K, P)); zeros of its shape where there are no columns."""
        if self._potrs is None:
            return np.zeros_like(rhs, dtype=float)
        x, info = self._potrs(self.chol[0], rhs, lower=self.chol[1])
        if info != 0:
            raise ValueError(f"illegal value in {-info}th argument of internal potrs")
        return x

    def cost(self, r: np.ndarray) -> float:
        """|r + j du|^2 + |du|^2 at the profiled shift of ``r`` (N C,), the squared norm of
        :meth:`profile`'s two parts without forming them: with b = jᵀ r and du = -A^-1 b,
        |r + j du|^2 + |du|^2 = |r|^2 + 2 b.du + duᵀ(jᵀj + I) du = |r|^2 - bᵀ A^-1 b
        (one pass over j instead of two; the same value up to round-off, ~1e-16 of |r|^2)."""
        last = self._last
        if last is not None and last[0] is r:          # profiled already: its own norm
            aug, du = last[1]
            return float(aug @ aug) + float(du @ du)
        rhs, x = self.moment(r)
        if not len(rhs):
            return float(r @ r)
        return float(r @ r) - float(rhs @ x)

    def _profile(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = self.moment(r)[1] if r.ndim == 1 else self.solve(self.jt(r))
        du = -x
        return r + self.j_times(du), du


def parameter_bounds(expl: Explanation, reference: Reference, dt: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of ``expl``'s parameters in their SI units: each effect parameter's
    declared bounds narrowed by its fit window for this vehicle (the effect's facts,
    :func:`quadsim.gap.fitting.parameter_bounds`: a mass offset within -1/2 .. 2 x the
    vehicle's mass, a payload within the rotor arm, a CoM shift within half of it, the thrust
    curve within the hover thrust per rad/s and
    :func:`~quadsim.gap.fitting.curve_quadratic_bounds`);
    a motor lag of at least :func:`~quadsim.gap.residual.min_time_constant` of the fit
    step ``dt`` (s; the rotor channel's Heun sub-step resolves no shorter one); a fitted delay
    within +-:data:`DELAY_BOUND_S`."""
    lower, upper = (list(x) for x in fit_bounds(expl, reference.params))
    k = 0
    for name, _, fitted in expl.parts:
        for _p in fitted:
            if name == "motor_lag":
                lower[k] = max(lower[k], min_time_constant(dt))
            k += 1
    if expl.shift:
        lower.append(-DELAY_BOUND_S)
        upper.append(DELAY_BOUND_S)
    return np.asarray(lower, float), np.asarray(upper, float)


def shared_effects(reference: Reference, replaces: tuple) -> tuple[list, list[int]]:
    """The reference effects without the replaced groups, and the marginalised columns."""
    names = reference.candidate.parameter_names
    keep = [k for k, n in enumerate(names) if n.split(".")[0] not in replaces]
    everything, n_base = reference.effects(), len(reference.candidate.base)
    # effects already in the model (held-out mode's --effects-file) stay; an explanation
    # replaces only the fitted shared groups
    effects = everything[:n_base] + [e for e in everything[n_base:] if e.name not in replaces]
    return effects, keep


def _air_force(states, reference: Reference, effects: list, own: list,
               memo: dict | None = None) -> np.ndarray:
    """Mean air force (world, N; (3,)) of the flight's wind beyond the references' wind:
    the model wrench with the reading's own effects ``own`` less that with the references'
    wind, on the shared ``effects``. ``memo``: the flight's (:func:`Problem.residual`'s),
    whose rotations and kept loads serve (the same numbers)."""
    from ..core.frames import rotate
    from .residual import model_wrench

    base = [e for e in reference.effects() if e.name == "wind"]   # the references' own
    kw = {}
    if memo is not None:
        rotation, motion = flight_memo(memo, states)
        kw = {"rotation": rotation, "flight_memo": motion}
    with_wind, _, _ = model_wrench(states, reference.params, effects + own, **kw)
    without, _, _ = model_wrench(states, reference.params, effects + base, **kw)
    return np.mean(rotate(states.quat, with_wind - without), axis=0)


def flight_residual(states, reference: Reference, effects: list, memo: dict | None = None
                    ) -> np.ndarray:
    """:func:`quadsim.gap.reference.weighted_residual`, flattened (N C,), with the residual
    parts that repeat on one flight kept in ``memo`` (:func:`quadsim.gap.fitting.residuals`)."""
    r = residuals(states, reference.params, effects, rotor_channel=reference.rotor, memo=memo)
    # in place: ``residuals`` returns a new array of its own (the same numbers)
    np.subtract(r, centre_term(states, reference.discrepancy, r.shape[1], memo), out=r)
    np.multiply(r, _root_weights(reference, memo), out=r)
    return r.ravel()


def _root_weights(reference: Reference, memo: dict | None) -> np.ndarray:
    """sqrt(``reference.weights``) (C,), kept in ``memo`` per reference object."""
    if memo is None:
        return np.sqrt(reference.weights)
    hit = memo.get("root_weights")
    if hit is None or hit[0] is not reference:
        hit = memo["root_weights"] = (reference, np.sqrt(reference.weights))
    return hit[1]


def shifted_view(states, delay_s: float, memo: dict | None = None):
    """:func:`quadsim.gap.reference.shifted` states (rotor speeds read ``delay_s`` s later);
    with a ``memo``, the same object for the same delay, the flight's rotor spectra computed
    once."""
    if memo is None:
        return shifted(states, delay_s)
    spectra = memoised(memo, ("spectra", id(states)), states, lambda: rotor_spectra(states))
    return memoised(memo, ("shifted", id(states), delay_s), states,
                 lambda: shifted(states, delay_s, spectra))


class Problem:
    """One explanation's fit on one flight (:mod:`quadsim.gap.evidence`, module doc).

    ``residual(z)``: the weighted residual (N C,) at z (the explanation's parameters in units
    of their prior spread, z = (theta - mean) / sd; the rotor delay last where it fits one);
    ``stacked(z)``: the vector whose squared norm is the fit's cost (profiled residual,
    marginalised shared shifts, z); ``z_lo``, ``z_hi``: the bounds in z; ``lower``,
    ``upper``: the same in SI units (:func:`parameter_bounds`); ``shared``/``keep``/``marg``:
    the reference effects it keeps, the shared columns it marginalises and their
    :class:`Marginal`; ``memo``: residual parts shared by the evaluations on this flight."""

    def __init__(self, states, reference: Reference, expl: Explanation, jac: np.ndarray,
                 s_all: np.ndarray, memo: dict | None = None):
        self.states, self.reference, self.expl = states, reference, expl
        self.s_all = s_all
        self.memo = memo          # residual parts shared by evaluations on one flight
        if memo is None:
            self.shared, self.keep = shared_effects(reference, expl.replaces)
        else:       # the same for every explanation that replaces the same groups
            kept = memo.setdefault("shared_effects", {})
            if expl.replaces not in kept:
                kept[expl.replaces] = shared_effects(reference, expl.replaces)
            self.shared, self.keep = kept[expl.replaces]
        self.marg = self._marginal(jac, s_all)
        self.mean, self.sd = np.asarray(expl.mean), np.asarray(expl.sd)
        lower, upper = parameter_bounds(expl, reference, float(states.t[1] - states.t[0]))
        self.lower, self.upper = lower, upper
        self.z_lo, self.z_hi = (lower - self.mean) / self.sd, (upper - self.mean) / self.sd
        self.size = jac.shape[0] + self.marg.shape[1] + len(self.mean)
        #: how many evaluations of :meth:`stacked` met the wall of values that make no
        #: vehicle (ModelError): a fit's Jacobian is taken again where any did
        #: (:func:`full_fit`)
        self.walls = 0

    def _marginal(self, jac: np.ndarray, s_all: np.ndarray) -> Marginal:
        """The marginal of the kept shared columns and the discrepancy's
        (:func:`quadsim.gap.reference.columns`, unit spread: they are scaled by the
        coefficients' covariance factor already), after them; with a ``memo``, one per set
        of columns (most explanations keep them all) and Jacobian. The discrepancy's
        columns are passed as :class:`ChannelBlocks` (each lies in one channel's rows), found
        once per flight, reference discrepancy and weights where there is a memo."""
        def build():
            extra = self._extra()
            return Marginal(jac[:, self.keep], s_all[self.keep], extra[0],
                            blocks=extra[1] if len(extra) > 1 else None)

        if self.memo is None:
            return build()
        kept = self.memo.setdefault("marginals", {})
        key = (id(jac), tuple(self.keep), s_all[self.keep].tobytes(),
               id(self.reference.discrepancy), self.reference.weights.tobytes())
        if key not in kept or kept[key][0] is not jac:
            kept[key] = (jac, build())
        return kept[key][1]

    def _extra(self) -> tuple:
        """(extra,) or (None, blocks) for :class:`Marginal`: the discrepancy's columns
        (:func:`quadsim.gap.reference.columns`) as :class:`ChannelBlocks` where they are
        such (extra None then), else dense; with a ``memo``, kept per states, discrepancy
        and weights (the same numbers for every marginal of the flight)."""
        reference = self.reference
        chans = len(reference.weights)
        key = ("marginal.extra", id(self.states), id(reference.discrepancy),
               reference.weights.tobytes())
        hit = None if self.memo is None else self.memo.get(key)
        if hit is not None and hit[0] is self.states and hit[1] is reference.discrepancy:
            return hit[2]
        extra = columns(self.states, reference.discrepancy, reference.weights, self.memo)
        blocks = ChannelBlocks.of(extra, chans)
        value = (extra,) if blocks is None else (None, blocks)
        if self.memo is not None:
            self.memo[key] = (self.states, reference.discrepancy, value)
        return value

    def residual(self, z: np.ndarray) -> np.ndarray:
        """The weighted residual at ``z``; with a ``memo``, the last one per explanation is
        kept (the screen's step and the refined fit ask again for the point they just
        evaluated: the start of the next step, the step just accepted)."""
        last = None if self.memo is None else self.memo.setdefault("last_residual", {})
        key = (self.expl.name, self.expl.variant)
        if last is not None and key in last and np.array_equal(last[key][0], z):
            return last[key][1]
        # z at its bound gives theta a round-off beyond the parameter's range: clipped
        theta = np.clip(self.mean + self.sd * z, self.lower, self.upper)
        own = own_effects(self.expl, theta)
        flight = self.shifted(float(theta[-1])) if self.expl.shift else self.states
        r = flight_residual(flight, self.reference, self.shared + own, self.memo)
        if last is not None:
            last[key] = (np.array(z, dtype=float), r)
        return r

    def shifted(self, delay_s: float):
        """:func:`shifted_view` of the flight's states with this problem's memo."""
        return shifted_view(self.states, delay_s, self.memo)

    def stacked(self, z: np.ndarray) -> np.ndarray:
        """(profiled residual (N C,), marginalised shifts (K,), z): the fit's cost is its
        squared norm; a vehicle the model rejects (ModelError) costs 1e3 per entry (a wall
        the fit turns back from)."""
        try:
            r = self.residual(z)
        except ModelError:
            self.walls += 1
            return np.full(self.size, 1e3)
        aug, du = self.marg.profile(r)
        return np.concatenate([aug, du, z])

    def cost(self, z: np.ndarray) -> float:
        """The fit's cost at ``z``: the squared norm of :meth:`stacked` (the same value up to
        round-off, :meth:`Marginal.cost`), for the callers that need no more than the norm
        (the delay grid, a refined fit's accepted or halved steps)."""
        try:
            r = self.residual(z)
        except ModelError:
            return float(self.size) * 1e6
        return self.marg.cost(r) + float(z @ z)

    def start(self, start_delay_s: float = 0.0) -> np.ndarray:
        """z = 0 with the delay at ``start_delay_s``, inside the bounds."""
        z0 = np.zeros_like(self.mean)
        if self.expl.shift:
            z0[-1] = start_delay_s / self.sd[-1]
        return np.clip(z0, self.z_lo + 1e-6, self.z_hi - 1e-6)

    def evidence(self, z, vec, h, at_bound: int) -> Evidence:
        """:func:`laplace` of this problem at ``z``."""
        return laplace(self, z, vec, h, at_bound)


def full_fit(inputs: FitInputs, expl: Explanation, start_delay_s: float,
             start: np.ndarray | None = None) -> Evidence:
    """``expl``'s MAP fit and Laplace evidence on the flight of ``inputs``
    (:mod:`quadsim.gap.evidence`, module doc): bounded trust-region least squares of
    :meth:`Problem.stacked` (at most :data:`FULL_FIT_EVALUATIONS` evaluations, step
    :data:`FULL_FIT_STEP`), the shared parameters ``expl`` does not replace marginalised.
    ``start_delay_s`` (s): where the rotor delay starts; ``start``: where the fit starts
    (z units; default :meth:`Problem.start`). The problem keeps no memo (a fit of its own)."""
    prob = Problem(inputs.states, inputs.reference, expl, inputs.jac, inputs.s_all)
    if not len(prob.mean):
        return prob.evidence(np.zeros(0), prob.stacked(np.zeros(0)), np.zeros((0, 0)), 0)
    z0 = prob.start(start_delay_s) if start is None else np.clip(
        np.asarray(start, dtype=float), prob.z_lo + 1e-6, prob.z_hi - 1e-6)
    fit = least_squares(prob.stacked, z0, bounds=(prob.z_lo, prob.z_hi),
                        diff_step=FULL_FIT_STEP, max_nfev=FULL_FIT_EVALUATIONS, method="trf")
    vec, jac, at_bound = fitted_jacobian(prob, fit, FULL_FIT_STEP)
    return prob.evidence(fit.x, vec, jac.T @ jac, at_bound)


def fitted_jacobian(prob: Problem, fit, step: float) -> tuple[np.ndarray, np.ndarray, int]:
    """(the stacked vector at ``fit.x``, its Jacobian (len, P), how many values count as at a
    bound) of ``fit`` (scipy's ``least_squares`` of ``prob.stacked`` in z, ``diff_step``
    ``step``): the solver's own where no evaluation met the wall of values that make no
    vehicle (``prob.walls`` 0); else taken again by :func:`wall_jacobian` (no difference
    across the wall), the wall counted as a bound where a step met it (half the Laplace
    volume, as a value at a bound). The solver's own where ``fit.x`` itself lies beyond the
    wall (its Jacobian is zero there: :func:`laplace` gives no evidence). ``prob``: a
    :class:`Problem`, or any fit with its ``stacked``, ``walls``, ``z_lo`` and ``z_hi``
    (:func:`quadsim.gap.diagnose.fit_own_starts`: the explanation and its nuisance starts).
    Why: the solver's last Jacobian may hold a difference across the wall (a relative step
    of a negative value goes down; a forward step from a MAP next to it), whose column is
    ~1e3 sqrt(len) / step (:func:`wall_jacobian`)."""
    at_bound = int(np.count_nonzero(fit.active_mask))
    if not prob.walls:
        return fit.fun, fit.jac, at_bound
    vec, jac, near = wall_jacobian(prob, fit.x, step)
    if vec is None:
        return fit.fun, fit.jac, at_bound
    return vec, jac, at_bound + int(near)


def inside_reads(t: np.ndarray, delay_s: float) -> np.ndarray | None:
    """(N,) whether each sample's read ``t + delay_s`` (s) lies inside the log's span
    [t_0, t_end]; None where every sample's does, or none does (nothing to leave out). The
    samples outside form one run at one end: the mask is a contiguous span. Beyond the log's
    ends a rotor log read later meets the mirror image of its samples
    (:func:`quadsim.gap.reference.read_later`): a fill that keeps the spectrum from ringing,
    not data, so what a reading leaves (:func:`laplace`'s ``ms`` and slow part) counts only
    the samples inside, on every channel that reads the shifted rotor speeds (the force and
    moment channels through the rotors' wrench, the rotor channels directly). The likelihood
    keeps every sample (each reading's own delay would give each a different sample count)."""
    inside = (t + delay_s <= t[-1]) & (t + delay_s >= t[0])
    return None if inside.all() or not inside.any() else inside


#: the slow part's window (s): the held-out noise model's (:data:`quadsim.gap.judge.SLOW_WINDOW_S`)
SLOW_WINDOW_S = 0.5


def slow_window(dt: float, window_s: float = SLOW_WINDOW_S) -> int:
    """The samples W of a moving average over ``window_s`` at step ``dt`` (s): the odd
    number nearest window_s / dt, at least 3."""
    return max(3, int(np.rint(window_s / dt)) | 1)


def slow_ms(resid: np.ndarray, dt: float, window_s: float = SLOW_WINDOW_S) -> np.ndarray:
    """(C,) mean square of the moving average over ``window_s`` (:func:`slow_window`
    samples of step ``dt`` s; zero padded at the ends) of each column of ``resid`` (N, C)
    (the residual over sigma_c: the per-flight systematic remainder's statistic,
    :func:`quadsim.gap.judge.judge`)."""
    n = slow_window(dt, window_s)
    c = np.cumsum(np.vstack([np.zeros((n // 2 + 1, resid.shape[1])), resid,
                             np.zeros((n // 2, resid.shape[1]))]), axis=0)
    slow = (c[n:] - c[:-n]) / n
    return np.mean(slow ** 2, axis=0)


def posterior_cov(h: np.ndarray) -> np.ndarray:
    """The posterior covariance (P, P) in z units of the posterior precision ``h`` (P, P,
    JᵀJ of the stacked residual in z units): H^-1 with H's eigenvalues floored at 1.
    H = J_dᵀJ_d + I holds the prior's identity rows (:meth:`Problem.stacked`), so in exact
    arithmetic every eigenvalue is >= 1 and the floor changes nothing; it keeps round-off
    (or a wall's constant residual) from reporting a spread above the prior's, and it
    replaces a pseudo-inverse, whose cut-off (1e-15 of the largest eigenvalue) dropped every
    direction but the largest where one direction's precision was ~1e16 times the rest,
    so that every parameter came out "determined" (:func:`wall_jacobian`)."""
    lam, vec = np.linalg.eigh(0.5 * (h + h.T))
    return (vec / np.maximum(lam, 1.0)) @ vec.T


#: a parent's value within this many posterior spreads of 0 is not told from "off" (a 95 %
#: interval that holds 0): a parameter acting only through it is then not identified
THROUGH_SDS = 2.0


def unidentified(expl: Explanation, theta: np.ndarray, post: np.ndarray, cov: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(post, cov) of ``expl`` at ``theta`` (SI, (P,)) with each parameter that acts only
    through a parent (``expl.through``) given its prior spread, uncorrelated, where the
    parent's value lies within :data:`THROUGH_SDS` posterior spreads of 0. Why: the
    parameter's column is proportional to the parent's value (a payload's position moves
    the CoM by mass x / m), so its Laplace spread is ~sqrt(s_p^2 + v^2 s_m^2) / |m| (s_p:
    the data's spread of the product, s_m the parent's, v the value): a local curvature of
    a bilinear surface, finite at any m != 0, while the data allow m = 0 where the parameter
    acts on nothing (a position of no payload). "Determined" would then be the
    parametrisation's, not the data's."""
    names = list(expl.parameter_names)
    sd = np.asarray(expl.sd, float)
    post, cov = post.copy(), cov.copy()
    for child, parent in expl.through:
        c, q = names.index(child), names.index(parent)
        if abs(theta[q]) <= THROUGH_SDS * post[q]:
            post[c] = sd[c]
            cov[c, :] = cov[:, c] = 0.0
            cov[c, c] = sd[c] ** 2
    return post, cov


def log_evidence(prob: Problem, vec: np.ndarray, h: np.ndarray, at_bound: int) -> float:
    """The log evidence :func:`laplace` gives ``prob``'s explanation (the same arguments):
    log Z = -1/2 |vec|^2 - 1/2 log det H - 1/2 log det A + log pi, a value at a bound
    keeping half the Laplace volume (log 2 per value into log det H); -inf where H is
    singular."""
    if len(prob.expl.mean):
        # a value at a bound: the posterior there is half a Gaussian, half the Laplace volume
        logdet_h = np.linalg.slogdet(h)[1] + 2.0 * np.log(2.0) * at_bound
    else:
        logdet_h = 0.0
    if not np.isfinite(logdet_h):
        # H holds the prior's identity rows, so it is singular only where the fit ended on the
        # wall of values that make no rigid vehicle (:meth:`Problem.stacked`: a constant
        # residual, a zero Jacobian): no fit, no evidence (not +inf, which would win)
        return -np.inf
    return (-0.5 * float(vec @ vec) - 0.5 * logdet_h - 0.5 * prob.marg.logdet
            + prob.expl.log_prior)


class PendingEvidence:
    """A screened row whose :class:`Evidence` is built only where it is kept
    (:func:`screened`: most rows within the cut are fitted to convergence, and their
    screened Evidence would be dropped unread): ``log_z`` (:func:`log_evidence`) at once,
    :meth:`evidence` (:func:`laplace` of the same arguments: the same numbers) on demand.
    ``screened`` and ``step_converged`` as :class:`Evidence`'s, carried over to it."""

    def __init__(self, prob: Problem, z: np.ndarray, vec: np.ndarray, h: np.ndarray,
                 at_bound: int):
        self._args = (prob, z, vec, h, at_bound)
        self.log_z = log_evidence(prob, vec, h, at_bound)
        self.screened = False
        self.step_converged = False

    def evidence(self) -> Evidence:
        ev = laplace(*self._args)
        ev.screened, ev.step_converged = self.screened, self.step_converged
        return ev


def laplace(prob: Problem, z: np.ndarray, vec: np.ndarray, h: np.ndarray, at_bound: int
            ) -> Evidence:
    """The :class:`Evidence` of ``prob``'s explanation at ``z`` (its parameters in prior
    units, (P,)): ``vec`` the stacked residual there (:meth:`Problem.stacked`), ``h`` (P, P)
    the posterior precision in z units (JᵀJ), ``at_bound`` how many values lie at a bound.

    log Z = -1/2 |vec|^2 - 1/2 log det H - 1/2 log det A + log pi (:mod:`quadsim.gap.evidence`,
    module doc); a value at a bound keeps half the Laplace volume (log 2 per value into
    log det H). Posterior spreads sd sqrt(diag H^-1), H's eigenvalues floored at the
    prior's 1 (:func:`posterior_cov`): never wider than the prior, and no direction of H
    hides another's spread; a parameter acting only through a parent that the data do not
    tell from 0 gets its prior spread (:func:`unidentified`). ``ms``: each channel's mean squared
    residual over sigma_c^2 (the stacked residual times sqrt(tau_c)); for a reading that
    shifts the rotor speeds (the flight's rotor delay, shared or its own), over the samples
    whose shifted read lies inside the log, on every channel, and its slow part likewise
    (:func:`inside_reads`). A wind reading also gets its air force
    (:func:`_air_force`)."""
    states, reference, expl = prob.states, prob.reference, prob.expl
    names_all = reference.candidate.parameter_names
    chans = len(reference.sigma)
    mean, sd = np.asarray(expl.mean), np.asarray(expl.sd)
    if len(mean):
        cov = sd[:, None] * posterior_cov(h) * sd[None, :]
        post = np.sqrt(np.clip(np.diag(cov), 0, None))
    else:
        post, cov = np.zeros(0), np.zeros((0, 0))
    theta = mean + sd * z
    if getattr(expl, "through", ()):
        post, cov = unidentified(expl, theta, post, cov)
    log_z = log_evidence(prob, vec, h, at_bound)
    n = prob.marg.shape[0]
    resid = vec[:n].reshape(-1, chans) * np.sqrt(reference.tau)
    keys = expl.parameter_names
    shift = {names_all[k]: float(prob.s_all[k] * d)
             for k, d in zip(prob.keep, vec[n:n + len(prob.keep)])}
    own = [expl.name == "signal_delay" or k != "delay.rotor" for k in keys]
    # the states' time step (s), the slow part's; None: no time base
    timed = None if getattr(states, "t", None) is None or len(states.t) < 2 \
        else float(states.t[1] - states.t[0])
    # what the reading leaves: over the samples whose shifted rotor read lies inside the log
    # (inside_reads: the mirror fill beyond its end is no residual, on every channel that
    # reads the shifted speeds); the likelihood above keeps every sample
    inside = inside_reads(states.t, float(theta[-1])) if expl.shift and timed else None
    left = resid if inside is None else resid[inside]
    ms = np.mean(left ** 2, axis=0)
    ev = Evidence(expl, dict(zip(keys, map(float, theta))), dict(zip(keys, map(float, post))),
                  dict(zip(keys, map(float, sd))),
                  {k: bool(p < DETERMINED * q) for k, p, q, o in zip(keys, post, sd, own) if o},
                  log_z, ms, np.mean(resid, axis=0) * reference.sigma,
                  shared_shift=shift, slow=None if timed is None else slow_ms(left, timed),
                  slow_window=None if timed is None else slow_window(timed),
                  post_cov=cov, prior_pull=0.5 * float(np.dot(z, z)))
    if expl.name == "wind":
        ev.air_force = _air_force(states, reference, prob.shared,
                                  own_effects(expl, np.clip(theta, prob.lower, prob.upper)),
                                  prob.memo)
    return ev


def evaluate(states, reference: Reference, explanations: list[Explanation],
             start_delay_s: float = 0.0, *, full: bool = False,
             memo: dict | None = None, fit=None,
             signal_sd: float | None = None) -> list[Evidence]:
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
    ``start_delay_s`` is one of its points). ``signal_sd`` (s): the wide prior's spread the
    grid spans (None: "signal_delay"'s among ``explanations``, 0 without it). The grid, and
    so every shared delay's start, depends on it: a caller that weighs a list in parts (one
    explanation per worker) passes the whole list's, so that each part starts where the
    whole does.

    Each explanation is first screened by one Gauss-Newton step and fully fitted only where
    it can matter (:func:`screened`); ``full=True`` fits every one with
    :func:`quadsim.gap.evidence.full_fit`, or with ``fit`` (the same arguments: stacked
    flights' own nuisance parameters, :mod:`quadsim.gap.diagnose`). ``memo``: the residual
    parts and the shared Jacobian kept from an earlier call on the same flight and reference
    (:func:`quadsim.gap.evidence.choose`)."""
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
    if signal_sd is None:
        signal_sd = float(wide.sd[-1]) if wide is not None else 0.0
    if null is not None:
        starts = delay_starts(inputs.problem(null), signal_sd, start_delay_s)
    if not full:
        return screened(inputs, explanations, starts)
    fit = full_fit if fit is None else fit
    return [fit(inputs, e, starts[1] if e.name == "signal_delay" else starts[0])
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
    :class:`~quadsim.gap.evidence.Problem` (its delay under the references' tight prior);
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
    cost = np.array([_grid_cost(null, float(d)) for d in grid])
    near = (np.abs(grid) <= reach + 1e-12) | (np.abs(grid - hint_s) <= reach + 1e-12)
    shared = float(grid[near][np.argmin((cost + (grid / sd) ** 2)[near])])
    own = float(grid[np.argmin(cost + (grid / signal_sd) ** 2)]) if signal_sd > 0 else hint_s
    return shared, own


def _kept_for(prob: Problem, kind: str, key: tuple, compute):
    """``compute()``, kept in ``prob``'s memo under ``kind`` and ``key`` (a key that names
    the explanation by name and variant, as :meth:`Problem.residual`'s does) while the
    flight's states, reference and marginal are the same objects: what the drag law's choice
    (:func:`choose`) computed for "no difference" serves the flight's evaluation after it
    where that asks for the same (the same numbers: the same inputs). No memo: computed."""
    if prob.memo is None:
        return compute()
    store = prob.memo.setdefault(kind, {})
    refs = (prob.states, prob.reference, prob.marg)
    hit = store.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], refs)):
        return hit[1]
    value = compute()
    store[key] = (refs, value)
    return value


def _grid_cost(null: Problem, delay_s: float) -> float:
    """The profiled cost of ``null`` (its prior term apart) with the rotor delay at
    ``delay_s`` (s): one point of :func:`delay_starts`' grid, kept per flight
    (:func:`_kept_for`: the drag law's choice and the evaluation after it share the points
    about zero and about the cross-correlation estimate). ``null``: a :class:`Problem`, or
    any with its ``cost`` and ``sd`` (kept only where it has a ``memo``)."""
    sd = float(null.sd[-1])

    def compute() -> float:
        z = np.array([delay_s / sd])
        return null.cost(z) - float(z @ z)

    if getattr(null, "memo", None) is None:       # no memo (or a stand-in without one)
        return compute()
    return _kept_for(null, "delay_grid", (null.expl.name, null.expl.variant, delay_s, sd),
                     compute)


class Columns:
    """Per-flight pieces every explanation's linear model shares (module doc, 2.): the
    reference residual (N C,) at theta_ref with the rotor speeds read a delay later
    (:meth:`base`), the rotor delay's column there (:meth:`delay`), and the shared Jacobian
    ``jac`` (N C, M) with ``index`` (shared parameter name -> column).

    ``inputs``: the flight's :class:`~quadsim.gap.evidence.FitInputs` (its memo keeps the
    shifted states); ``null``: the "no difference" explanation, whose fixed-only parts and
    replaced groups make the shared base model (the reference model, or it under a flight's
    drag law, :mod:`quadsim.gap.evidence`); None: the reference model. ``delay_s``: the delay
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
        if self.fixed:      # as problem.shared_effects: the base's effects always stay
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


#: the explanation's own parameters that scale the vehicle's principal moments
#: (:mod:`quadsim.effects.inertia_error`: I'_ii = (1 + e_i) I_ii)
INERTIA_KEYS = ("inertia_error.xx", "inertia_error.yy", "inertia_error.zz")
#: relative tolerance of the triangle inequality: the vehicle's own check's
#: (:data:`quadsim.vehicle.params.TRIANGLE_RTOL`, :func:`~quadsim.vehicle.params.inertia_problems`)
WALL_TOL = TRIANGLE_RTOL


@dataclass(frozen=True)
class InertiaWall:
    """The triangle inequality of the vehicle's principal moments (no rigid body has
    I_a + I_b < I_c) as linear functions of a step x (P,) in z from a point: per axis c as
    the largest, ``g_c = g0_c + g[c] . x = sum_(a != c) I_a - I_c`` (kg m^2), exact where
    the explanation's own inertia errors are the only values it fits that move the inertia
    (:func:`inertia_wall`). ``scale``: the largest moment at the point (kg m^2)."""

    g: np.ndarray
    g0: np.ndarray
    scale: float

    def crossed(self, values: np.ndarray) -> bool:
        """Whether ``values`` (3,) of ``g`` leave the physical set (beyond :data:`WALL_TOL`)."""
        return bool(np.min(values) < -WALL_TOL * self.scale)

    def on(self, values: np.ndarray) -> bool:
        """Whether ``values`` (3,) of ``g`` lie on the wall (within :data:`WALL_TOL`)."""
        return bool(np.min(values) <= WALL_TOL * self.scale)


def inertia_wall(prob: Problem, start: np.ndarray) -> InertiaWall | None:
    """The :class:`InertiaWall` of ``prob`` about ``start`` (z, (P,)), or None where the
    explanation fits no inertia error (:data:`INERTIA_KEYS`), fits another effect too (its
    values might move the inertia), or the rest of its vehicle has a non-diagonal inertia
    (the principal moments are then not linear in the errors). With I the inertia of the
    shared and the explanation's other effects, the moments at theta are (1 + e_i) I_ii,
    e_i = mean + sd z (the fitted axes; a fixed one at its fixed value)."""
    expl = prob.expl
    names = list(expl.parameter_names)
    if not any(n in INERTIA_KEYS for n in names) or any(
            fitted and name != "inertia_error" for name, _, fitted in expl.parts):
        return None
    theta = np.clip(prob.mean + prob.sd * start, prob.lower, prob.upper)
    own = own_effects(expl, theta)
    error = next(e for e in own if e.name == "inertia_error")
    try:
        inertia = np.asarray(EffectSet(tuple(prob.shared) + tuple(
            e for e in own if e.name != "inertia_error")).apply_to_params(
                prob.reference.params).inertia, float)
    except ModelError:
        return None
    if np.any(inertia - np.diag(np.diag(inertia))):
        return None
    base = np.diag(inertia)
    moments = base * (1.0 + np.array([error.xx, error.yy, error.zz]))
    slope = np.zeros((3, len(start)))          # d moment_i / d z_k
    for k, n in enumerate(names):
        if n in INERTIA_KEYS:
            i = INERTIA_KEYS.index(n)
            slope[i, k] = base[i] * prob.sd[k]
    sign = 1.0 - 2.0 * np.eye(3)               # row c: +1 for a != c, -1 for c
    return InertiaWall(sign @ slope, sign @ moments, float(np.max(moments)))


def idle_parameters(prob: Problem, z: np.ndarray) -> set:
    """The parameters of ``prob``'s explanation that act on nothing at ``z`` (prior units):
    each that acts only through a parent (``Explanation.through``: a payload's position
    through its mass, a propeller's speed exponent through its change) whose value there
    (clipped to its bounds, as :meth:`Problem.residual` builds it) is exactly 0. Their
    column of the residual's Jacobian is zero: the residual a step in them gives is the one
    at ``z`` itself (the effect multiplies them by the parent's 0, or raises 1 + 0 to them),
    which the forward difference would evaluate only to subtract it."""
    through = getattr(prob.expl, "through", ())
    if not through:
        return set()
    names = list(prob.expl.parameter_names)
    theta = np.clip(prob.mean + prob.sd * z, prob.lower, prob.upper)
    return {child for child, parent in through if theta[names.index(parent)] == 0.0}


def jacobian_columns(prob: Problem, cols: Columns, start: np.ndarray, base: np.ndarray,
                     signs: np.ndarray, *, which=None, out: np.ndarray | None = None
                     ) -> np.ndarray:
    """The weighted residual's Jacobian (N C, P) in z at ``start`` (module doc, 2.);
    one-sided differences of :data:`STEP` towards ``signs`` (P,) (turned round at a bound
    and where it would cross the inertia's wall, :class:`InertiaWall`), zero without an
    evaluation for a parameter that acts on nothing there (:func:`idle_parameters`);
    ``base``: the residual at ``start``; only the columns ``which`` (bool (P,), default all)
    into ``out`` (default a new array). At the reference model the shared parts serve: the
    delay's column, and a replaced group's from the shared Jacobian (taken without the
    delay: a column of the linear model only, the cost is evaluated at the step)."""
    expl, delay = prob.expl, _shared_point(prob, cols, start)
    jac = np.empty((base.size, len(start))) if out is None else out
    wall = inertia_wall(prob, start)
    idle = idle_parameters(prob, start)
    for k, key in enumerate(expl.parameter_names):
        if which is not None and not which[k]:
            continue
        group = key.split(".")[0]
        if key in idle:
            jac[:, k] = 0.0
        elif delay is not None and key == "delay.rotor":
            jac[:, k] = cols.delay(delay, float(prob.sd[k]), signs[k])
        elif delay is not None and group in expl.replaces:
            jac[:, k] = cols.jac[:, cols.index[key]] * prob.sd[k]
        else:
            z = start.copy()
            h = signs[k] * STEP
            if not prob.z_lo[k] <= z[k] + h <= prob.z_hi[k] or (
                    wall is not None and wall.crossed(wall.g0 + wall.g[:, k] * h)):
                h = -h
            z[k] += h
            jac[:, k] = (prob.residual(z) - base) / h
    return jac


def linear_step(prob: Problem, start: np.ndarray, base: np.ndarray, jac: np.ndarray):
    """The bounded minimum of the linear model ``r(z) ~ base + jac (z - start)`` of the
    stacked cost: (z1 (P,), its predicted cost, the stacked Jacobian's Gauss-Newton precision
    H = AᵀA (P, P; A the stacked Jacobian, N C + K + P rows), the count of values at a bound,
    the inertia's wall counted as one where z1 is held on it: module doc, 2.). The linear
    model's triangle R, Qᵀb and remainder come from :func:`gram_factor` (from the Gram
    matrix, without forming A), or :func:`qr_factor` where that is not positive definite."""
    try:
        r, qb, rest, h = gram_factor(prob.marg, start, base, jac)
    except np.linalg.LinAlgError:
        r, qb, rest, h = qr_factor(prob.marg, start, base, jac)
    lower, upper = prob.z_lo - start, prob.z_hi - start
    # lsq_linear's own first step: the unconstrained solution, returned when inside the
    # bounds (the same numbers, without its checks and wrappers)
    x = np.linalg.lstsq(r, -qb, rcond=-1)[0]
    if np.all((x >= lower) & (x <= upper)):
        active = 0
    else:
        step = lsq_linear(r, -qb, bounds=(lower, upper), method="bvls")
        x, active = step.x, int(np.count_nonzero(step.active_mask))
    wall = inertia_wall(prob, start)
    if wall is not None and wall.crossed(wall.g0 + wall.g @ x):
        # across the inertia's wall: the same quadratic's minimum on it (InertiaWall)
        row = int(np.argmin(wall.g0 + wall.g @ x))
        on = plane_step(r, qb, wall.g[row], -float(wall.g0[row]), bounds=(lower, upper))
        if on is not None and not wall.crossed(wall.g0 + wall.g @ on):
            x = on
            active = int(np.count_nonzero((x <= lower) | (x >= upper))) + 1
    predicted = rest + float(np.sum((qb + r @ x) ** 2))
    return start + x, predicted, h, active


def qr_factor(marg: Marginal, start: np.ndarray, base: np.ndarray, jac: np.ndarray):
    """(R (P, P), Qᵀb (P,), |b - Q Qᵀb|^2, AᵀA (P, P)) of the linear model's stacked least
    squares |A x + b|^2, A = [aug; du; I] the profiled columns ``jac`` (N C, P) through
    ``marg`` (:meth:`Marginal.profile`) over the prior's identity rows, b = [aug0; du0;
    ``start``] the profiled ``base`` (N C,): one Householder QR of [A b] (R only, LAPACK
    geqrf in place, :func:`_upper_factor`; no Q of the tall matrix is formed)."""
    n = len(start)
    aug0, du0 = marg.profile(base)
    aug, du = marg.profile(jac)
    # [A b] written column-major at once (the layout LAPACK factors in place): the same
    # numbers as ``np.column_stack([a, b])`` copied to column-major, without the two copies
    ab = np.empty((len(aug) + len(du) + n, n + 1), order="F")
    ab[:len(aug), :n] = aug
    ab[len(aug):len(aug) + len(du), :n] = du
    ab[len(aug) + len(du):, :n] = np.eye(n)
    ab[:len(aug0), n] = aug0
    ab[len(aug0):len(aug0) + len(du0), n] = du0
    ab[len(aug0) + len(du0):, n] = start
    a = ab[:, :n].copy()
    rb = _upper_factor(ab, overwrite=True)
    return rb[:n, :n], rb[:n, n], float(rb[n, n] ** 2), a.T @ a


def gram_factor(marg: Marginal, start: np.ndarray, base: np.ndarray, jac: np.ndarray):
    """:func:`qr_factor`'s four results from the Gram matrix of [A b] instead of A itself:
    with F = [jac base] (N C, P + 1), C = jᵀF and Y = A_m^-1 C (A_m = I + jᵀj, the
    marginal's), the profiled rows give [aug aug0]ᵀ[aug aug0] + [du du0]ᵀ[du du0] = FᵀF - CᵀY
    (aug = F + j du, du = -Y: FᵀF - 2 CᵀY + YᵀA_mY); the prior rows add [I start]ᵀ[I
    start]. Its upper Cholesky factor U (UᵀU = [A b]ᵀ[A b]) is the R of [A b] up to the
    rows' signs, which neither the step nor its cost see: R = U[:P, :P], Qᵀb = U[:P, P],
    the remainder U[P, P]^2. Two passes over the tall arrays (jᵀF, FᵀF) where the QR makes
    several and forms A; the same numbers up to round-off of the order of the condition
    number of AᵀA times 1e-16 (tests/test_fast_paths_weighing.py). Raises LinAlgError where
    the Gram matrix is not positive definite to round-off (b in the span of A: the caller
    factors A itself then)."""
    n = len(start)
    c_jac, (c_base, y_base) = marg.jt(jac), marg.moment(base)
    y_jac = marg.solve(c_jac)
    m = np.empty((n + 1, n + 1))
    m[:n, :n] = jac.T @ jac - c_jac.T @ y_jac + np.eye(n)
    m[:n, n] = m[n, :n] = jac.T @ base - c_jac.T @ y_base + start
    m[n, n] = float(base @ base) - float(c_base @ y_base) + float(start @ start)
    u = np.linalg.cholesky(m).T
    if not np.all(np.isfinite(u)):
        raise np.linalg.LinAlgError("gram_factor: not finite")
    return u[:n, :n], u[:n, n], float(u[n, n] ** 2), m[:n, :n].copy()


def _upper_factor(m: np.ndarray, overwrite: bool = False) -> np.ndarray:
    """R (K, K) of the QR factorisation of ``m`` (M, K), M >= K: LAPACK geqrf, the call
    ``numpy.linalg.qr(m, mode="r")`` makes (the same numbers), without its wrapper's
    copies and workspace query (most of its cost on these thin matrices). ``overwrite``:
    ``m`` (column-major float64) is factored in place, its contents lost; else a copy."""
    geqrf = get_lapack_funcs(("geqrf",), (m,))[0]
    work = m if overwrite and m.flags.f_contiguous and m.dtype == np.float64 else \
        np.array(m, order="F")                      # a copy: m stays
    qr, _, _, info = geqrf(work, overwrite_a=True)
    if info != 0:
        raise np.linalg.LinAlgError(f"geqrf: illegal value in argument {-info}")
    return np.triu(qr[:m.shape[1]])


def linearised(prob: Problem, cols: Columns, start: np.ndarray
               ) -> tuple[Evidence, np.ndarray, float]:
    """One Gauss-Newton step of ``prob`` from ``start`` (module doc, 2.): (the
    :class:`Evidence` at the step, the step z1, how far the linear model's cost there was
    off, cost units): :func:`screen_step` with its evidence built."""
    pending, z1, miss = screen_step(prob, cols, start)
    return pending.evidence(), z1, miss


def screen_step(prob: Problem, cols: Columns, start: np.ndarray
                ) -> tuple[PendingEvidence, np.ndarray, float]:
    """:func:`linearised` with the evidence at the step as a :class:`PendingEvidence` (its
    log Z at once, the :class:`Evidence` built only where the screen keeps the row). A
    one-sided column (the rotor delay's kink) that the step leaves on the other side is
    recomputed on that side."""
    base = _base(prob, cols, start)
    z1, predicted, h, active = _signed_step(prob, cols, start, base)
    vec = prob.stacked(z1)
    miss = abs(float(vec @ vec) - predicted)
    return PendingEvidence(prob, z1, vec, h, active), z1, miss


def _second_reach(prob: Problem, cols: Columns, z1: np.ndarray) -> float:
    """What a coupled explanation with kin (module doc, 3.) can reach by a second
    Gauss-Newton step from its first one ``z1``, where the parameter another acts through
    has moved and the other's column is no longer zero: the screened evidence there plus
    half its miss (-inf where the step fails). Taken only where neither its own reach nor
    its kin has it fitted already; it only decides whether the explanation is fitted, and
    the fit starts from ``z1`` as before."""
    try:
        ev, _, miss = screen_step(prob, cols, z1)
    except (ModelError, np.linalg.LinAlgError):
        return -np.inf
    return ev.log_z + 0.5 * miss if np.isfinite(miss) else -np.inf


def _signed_step(prob: Problem, cols: Columns, start: np.ndarray, base: np.ndarray):
    signs = np.ones(len(start))
    jac = jacobian_columns(prob, cols, start, base, signs)
    z1, predicted, h, active = linear_step(prob, start, base, jac)
    flip = (z1 < start) & (signs > 0)
    flip &= np.array([k == "delay.rotor" for k in prob.expl.parameter_names])
    if np.any(flip):
        signs[flip] = -1.0
        jac = jacobian_columns(prob, cols, start, base, signs, which=flip, out=jac)
        z1, predicted, h, active = linear_step(prob, start, base, jac)
    return z1, predicted, h, active


def refined(prob: Problem, cols: Columns, z: np.ndarray) -> Evidence:
    """The MAP fit of ``prob`` from ``z`` by projected Gauss-Newton steps (Jacobian by
    forward differences at each iterate, the bounded linear step, halved up to 4 times until
    the cost falls), until the cost falls by less than :data:`CONVERGED` or after
    :data:`MAX_STEPS` steps; the Laplace evidence at the optimum with the last Jacobian
    (the inertia's wall counted as a bound where the optimum lies on it, :func:`linear_step`)."""
    vec = prob.stacked(z)
    cost = float(vec @ vec)
    h = None
    for _ in range(MAX_STEPS):
        base = prob.residual(z)
        z_new, _, h, active = _signed_step(prob, cols, z, base)
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
    if h is None:
        base = prob.residual(z)
        _, _, h, active = linear_step(prob, z, base, jacobian_columns(
            prob, cols, z, base, np.ones(len(z))))
    else:
        wall = inertia_wall(prob, z)
        active = int(np.count_nonzero((z <= prob.z_lo) | (z >= prob.z_hi))) + int(
            wall is not None and wall.on(wall.g0))
    return prob.evidence(z, vec, h, active)


def _refined_coupled(prob: Problem, cols: Columns, z1: np.ndarray, delay_s: float
                     ) -> Evidence:
    """:func:`refined` of a coupled explanation from the linear step ``z1`` and, where that
    step raised the cost above the prior centre's, from the centre too (the shared rotor
    delay kept at ``z1``'s): the better evidence. Why: the step cannot see what a coupled
    parameter reaches, and a wrong start leads the Gauss-Newton steps into another basin;
    some explanations need the step's start, others the centre's."""
    # the step's stacked residual first: the refined fit starts by asking for it again
    # (kept as the explanation's last residual), after which it would be evaluated anew
    a = prob.stacked(z1)
    first = refined(prob, cols, z1)
    centre = prob.start(delay_s)
    if prob.expl.shift and prob.expl.name != "signal_delay":
        centre[-1] = z1[-1]
    if prob.cost(centre) >= float(a @ a):
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
    ``rows`` its Evidence (a :class:`PendingEvidence` for a screened step; None where the
    step failed), ``starts`` the step z1 a refined fit
    starts from (None: exact already, or no step), ``weight`` the log weight it counts with
    towards the best (log Z; "no difference" plus its prior), ``reach`` what a fit could
    reach (screened log Z + miss / 2; inf where the step failed), ``miss`` how far the
    linear model's cost at the step was off (cost units; inf where there is no step)."""

    rows: list
    starts: list
    weight: list
    reach: list
    miss: list = dataclasses.field(default_factory=list)

    def add(self, row, start, weight: float, reach: float, miss: float = np.inf) -> None:
        self.rows.append(row)
        self.starts.append(start)
        self.weight.append(weight)
        self.reach.append(reach)
        self.miss.append(miss)


def _null_fit(inputs: FitInputs, cols: Columns, null: Explanation, shared_start: float
              ) -> Evidence:
    """Step 1 of the module doc: "no difference" with the flight's rotor delay, fitted to
    convergence from ``shared_start``; sets ``cols.delay_s`` to its delay, or to
    ``shared_start`` where the delay lies beyond :data:`DELAY_GRID_SDS` prior spreads (there
    it absorbs a gap rather than timing the log). The fit is kept per flight and start
    (:func:`_kept_for`): the drag law's choice fits the references' law's "no difference"
    first, and the evaluation under that law starts it at the same delay on about half of
    the flights."""
    prob = inputs.problem(null)
    z0 = prob.start(shared_start)
    fitted = dataclasses.replace(_kept_for(
        prob, "null_fit", (null.name, null.variant, z0.tobytes()),
        lambda: refined(prob, cols, z0)))      # a copy: each caller's rows their own
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
            ev, z1, miss = screen_step(prob, cols, start)
        except (ModelError, np.linalg.LinAlgError):
            ev, z1, miss = None, None, np.inf
        # what a fit could reach: the screened evidence plus half the linear model's miss
        out.add(ev, z1, -np.inf if ev is None else ev.log_z,
                np.inf if ev is None or not np.isfinite(miss) else ev.log_z + 0.5 * miss,
                miss)
    return out


#: the linear model's miss (cost units: |cost(z1) - predicted|) at or below which the
#: screen's step z1 is taken as the converged fit (:func:`converged_steps`): log Z off by a
#: two-thousandth along the step; the refined fit from such a step moved log Z by at most
#: 0.014 on the real mixed flights (CHANGELOG.md: Docstrings as contracts)
STEP_MISS = 1e-3
#: the margin (log-evidence units) stated for a converged step's log Z against its refined
#: fit's: 3.5 x the largest move measured (:data:`STEP_MISS`)
STEP_LOG_Z = 0.05
#: the most the converged steps of one flight weigh together, each as exp(reach + STEP_LOG_Z
#: - best) (its posterior weight over the best's at most): with every one off by at most
#: STEP_LOG_Z, no probability the judge prints moves by more than
#: 2 (e^0.05 - 1) 0.04 / (1 - (e^0.05 - 1) 0.04) = 0.0041 < 0.005 (:func:`converged_steps`)
STEP_SHARE = 0.04


def converged_steps(explanations: list, screening: Screening) -> set:
    """The indices of the explanations whose screen step is kept as their converged fit
    (no :func:`refined` fit): not coupled (its step sees what it reaches), a step there, its
    linear model's miss at most :data:`STEP_MISS`, the lightest first while their weights
    exp(reach + :data:`STEP_LOG_Z` - best) sum to at most :data:`STEP_SHARE` (best: the
    screen's best log weight, which the refined fits only raise).

    Why the probabilities move by less than 0.005: a probability the judge prints is a sum
    of posterior weights e^w over their total Z >= e^best. Where the kept steps' log Z are
    each off by at most d = STEP_LOG_Z and weigh at most s = STEP_SHARE e^best together,
    numerator and total each move by at most (e^d - 1) s Z, so the ratio by at most
    2 (e^d - 1) s / (1 - (e^d - 1) s) = 0.0041. d is a measured margin, not a proof: a step
    whose linear model is exact along it may still sit off the optimum where the cost is
    flat across it (STEP_MISS, measured). A reading within -log(STEP_SHARE) + STEP_LOG_Z =
    3.3 log units of the best is always refined (it alone weighs more than STEP_SHARE)."""
    best = max(screening.weight)
    cands = sorted((screening.reach[k], k) for k, e in enumerate(explanations)
                   if not e.coupled and screening.rows[k] is not None
                   and screening.starts[k] is not None
                   and np.isfinite(screening.miss[k]) and screening.miss[k] <= STEP_MISS)
    out, total = set(), 0.0
    for reach, k in cands:
        total += float(np.exp(reach + STEP_LOG_Z - best))
        if total > STEP_SHARE:
            break
        out.add(k)
    return out


def _matters(inputs: FitInputs, cols: Columns, explanations: list, k: int,
             screening: Screening, cut: tuple[float, float | None]) -> bool:
    """Step 3 of the module doc: whether explanation ``k`` is fitted to convergence, with
    ``cut`` = (the best log weight so far, the best before any coupled fit): its reach
    within :data:`SCREEN_CUT` of the best; a coupled one whose kin matters
    (:func:`_kin_matters`) or whose second step reaches the cut; any other whose first
    step's linear model missed by more than the cut, its reach within twice the cut, and
    its second step within the cut (module doc, 3.)."""
    best, before = cut
    expl, row, start = explanations[k], screening.rows[k], screening.starts[k]
    if row is None or screening.reach[k] >= best - SCREEN_CUT:
        return True
    if expl.coupled and _kin_matters(expl, explanations, screening, before):
        return True
    if expl.coupled:
        return bool(expl.kin and start is not None and _second_reach(
            inputs.problem(expl), cols, start) >= best - SCREEN_CUT)
    # a step whose linear model missed by more than the cut itself cannot place the
    # explanation against the cut: a second step from it decides; only within twice the
    # cut, so that the extra steps stay with readings near it (module doc, 3.)
    return bool(start is not None and screening.miss[k] > SCREEN_CUT
                and screening.reach[k] >= best - 2.0 * SCREEN_CUT
                and _second_reach(inputs.problem(expl), cols, start) >= best - SCREEN_CUT)


def _fit_to_convergence(inputs: FitInputs, cols: Columns, expl: Explanation,
                        start: np.ndarray | None, delay: float) -> Evidence:
    """:func:`refined` (coupled: :func:`_refined_coupled`) from the step ``start``; the full
    fit (:func:`~quadsim.gap.evidence.full_fit`) where there is no step or the refined fit
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
    kept = converged_steps(explanations, screening)
    for k in order:
        expl = explanations[k]
        if expl is null or (rows[k] is not None and screening.starts[k] is None):
            continue
        if expl.coupled and before is None:
            before = best
        if not _matters(inputs, cols, explanations, k, screening, (best, before)):
            rows[k].screened = True
        elif k in kept:      # the step is its fit (converged_steps); it weighs in as it is
            rows[k].step_converged = True
        else:
            delay = start_delay_s if expl.name == "signal_delay" else cols.delay_s
            rows[k] = _fit_to_convergence(inputs, cols, expl, screening.starts[k], delay)
            best = max(best, rows[k].log_z)
    return [row.evidence() if isinstance(row, PendingEvidence) else row for row in rows]


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


#: removed names, refused with what to write instead (CHANGELOG.md lists each)
__getattr__ = refuse_moved(__name__, {
    "read_inside": "was removed: what a reading leaves counts the samples of "
                   "`inside_reads(t, delay_s)` (None: all of them); take the mean square over "
                   "that mask"})
