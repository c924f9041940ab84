"""Bounded nonlinear least squares on a tall residual, solved through its R factor.

:func:`compact_least_squares` is scipy's ``least_squares(fun, x0, bounds=..., method="trf",
x_scale=1.0, diff_step=...)`` with the default forward-difference Jacobian, for a residual
of many more samples ``m`` than parameters ``n`` (the calibration's 155,810 x 15-17). It
hands scipy's trust-region-reflective solver an orthogonally reduced problem of ``n + 1``
rows in place of the ``m`` rows:

    [f  J] = Q R        (thin QR, R (n+1, n+1) upper triangular, R[0, 0] = |f| >= 0)
    f_red = Qᵀ f = (|f|, 0, ..., 0),   J_red = Qᵀ J = R[:, 1:]

Every quantity the solver reads is invariant under the orthogonal ``Qᵀ``: the cost
``|f|²/2``, the gradient ``Jᵀf``, ``JᵀJ``, ``|J s|`` for any step ``s``, the singular values
and right singular vectors of the scaled, augmented Jacobian and ``Uᵀf``. So the iterates
are scipy's own up to rounding, while each iteration's SVD is of an (n+1) x n matrix
instead of an m x n one (the QR of ``[f J]`` costs about a quarter of that SVD).

One reading differs: the trust-region solver's full-rank test ``s_min > eps m s_max``
(``scipy.optimize._lsq.common.solve_lsq_trust_region``) reads ``m = n + 1`` here, so where
the scaled Jacobian's condition number lies between ``1 / (eps m)`` and ``1 / (eps (n+1))``
(about 3e10 to 2e14 for the calibration) a Gauss-Newton step is tried first where scipy
would go straight to the damped step; it is taken only where it lies inside the trust
region.

The forward differences are scipy's (``scipy.optimize._numdiff.approx_derivative``,
``method="2-point"``, ``rel_step=diff_step``, with ``bounds``), written out here so that the
full residual at each point is kept for the QR: step ``h_i = diff_step sign(x_i) |x_i|``
(``sign(0) = +1``), or ``sqrt(eps) sign(x_i) max(1, |x_i|)`` where that step vanishes in
floating point; a step that would leave the box turned the other way where it fits there,
else taken to the farther bound; the column ``(f(x + h_i e_i) - f(x)) / ((x_i + h_i) - x_i)``.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

EPS = float(np.finfo(np.float64).eps)


@dataclass(frozen=True)
class CompactResult:
    """What :func:`compact_least_squares` found. ``x`` (n,): the solution; ``cost``:
    ``|f(x)|² / 2``; ``fun`` (m,): the full residual ``f(x)``; ``jac`` (n+1, n): the R
    factor's Jacobian block ``Qᵀ J`` at ``x`` (not ``J`` itself: ``jacᵀ jac`` equals ``JᵀJ``
    and its column norms ``J``'s); ``status``, ``nfev``, ``njev``, ``active_mask``: scipy's
    (``nfev`` counts the solver's evaluations, not the differences')."""

    x: np.ndarray
    cost: float
    fun: np.ndarray
    jac: np.ndarray
    status: int
    nfev: int
    njev: int
    active_mask: np.ndarray


def forward_steps(x: np.ndarray, lower: np.ndarray, upper: np.ndarray, rel_step: float
                  ) -> np.ndarray:
    """The forward-difference steps (n,) scipy's ``approx_derivative(method="2-point",
    rel_step=rel_step, bounds=(lower, upper))`` takes at ``x`` (module doc)."""
    x = np.asarray(x, dtype=float)
    sign = (x >= 0).astype(float) * 2 - 1
    h = rel_step * sign * np.abs(x)
    h = np.where((x + h) - x == 0, EPS ** 0.5 * sign * np.maximum(1.0, np.abs(x)), h)
    if np.all((lower == -np.inf) & (upper == np.inf)):
        return h
    below, above = x - lower, upper - x
    out = h.copy()
    trial = x + h
    violated = (trial < lower) | (trial > upper)
    fitting = np.abs(h) <= np.maximum(below, above)
    out[violated & fitting] *= -1
    forward = (above >= below) & ~fitting
    out[forward] = above[forward]
    backward = (above < below) & ~fitting
    out[backward] = -below[backward]
    return out


class _Reduced:
    """The reduced problem's residual and Jacobian (module doc) around the full ``fun``,
    keeping the full residual of the point last evaluated and of the point whose Jacobian
    was last taken (the solver's current point)."""

    def __init__(self, fun: Callable[[np.ndarray], np.ndarray], n: int, *, bounds: tuple,
                 rel_step: float):
        self.fun, self.n, self.rel_step = fun, n, rel_step
        self.lower, self.upper = (np.asarray(b, dtype=float) for b in bounds)
        self.last: tuple | None = None      # (x, f) of the last evaluation
        self.current: tuple | None = None   # (x, f) where the Jacobian was last taken

    def full(self, x: np.ndarray) -> np.ndarray:
        """The full residual at ``x``: kept where it was just evaluated."""
        if self.last is not None and np.array_equal(self.last[0], x):
            return self.last[1]
        f = np.asarray(self.fun(x), dtype=float)
        self.last = (np.array(x, dtype=float), f)
        return f

    def residual(self, x: np.ndarray) -> np.ndarray:
        f = np.asarray(self.fun(x), dtype=float)
        self.last = (np.array(x, dtype=float), f)
        out = np.zeros(self.n + 1)
        out[0] = np.sqrt(float(f @ f))
        return out

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        from scipy.linalg import qr

        x = np.array(x, dtype=float)
        f = self.full(x)
        self.current = (x, f)
        h = forward_steps(x, self.lower, self.upper, self.rel_step)
        stacked = np.empty((f.size, self.n + 1), order="F")
        stacked[:, 0] = f
        for i in range(self.n):
            moved = x.copy()
            moved[i] = x[i] + h[i]
            stacked[:, i + 1] = (np.asarray(self.fun(moved), dtype=float) - f) \
                / ((x[i] + h[i]) - x[i])
        _, r = qr(stacked, mode="raw", overwrite_a=True, check_finite=False)
        r = np.array(r[: self.n + 1], dtype=float)
        if f.size < self.n + 1:         # fewer samples than n + 1: R's missing rows are 0
            r = np.vstack([r, np.zeros((self.n + 1 - r.shape[0], self.n + 1))])
        if r[0, 0] < 0:                 # Qᵀ f = (|f|, 0, ...): the residual's own sign
            r[0] = -r[0]
        return r[:, 1:]


def compact_least_squares(fun: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, *,
                          bounds: tuple, diff_step: float, max_nfev: int) -> CompactResult:
    """scipy's bounded ``least_squares(fun, x0, bounds=bounds, method="trf", x_scale=1.0,
    diff_step=diff_step, max_nfev=max_nfev)`` on the reduced problem of the module doc:
    the same iterates up to rounding (tests/test_compact_lsq.py), each iteration's SVD on
    n+1 rows. ``fun(x)`` -> the full residual (m,); ``bounds``: (lower, upper), each (n,)."""
    from scipy.optimize import least_squares

    x0 = np.asarray(x0, dtype=float)
    reduced = _Reduced(fun, len(x0), bounds=bounds, rel_step=diff_step)
    result = least_squares(reduced.residual, x0, jac=reduced.jacobian, bounds=bounds,
                           method="trf", x_scale=1.0, max_nfev=max_nfev)
    if reduced.current is not None and np.array_equal(reduced.current[0], result.x):
        full = reduced.current[1]
    else:                               # not reached by scipy 1.17's trf; kept for safety
        full = np.asarray(fun(result.x), dtype=float)
    return CompactResult(result.x, float(0.5 * (full @ full)), full, result.jac,
                         int(result.status), int(result.nfev), int(result.njev),
                         result.active_mask)


def wall_jacobian(prob, z: np.ndarray, step: float, *, prior: bool = True
                  ) -> tuple[np.ndarray | None, np.ndarray | None, bool]:
    """(``prob.stacked`` at ``z``, its forward-difference Jacobian (len, P), whether a step
    met the wall) with no difference taken across the wall of values that make no vehicle
    (a :class:`~quadsim.core.errors.ModelError`, which ``stacked`` answers with a constant
    1e3 per entry and counts in ``prob.walls``): column k by a step of ``step`` max(1,
    |z_k|) (z units, relative as the trust-region solver takes it), forward, turned back at
    the upper bound ``prob.z_hi`` or where the step meets the wall (within ``prob.z_lo``).
    A column whose steps meet the wall both ways keeps the prior's row only (the data say
    nothing there: that parameter's spread is its prior's; ``stacked`` ends with z, the
    prior's rows); ``prior=False``, for a vector with no prior's rows
    (:func:`quadsim.gap.fitting.fit_candidate`): that column stays zero. (None, None,
    False) where ``z`` itself lies beyond the wall (no fit). ``prob``: a
    :class:`quadsim.gap.evidence.Problem`, or any fit with ``stacked``, ``walls``,
    ``z_lo`` and ``z_hi`` (:func:`quadsim.gap.evidence.fitted_jacobian`). Here, beside the
    solver it serves, so that the fits of :mod:`.fitting` and :mod:`.evidence` share it
    without an import circle.

    Why: a difference across the wall is ~1e3 sqrt(len) / step, a precision ~1e16-1e20
    times the data's; its direction then swamps every other in the posterior (the
    Crazyflie's references: an off-centre payload fitted lighter than modelled by 0.17 g,
    whose inertia lies ~1e-3 prior spreads from I_x + I_y = I_z, came out "determined" to
    2e-12 kg and 2e-22 m; CHANGELOG)."""
    def at(point: np.ndarray) -> np.ndarray | None:
        walls = prob.walls
        row = prob.stacked(point)
        return None if prob.walls > walls else row

    base = at(z)
    if base is None:
        return None, None, False
    jac = np.zeros((base.size, len(z)))
    near = False
    for k in range(len(z)):
        h = step * max(1.0, abs(float(z[k])))
        for hk in ((h, -h) if z[k] + h <= prob.z_hi[k] else (-h, h)):
            point = z.copy()
            point[k] += hk
            if prob.z_lo[k] <= point[k] <= prob.z_hi[k]:
                row = at(point)
                if row is not None:
                    jac[:, k] = (row - base) / hk
                    break
            near = True
        else:
            if prior:
                jac[base.size - len(z) + k, k] = 1.0       # the prior's row of z_k
    return base, jac, near
