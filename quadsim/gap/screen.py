"""Linearised evidence of every explanation, and the cut that decides which ones get the
full fit (:func:`quadsim.gap.evidence.evaluate`).

The full fit of an explanation (:func:`quadsim.gap.evidence._fit_one`: bounded trust-region
least squares, finite-difference Jacobian) costs 20-40 evaluations of the flight's residual;
a flight has ~20 explanations, and most of them lie many orders of evidence below the best.
So every explanation first gets one Gauss-Newton step from its start z0 (z = 0: the
reference model at theta_ref; a "signal_delay" reading at its cross-correlation estimate)::

    r(z) ~ r(z0) + J (z - z0)

J's columns (prior units z, :class:`quadsim.gap.evidence.Problem`): for a shared group the
explanation gives a value of its own, the shared-parameter Jacobian the marginal already needs
(:func:`quadsim.gap.calibrate.jacobian`, once per flight); for the rotor delay every
explanation carries, one column per flight; for every other parameter one forward difference
(step :data:`STEP`, the full fit's ``diff_step``). The stacked cost (profiled residual,
marginalised shifts, z) is then quadratic, its bounded minimum z1 a small linear
least-squares problem (``scipy.optimize.lsq_linear``, bounded-variable). The residual is then
evaluated at z1 itself, and the *screened* evidence is the Laplace evidence
(:func:`quadsim.gap.evidence.laplace`) at z1 with the Gauss-Newton precision H = AᵀA: the
cost of a point the full fit can reach, so the full fit's optimum costs at most as much.

Cut (:func:`screened`): the full fit, started at z1, is run for every explanation whose
screened log weight (log Z; "no difference" with its prior, as in
:func:`quadsim.gap.judge.posterior`) lies within :data:`SCREEN_CUT` of the best screened
weight, and for every explanation whose linear model was off at z1 (predicted and evaluated
cost differ by more than :data:`NONLINEAR`: one Gauss-Newton step is no model of it there)
or whose step met a non-physical vehicle. Why that cannot move the verdict: a
reading below the cut has posterior odds against the best below exp(-SCREEN_CUT) by its
screened evidence; its screened cost is an upper bound of its fitted cost (the full fit
starts at z1 and only descends), and where the linear model held at z1 the full fit moves
the cost by less than NONLINEAR plus the Occam term's change (H at the optimum against H at
z1: equal for a linear model, within a few tenths of a log unit measured, docs/gap.md). With
SCREEN_CUT = log(1e4) + NONLINEAR + 2 such a reading would have to gain more than 9 log
units to reach a posterior of 1e-4: it stays below every threshold the judge uses
(READING_P 0.1, CONFIDENT 0.9). Its JSON entry keeps the screened values (marked
``"screened": true`` in :func:`quadsim.gap.judge.judge`'s posterior list).

``evaluate(..., full=True)`` fits every explanation (the reference path the equivalence
test compares with: tests/test_screen.py).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear

from ..core.errors import ModelError
from .calibrate import Reference, weighted_residual
from .evidence import Evidence, Explanation, Problem, _fit_one, shifted

__all__ = ["screened", "linearised", "SCREEN_CUT", "NONLINEAR", "STEP"]

#: forward-difference step in prior units (the full fit's ``diff_step``).
STEP = 1e-3
#: a linear model that misjudges the cost at its own step by more than this (cost units,
#: twice log-evidence units) sends its explanation to the full fit.
NONLINEAR = 2.0
#: log-weight margin below the best screened explanation within which the full fit is run
#: (module doc: posterior odds 1e-4, plus the linear model's allowed error, plus 2).
SCREEN_CUT = float(np.log(1e4)) + NONLINEAR + 2.0
#: Gauss-Newton steps of a refined fit at most, and the cost drop (cost units) below which
#: it has converged (a hundredth of a log-evidence unit: far below any posterior threshold).
MAX_STEPS = 8
CONVERGED = 0.02


class _Columns:
    """Per-flight pieces every explanation's linear model shares: the reference residual at
    theta_ref with the rotor speeds shifted by a delay, and the rotor-delay column there."""

    def __init__(self, states, reference: Reference, jac: np.ndarray, names_all: list[str]):
        self.states, self.reference, self.jac = states, reference, jac
        self.index = {n: k for k, n in enumerate(names_all)}
        self._base: dict[float, np.ndarray] = {}
        self._delay: dict[tuple, np.ndarray] = {}
        self.delay_s = 0.0          # the delay every explanation starts at (:func:`screened`)

    def base(self, delay_s: float) -> np.ndarray:
        if delay_s not in self._base:
            self._base[delay_s] = weighted_residual(shifted(self.states, delay_s),
                                                    self.reference,
                                                    self.reference.effects()).ravel()
        return self._base[delay_s]

    def delay(self, delay_s: float, sd: float, sign: float) -> np.ndarray:
        """d r / d z of the rotor delay at ``delay_s`` (prior spread ``sd``, s), one-sided
        towards ``sign``: the shifted speeds are interpolated between samples, so the
        residual is piecewise linear in the delay with a kink at every sample step."""
        key = (delay_s, sd, sign)
        if key not in self._delay:
            h = sign * STEP
            moved = weighted_residual(shifted(self.states, delay_s + h * sd), self.reference,
                                      self.reference.effects()).ravel()
            self._delay[key] = (moved - self.base(delay_s)) / h
        return self._delay[key]


def _shared_point(prob: Problem, cols: _Columns, z: np.ndarray) -> float | None:
    """The delay (s) at ``z`` when ``z`` is the reference model there (no own value moved
    and the delay one the per-flight pieces hold), else None."""
    own = len(z) - (1 if prob.expl.shift else 0)
    if np.any(z[:own]) or prob.expl.name == "signal_delay":
        return None
    if not prob.expl.shift:
        return 0.0
    delay = float(prob.mean[-1] + prob.sd[-1] * z[-1])
    return cols.delay_s if abs(delay - cols.delay_s) <= 1e-12 else None


def _base(prob: Problem, cols: _Columns, z: np.ndarray) -> np.ndarray:
    delay = _shared_point(prob, cols, z)
    return prob.residual(z) if delay is None else cols.base(delay)


def _columns(prob: Problem, cols: _Columns, start: np.ndarray, base: np.ndarray,
             signs: np.ndarray, which=None, out: np.ndarray | None = None) -> np.ndarray:
    """The weighted residual's Jacobian in z at ``start`` (module doc); one-sided
    differences towards ``signs``; only the columns ``which`` (default all) into ``out``
    (default a new array). At the reference model the shared parts serve: the
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


def _step(prob: Problem, start: np.ndarray, base: np.ndarray, jac: np.ndarray):
    """The bounded minimum of the linear model: (z1, its predicted cost, A, active count)."""
    n = len(start)
    aug0, du0 = prob.marg.profile(base)
    aug, du = prob.marg.profile(jac)
    a = np.vstack([aug, du, np.eye(n)])
    b = np.concatenate([aug0, du0, start])
    q, r = np.linalg.qr(a)
    qb = q.T @ b
    rest = float(b @ b - qb @ qb)
    step = lsq_linear(r, -qb, bounds=(prob.z_lo - start, prob.z_hi - start), method="bvls")
    predicted = rest + float(np.sum((qb + r @ step.x) ** 2))
    return start + step.x, predicted, a, int(np.count_nonzero(step.active_mask))


def linearised(prob: Problem, cols: _Columns, start: np.ndarray, names_all, s_all):
    """One Gauss-Newton step of ``prob`` from ``start`` (module doc): (Evidence at the step,
    the step z1, how far the linear model's cost there was off, cost units). A one-sided
    column (the rotor delay's kink) that the step leaves on the other side is recomputed on
    that side."""
    base = _base(prob, cols, start)
    z1, predicted, a, active = _signed_step(prob, cols, start, base)
    vec = prob.stacked(z1)
    miss = abs(float(vec @ vec) - predicted)
    return prob.evidence(z1, vec, a.T @ a, active, names_all, s_all), z1, miss


def _signed_step(prob: Problem, cols: _Columns, start: np.ndarray, base: np.ndarray):
    signs = np.ones(len(start))
    jac = _columns(prob, cols, start, base, signs)
    z1, predicted, a, active = _step(prob, start, base, jac)
    flip = (z1 < start) & (signs > 0)
    flip &= np.array([k == "delay.rotor" for k in prob.expl.parameter_names])
    if np.any(flip):
        signs[flip] = -1.0
        jac = _columns(prob, cols, start, base, signs, which=flip, out=jac)
        z1, predicted, a, active = _step(prob, start, base, jac)
    return z1, predicted, a, active


def refined(prob: Problem, cols: _Columns, z: np.ndarray, names_all, s_all) -> Evidence:
    """The MAP fit of ``prob`` from ``z`` by projected Gauss-Newton steps (Jacobian by
    forward differences at each iterate, the bounded linear step, halved until the cost
    falls), until the cost falls by less than :data:`CONVERGED` or after :data:`MAX_STEPS`
    steps; the Laplace evidence at the optimum with the last Jacobian."""
    vec = prob.stacked(z)
    cost = float(vec @ vec)
    a, active = None, 0
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
    if a is None:
        base = prob.residual(z)
        _, _, a, active = _step(prob, z, base, _columns(prob, cols, z, base,
                                                         np.ones(len(z))))
    return prob.evidence(z, vec, a.T @ a, active, names_all, s_all)


def screened(states, reference: Reference, explanations: list[Explanation], jac: np.ndarray,
             names_all: list[str], s_all: np.ndarray, start_delay_s: float = 0.0
             ) -> list[Evidence]:
    """Every explanation's Evidence: screened, and fully fitted where it can matter (module
    doc); ``jac`` the shared-parameter Jacobian at theta_ref."""
    cols = _Columns(states, reference, jac, names_all)
    effects = {e.name for e in explanations} - {"no_difference"}
    prior_null = float(np.log(max(1, len(effects))))
    rows, starts, weight, reach = [], [], [], []
    # the flight's own rotor delay under the reference model first (every explanation
    # carries it with the same prior): the others start there
    null = next((e for e in explanations if e.name == "no_difference" and e.shift), None)
    fitted = None
    if null is not None:
        prob = Problem(states, reference, null, jac, s_all)
        fitted = refined(prob, cols, prob.start(0.0), names_all, s_all)
        cols.delay_s = fitted.values["delay.rotor"]
    for expl in explanations:
        prob = Problem(states, reference, expl, jac, s_all)
        delay = start_delay_s if expl.name == "signal_delay" else 0.0
        if expl is null:
            rows.append(fitted)
            starts.append(None)
            weight.append(fitted.log_z + prior_null)
            reach.append(weight[-1])
            continue
        if not len(prob.mean):                        # nothing to fit: exact already
            rows.append(_fit_one(states, reference, expl, jac, s_all, names_all, delay))
            starts.append(None)
            weight.append(rows[-1].log_z + prior_null)
            reach.append(weight[-1])
            continue
        start = prob.start(delay)
        if expl.shift and expl is not null and expl.name != "signal_delay":
            start[-1] = np.clip((cols.delay_s - prob.mean[-1]) / prob.sd[-1],
                                prob.z_lo[-1], prob.z_hi[-1])
        try:
            ev, z1, miss = linearised(prob, cols, start, names_all, s_all)
        except (ModelError, np.linalg.LinAlgError):
            ev, z1, miss = None, None, np.inf
        rows.append(ev)
        starts.append(z1)
        weight.append(-np.inf if ev is None else ev.log_z)
        # what a fit could reach: the screened evidence plus half the linear model's miss
        reach.append(np.inf if ev is None or not np.isfinite(miss) else ev.log_z + 0.5 * miss)
    # most promising first: each refined fit can only raise the best weight, and with it
    # the cut for those after it
    best = max(weight)
    for k in sorted(range(len(explanations)), key=lambda k: -reach[k]):
        expl = explanations[k]
        if expl is null or (rows[k] is not None and starts[k] is None):
            continue
        if rows[k] is None or reach[k] >= best - SCREEN_CUT:
            delay = start_delay_s if expl.name == "signal_delay" else 0.0
            if starts[k] is None:
                rows[k] = _fit_one(states, reference, expl, jac, s_all, names_all, delay)
            else:
                prob = Problem(states, reference, expl, jac, s_all)
                rows[k] = refined(prob, cols, starts[k], names_all, s_all)
            best = max(best, rows[k].log_z)
        else:
            rows[k].screened = True
    return rows
