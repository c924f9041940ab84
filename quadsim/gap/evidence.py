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
physical prior of a difference, :func:`~quadsim.gap.explanations.marginal_sd`), marginalised in closed form
around theta_ref (linear in theta_s, Jacobian J_s of the weighted residual): with
u = (theta_s - theta_ref) / s_ref, Ĵ = J_s diag(s_ref) and A = I + ĴᵀĴ the profile is
``|r + Ĵ du|^2 + |du|^2`` at ``du = -A^-1 Ĵᵀ r`` and the marginal adds ``-1/2 log det A``.
An explanation that gives a shared group a value of its own takes that group out of the
marginal and fits it with the wider prior N(theta_ref, s_ref^2 + w^2) (w: the prior spread
of a difference, :func:`quadsim.gap.explanations._prior_sd`). The rotor speeds' logging delay is shared as well, but
not linear at all over a few ms: every explanation fits it, with the references' spread
(:func:`quadsim.gap.explanations.reference_delay_sd`) as its prior; the reading "signal_delay" fits it with the wide
prior N(0, s^2 + (20 ms)^2).

Evidence (Laplace at the bounded least-squares optimum, parameters in units of their prior
spread, z = (theta - mu) / sd)::

    log Z = -1/2 (|aug(z)|^2 + |z|^2) - 1/2 log det H - 1/2 log det A + log pi

with H = JᵀJ of the stacked residual (the posterior precision in z units; -1/2 log det H is
the Occam factor log(posterior volume / prior volume); a value at a bound of its parameter
keeps half the volume, log 2 less) and pi the model prior: equal per
effect, split evenly among an effect's variants (one per rotor for a weak or canted rotor);
"no difference" is weighed against them in :func:`quadsim.gap.judge.posterior`. A parameter is *determined* by the data when its posterior spread is
below half its prior spread (:data:`quadsim.gap.explanations.DETERMINED`); only determined values are ever printed.

The explanations, their priors and the propeller coupling: :mod:`quadsim.gap.explanations`.

Example::

    >>> rows = evaluate(flight.fit, reference, explanations_for(reference, flight.fit))
    >>> [(e.name, e.log_z) for e in rows]
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve, get_lapack_funcs
from scipy.optimize import least_squares

from ..core.errors import ModelError
from .calibrate import Reference, jacobian, shifted
from .explanations import (  # re-exported: the evidence's public names
    DELAY_SD_S,
    DETERMINED,
    Explanation,
    _own_effects,
    explanations_for,
    marginal_sd,
    reference_determined,
)
from .fitting import _arm, curve_bound, effect_class, residuals
from .memo import _memo
from .priors import curve_quadratic_bounds
from .reference import rotor_spectra
from .rotor_channel import min_time_constant
from .screen import delay_starts, screened

__all__ = ["Explanation", "Evidence", "explanations_for", "evaluate", "marginal_sd",
           "DETERMINED", "DELAY_SD_S", "shifted", "reference_determined"]


@dataclass
class Evidence:
    """One explanation's result on one flight: MAP values, posterior and prior spreads,
    which values the data determine, log evidence, per-channel mean squared residual over
    sigma_c^2 (``ms``) and the air force of a wind reading (world, N)."""

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

    @property
    def name(self) -> str:
        return self.explanation.name


class _Marginal:
    """The shared parameters not fitted by an explanation, marginalised linearly (module doc)."""

    def __init__(self, jac: np.ndarray, s_ref: np.ndarray):
        self.j = jac * s_ref
        a = np.eye(len(s_ref)) + self.j.T @ self.j
        self.chol = cho_factor(a)
        self.logdet = 2.0 * float(np.sum(np.log(np.diag(self.chol[0]))))
        # cho_solve's own LAPACK call (the same numbers), without its per-call checks and
        # batch wrapper: most of its cost on these small systems, called thousands of times
        self._potrs = get_lapack_funcs(("potrs",), (self.chol[0],))[0] if len(s_ref) else None

    def profile(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rhs = self.j.T @ r
        if self._potrs is None:
            du = -cho_solve(self.chol, rhs)
        else:
            x, info = self._potrs(self.chol[0], rhs, lower=self.chol[1])
            if info != 0:
                raise ValueError(f"illegal value in {-info}th argument of internal potrs")
            du = -x
        return r + self.j @ du, du


def _bounds(expl: Explanation, reference: Reference, dt: float):
    lower, upper = [], []
    for name, _, fitted in expl.parts:
        cls = effect_class(name)
        specs = {p.name: p for p in cls.parameters}
        for p in fitted:
            lo, hi = specs[p].lower, specs[p].upper
            if name == "motor_lag":
                lo = max(lo, min_time_constant(dt))
            if name == "mass_offset" and p == "mass":
                lo, hi = max(lo, -0.5 * reference.params.mass), min(hi, 2 * reference.params.mass)
            elif name == "mass_offset":         # a payload within the rotors' span
                lo, hi = max(lo, -_arm(reference.params)), min(hi, _arm(reference.params))
            if name == "com_offset":
                arm = _arm(reference.params)
                lo, hi = max(lo, -0.5 * arm), min(hi, 0.5 * arm)
            if name == "thrust_curve" and p == "linear":
                bound = curve_bound(reference.params)
                lo, hi = max(lo, -bound), min(hi, bound)
            if name == "thrust_curve" and p == "quadratic":
                low, high = curve_quadratic_bounds(reference.params)
                lo, hi = max(lo, low), min(hi, high)
            lower.append(lo)
            upper.append(hi)
    if expl.shift:
        lower.append(-0.1)
        upper.append(0.1)
    return np.asarray(lower, float), np.asarray(upper, float)


def _shared_effects(reference: Reference, replaces: tuple) -> tuple[list, list[int]]:
    """The reference effects without the replaced groups, and the marginalised columns."""
    names = reference.candidate.parameter_names
    keep = [k for k, n in enumerate(names) if n.split(".")[0] not in replaces]
    everything, n_base = reference.effects(), len(reference.candidate.base)
    # effects already in the model (held-out mode's --effects-file) stay; an explanation
    # replaces only the fitted shared groups
    effects = everything[:n_base] + [e for e in everything[n_base:] if e.name not in replaces]
    return effects, keep


def _air_force(states, reference, effects, own) -> np.ndarray:
    """Mean air force (world, N) of the flight's wind beyond the references' wind."""
    from ..core.frames import rotate
    from .residual import model_wrench

    base = [e for e in reference.effects() if e.name == "wind"]   # the references' own
    with_wind, _, _ = model_wrench(states, reference.params, effects + own)
    without, _, _ = model_wrench(states, reference.params, effects + base)
    return np.mean(rotate(states.quat, with_wind - without), axis=0)


def evaluate(states, reference: Reference, explanations: list[Explanation],
             start_delay_s: float = 0.0, *, full: bool = False,
             memo: dict | None = None) -> list[Evidence]:
    """Log evidence of every explanation on one flight's (decimated) ``states``.

    With a rotor-delay reading, every explanation fits the flight's rotor delay too: with
    the references' prior (:func:`reference_delay_sd`) as a shared parameter, or with the
    wide prior as the reading "signal_delay". Both start at the best point of a grid of
    delays under their prior (:func:`quadsim.gap.screen.delay_starts`; ``start_delay_s``,
    the cross-correlation estimate against the references', is one of its points).

    Each explanation is first screened by one Gauss-Newton step and fully fitted only where
    it can matter (:mod:`quadsim.gap.screen`); ``full=True`` fits every one. ``memo``: the
    residual parts and the shared Jacobian kept from an earlier call on the same flight and
    reference (:func:`quadsim.gap.drag_law.choose`)."""
    names = list(reference.candidate.parameter_names)
    s_all = marginal_sd(reference)
    memo = {} if memo is None else memo   # residual parts shared by evaluations on this flight
    kept = memo.get("evidence.jacobian")
    if kept is None or kept[0] is not states or kept[1] is not reference:
        kept = memo["evidence.jacobian"] = (states, reference, jacobian(
            states, reference, list(range(len(names))), reference.candidate.effects, memo=memo))
    jac = kept[2]
    starts = (0.0, start_delay_s)
    null = next((e for e in explanations if e.name == "no_difference" and e.shift), None)
    wide = next((e for e in explanations if e.name == "signal_delay"), None)
    if null is not None:
        starts = delay_starts(Problem(states, reference, null, jac, s_all, memo),
                              float(wide.sd[-1]) if wide is not None else 0.0, start_delay_s)
    if not full:
        return screened(states, reference, explanations, jac, names, s_all,
                        starts, problem=Problem, fit_one=_fit_one,
                        residual=flight_residual, memo=memo)
    return [_fit_one(states, reference, e, jac, s_all, names,
                     starts[1] if e.name == "signal_delay" else starts[0])
            for e in explanations]


def flight_residual(states, reference: Reference, effects: list, memo: dict | None = None
                    ) -> np.ndarray:
    """:func:`quadsim.gap.calibrate.weighted_residual`, flattened (N C,), with the residual
    parts that repeat on one flight kept in ``memo`` (:func:`quadsim.gap.fitting.residuals`)."""
    r = residuals(states, reference.params, effects, rotor_channel=reference.rotor, memo=memo)
    return (r * np.sqrt(reference.weights)).ravel()


class Problem:
    """One explanation's fit on one flight (module doc): ``residual(z)`` the weighted
    residual (N C,) at z (prior units), ``stacked(z)`` the vector whose squared norm is the
    fit's cost (profiled residual, marginalised shared shifts, z); ``z_lo``, ``z_hi`` the
    bounds; ``shared``/``keep``/``marg`` the reference effects it keeps and their marginal."""

    def __init__(self, states, reference: Reference, expl: Explanation, jac: np.ndarray,
                 s_all: np.ndarray, memo: dict | None = None):
        self.states, self.reference, self.expl = states, reference, expl
        self.memo = memo          # residual parts shared by evaluations on one flight
        if memo is None:
            self.shared, self.keep = _shared_effects(reference, expl.replaces)
        else:       # the same for every explanation that replaces the same groups
            kept = memo.setdefault("shared_effects", {})
            if expl.replaces not in kept:
                kept[expl.replaces] = _shared_effects(reference, expl.replaces)
            self.shared, self.keep = kept[expl.replaces]
        self.marg = self._marginal(jac, s_all)
        self.mean, self.sd = np.asarray(expl.mean), np.asarray(expl.sd)
        lower, upper = _bounds(expl, reference, float(states.t[1] - states.t[0]))
        self.lower, self.upper = lower, upper
        self.z_lo, self.z_hi = (lower - self.mean) / self.sd, (upper - self.mean) / self.sd
        self.size = jac.shape[0] + len(self.keep) + len(self.mean)

    def _marginal(self, jac: np.ndarray, s_all: np.ndarray) -> _Marginal:
        """The marginal of the kept shared columns; with a ``memo``, one per set of columns
        (most explanations keep them all) and Jacobian."""
        if self.memo is None:
            return _Marginal(jac[:, self.keep], s_all[self.keep])
        kept = self.memo.setdefault("marginals", {})
        key = (id(jac), tuple(self.keep), s_all[self.keep].tobytes())
        if key not in kept or kept[key][0] is not jac:
            kept[key] = (jac, _Marginal(jac[:, self.keep], s_all[self.keep]))
        return kept[key][1]

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
        own = _own_effects(self.expl, theta)
        flight = self.shifted(float(theta[-1])) if self.expl.shift else self.states
        r = flight_residual(flight, self.reference, self.shared + own, self.memo)
        if last is not None:
            last[key] = (np.array(z, dtype=float), r)
        return r

    def shifted(self, delay_s: float):
        """:func:`shifted` states, the same object for the same delay (``memo``)."""
        if self.memo is None:
            return shifted(self.states, delay_s)
        spectra = _memo(self.memo, ("spectra", id(self.states)), self.states,
                        lambda: rotor_spectra(self.states))
        return _memo(self.memo, ("shifted", id(self.states), delay_s), self.states,
                     lambda: shifted(self.states, delay_s, spectra))

    def stacked(self, z: np.ndarray) -> np.ndarray:
        try:
            r = self.residual(z)
        except ModelError:
            return np.full(self.size, 1e3)
        aug, du = self.marg.profile(r)
        return np.concatenate([aug, du, z])

    def start(self, start_delay_s: float = 0.0) -> np.ndarray:
        """z = 0 with the delay at ``start_delay_s``, inside the bounds."""
        z0 = np.zeros_like(self.mean)
        if self.expl.shift:
            z0[-1] = start_delay_s / self.sd[-1]
        return np.clip(z0, self.z_lo + 1e-6, self.z_hi - 1e-6)

    def evidence(self, z, vec, h, at_bound: int, names_all, s_all) -> Evidence:
        return laplace(self.states, self.reference, self.expl, self.marg, self.keep, s_all,
                       names_all, self.shared, z, vec, h, at_bound)


def _fit_one(states, reference: Reference, expl: Explanation, jac: np.ndarray,
             s_all: np.ndarray, names_all: list[str], start_delay_s: float,
             start: np.ndarray | None = None) -> Evidence:
    """One explanation's MAP fit and Laplace evidence (module doc); ``jac`` (N C, M): the
    weighted residual's Jacobian in the shared parameters ``names_all`` (spreads ``s_all``),
    of which those the explanation does not replace are marginalised. ``start``: where the
    fit starts (z units; default :meth:`Problem.start`)."""
    prob = Problem(states, reference, expl, jac, s_all)
    if not len(prob.mean):
        return prob.evidence(np.zeros(0), prob.stacked(np.zeros(0)), np.zeros((0, 0)), 0,
                             names_all, s_all)
    z0 = prob.start(start_delay_s) if start is None else np.clip(
        np.asarray(start, dtype=float), prob.z_lo + 1e-6, prob.z_hi - 1e-6)
    fit = least_squares(prob.stacked, z0, bounds=(prob.z_lo, prob.z_hi), diff_step=1e-3,
                        max_nfev=40, method="trf")
    return prob.evidence(fit.x, fit.fun, fit.jac.T @ fit.jac,
                         int(np.count_nonzero(fit.active_mask)), names_all, s_all)


def _read_inside(t: np.ndarray, delay_s: float, resid: np.ndarray, ms: np.ndarray
                 ) -> np.ndarray:
    """The rotor channels' mean square over the samples whose read ``t + delay_s`` lies inside
    the log (``ms`` where all or none do). Beyond the log's end a rotor log read later meets
    the mirror image of its last samples (:func:`quadsim.gap.reference.read_later`): a fill
    that keeps the spectrum from ringing, not data. Counted in a reading's residual statistic
    it raised what the reading leaves: quadcopter-sim's rotor log 27 ms late, read as
    ``signal_delay`` at 1.00 with the right 27 ms, left rotor 2 at 1.7x the references' RMS
    through its last 27 ms alone (a fast flight's speeds turn there), and the flight was
    ``unexplained``. The likelihood keeps every sample: each reading's own delay would give
    each a different sample count."""
    inside = (t + delay_s <= t[-1]) & (t + delay_s >= t[0])
    if inside.all() or not inside.any():
        return ms
    return np.mean(resid[inside] ** 2, axis=0)


def laplace(states, reference: Reference, expl: Explanation, marg: _Marginal, keep: list[int],
            s_all: np.ndarray, names_all: list[str], shared: list, z: np.ndarray,
            vec: np.ndarray, h: np.ndarray, at_bound: int) -> Evidence:
    """The Evidence of ``expl`` at ``z`` (module doc): ``vec`` the stacked residual there,
    ``h`` the posterior precision (z units), ``at_bound`` how many values lie at a bound."""
    chans = len(reference.sigma)
    mean, sd = np.asarray(expl.mean), np.asarray(expl.sd)
    if len(mean):
        # a value at a bound: the posterior there is half a Gaussian, half the Laplace volume
        logdet_h = np.linalg.slogdet(h)[1] + 2.0 * np.log(2.0) * at_bound
        post = sd * np.sqrt(np.clip(np.diag(np.linalg.pinv(h)), 0, None))
    else:
        logdet_h, post = 0.0, np.zeros(0)
    theta = mean + sd * z
    log_z = -0.5 * float(vec @ vec) - 0.5 * logdet_h - 0.5 * marg.logdet + expl.log_prior
    n = marg.j.shape[0]
    resid = vec[:n].reshape(-1, chans) * np.sqrt(reference.tau)
    keys = expl.parameter_names
    shift = {names_all[k]: float(s_all[k] * d) for k, d in zip(keep, vec[n:n + len(keep)])}
    own = [expl.name == "signal_delay" or k != "delay.rotor" for k in keys]
    ms = np.mean(resid ** 2, axis=0)
    if expl.shift and reference.rotor and chans > 6:
        ms[6:] = _read_inside(states.t, float(theta[-1]), resid[:, 6:], ms[6:])
    ev = Evidence(expl, dict(zip(keys, map(float, theta))), dict(zip(keys, map(float, post))),
                  dict(zip(keys, map(float, sd))),
                  {k: bool(p < DETERMINED * q) for k, p, q, o in zip(keys, post, sd, own) if o},
                  log_z, ms, np.mean(resid, axis=0) * reference.sigma,
                  shared_shift=shift)
    if expl.name == "wind":
        lower, upper = _bounds(expl, reference, float(states.t[1] - states.t[0]))
        ev.air_force = _air_force(states, reference, shared,
                                  _own_effects(expl, np.clip(theta, lower, upper)))
    return ev
