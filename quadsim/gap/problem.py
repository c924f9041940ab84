"""One explanation's fit on one flight, and its Laplace evidence.

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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve, get_lapack_funcs
from scipy.optimize import least_squares

from ..core.errors import ModelError
from .discrepancy import centre_term, columns
from .explanations import DETERMINED, Explanation, own_effects
from .fitting import parameter_bounds as fit_bounds
from .fitting import residuals
from .memo import memoised
from .reference import Reference, rotor_spectra, shifted
from .rotor_channel import min_time_constant

__all__ = [
    "DELAY_BOUND_S",
    "FULL_FIT_EVALUATIONS",
    "FULL_FIT_STEP",
    "Evidence",
    "FitInputs",
    "Marginal",
    "Problem",
    "flight_residual",
    "full_fit",
    "laplace",
    "parameter_bounds",
    "read_inside",
    "shifted_view",
]

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
    screen's linearised evidence (:mod:`quadsim.gap.screen`), not a converged fit."""

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


class Marginal:
    """The shared parameters not fitted by an explanation, marginalised linearly
    (:mod:`quadsim.gap.evidence`, module doc): ``j`` = J_s diag(s_ref) (N C, K), ``chol`` the
    Cholesky factor of A = I + jᵀj, ``logdet`` = log det A."""

    def __init__(self, jac: np.ndarray, s_ref: np.ndarray):
        self.j = jac * s_ref
        a = np.eye(len(s_ref)) + self.j.T @ self.j
        self.chol = cho_factor(a)
        self.logdet = 2.0 * float(np.sum(np.log(np.diag(self.chol[0]))))
        # cho_solve's own LAPACK call (the same numbers), without its per-call checks and
        # batch wrapper: most of its cost on these small systems, called thousands of times
        self._potrs = get_lapack_funcs(("potrs",), (self.chol[0],))[0] if len(s_ref) else None
        self._last: tuple | None = None

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

    def _profile(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rhs = self.j.T @ r
        if self._potrs is None:
            du = -cho_solve(self.chol, rhs)
        else:
            x, info = self._potrs(self.chol[0], rhs, lower=self.chol[1])
            if info != 0:
                raise ValueError(f"illegal value in {-info}th argument of internal potrs")
            du = -x
        return r + self.j @ du, du


def parameter_bounds(expl: Explanation, reference: Reference, dt: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of ``expl``'s parameters in their SI units: each effect parameter's
    declared bounds narrowed by its fit window for this vehicle (the effect's facts,
    :func:`quadsim.gap.fitting.parameter_bounds`: a mass offset within -1/2 .. 2 x the
    vehicle's mass, a payload within the rotor arm, a CoM shift within half of it, the thrust
    curve within the hover thrust per rad/s and :func:`~quadsim.gap.priors.curve_quadratic_bounds`);
    a motor lag of at least :func:`~quadsim.gap.rotor_channel.min_time_constant` of the fit
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


def _shared_effects(reference: Reference, replaces: tuple) -> tuple[list, list[int]]:
    """The reference effects without the replaced groups, and the marginalised columns."""
    names = reference.candidate.parameter_names
    keep = [k for k, n in enumerate(names) if n.split(".")[0] not in replaces]
    everything, n_base = reference.effects(), len(reference.candidate.base)
    # effects already in the model (held-out mode's --effects-file) stay; an explanation
    # replaces only the fitted shared groups
    effects = everything[:n_base] + [e for e in everything[n_base:] if e.name not in replaces]
    return effects, keep


def _air_force(states, reference: Reference, effects: list, own: list) -> np.ndarray:
    """Mean air force (world, N; (3,)) of the flight's wind beyond the references' wind:
    the model wrench with the reading's own effects ``own`` less that with the references'
    wind, on the shared ``effects``."""
    from ..core.frames import rotate
    from .residual import model_wrench

    base = [e for e in reference.effects() if e.name == "wind"]   # the references' own
    with_wind, _, _ = model_wrench(states, reference.params, effects + own)
    without, _, _ = model_wrench(states, reference.params, effects + base)
    return np.mean(rotate(states.quat, with_wind - without), axis=0)


def flight_residual(states, reference: Reference, effects: list, memo: dict | None = None
                    ) -> np.ndarray:
    """:func:`quadsim.gap.reference.weighted_residual`, flattened (N C,), with the residual
    parts that repeat on one flight kept in ``memo`` (:func:`quadsim.gap.fitting.residuals`)."""
    r = residuals(states, reference.params, effects, rotor_channel=reference.rotor, memo=memo)
    r = r - centre_term(states, reference.discrepancy, r.shape[1], memo)
    return (r * np.sqrt(reference.weights)).ravel()


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
            self.shared, self.keep = _shared_effects(reference, expl.replaces)
        else:       # the same for every explanation that replaces the same groups
            kept = memo.setdefault("shared_effects", {})
            if expl.replaces not in kept:
                kept[expl.replaces] = _shared_effects(reference, expl.replaces)
            self.shared, self.keep = kept[expl.replaces]
        self.marg = self._marginal(jac, s_all)
        self.mean, self.sd = np.asarray(expl.mean), np.asarray(expl.sd)
        lower, upper = parameter_bounds(expl, reference, float(states.t[1] - states.t[0]))
        self.lower, self.upper = lower, upper
        self.z_lo, self.z_hi = (lower - self.mean) / self.sd, (upper - self.mean) / self.sd
        self.size = jac.shape[0] + self.marg.j.shape[1] + len(self.mean)

    def _marginal(self, jac: np.ndarray, s_all: np.ndarray) -> Marginal:
        """The marginal of the kept shared columns and the discrepancy's
        (:func:`quadsim.gap.discrepancy.columns`, unit spread: they are scaled by the
        coefficients' covariance factor already), after them; with a ``memo``, one per set
        of columns (most explanations keep them all) and Jacobian."""
        def build():
            extra = columns(self.states, self.reference.discrepancy, self.reference.weights,
                            self.memo)
            return Marginal(np.hstack([jac[:, self.keep], extra]),
                            np.concatenate([s_all[self.keep], np.ones(extra.shape[1])]))

        if self.memo is None:
            return build()
        kept = self.memo.setdefault("marginals", {})
        key = (id(jac), tuple(self.keep), s_all[self.keep].tobytes(),
               id(self.reference.discrepancy), self.reference.weights.tobytes())
        if key not in kept or kept[key][0] is not jac:
            kept[key] = (jac, build())
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
            return np.full(self.size, 1e3)
        aug, du = self.marg.profile(r)
        return np.concatenate([aug, du, z])

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
    return prob.evidence(fit.x, fit.fun, fit.jac.T @ fit.jac,
                         int(np.count_nonzero(fit.active_mask)))


def read_inside(t: np.ndarray, delay_s: float, resid: np.ndarray, ms: np.ndarray
                ) -> np.ndarray:
    """The rotor channels' mean square (R,) over the samples whose read ``t + delay_s`` (s)
    lies inside the log; ``ms`` where all or none do. ``resid`` (N, R): the rotor channels'
    residual. Beyond the log's ends a rotor log read later meets the mirror image of its
    samples (:func:`quadsim.gap.reference.read_later`): a fill that keeps the spectrum from
    ringing, not data, so it does not count in what a reading leaves. The likelihood keeps
    every sample (each reading's own delay would give each a different sample count)."""
    inside = (t + delay_s <= t[-1]) & (t + delay_s >= t[0])
    if inside.all() or not inside.any():
        return ms
    return np.mean(resid[inside] ** 2, axis=0)


def laplace(prob: Problem, z: np.ndarray, vec: np.ndarray, h: np.ndarray, at_bound: int
            ) -> Evidence:
    """The :class:`Evidence` of ``prob``'s explanation at ``z`` (its parameters in prior
    units, (P,)): ``vec`` the stacked residual there (:meth:`Problem.stacked`), ``h`` (P, P)
    the posterior precision in z units (JᵀJ), ``at_bound`` how many values lie at a bound.

    log Z = -1/2 |vec|^2 - 1/2 log det H - 1/2 log det A + log pi (:mod:`quadsim.gap.evidence`,
    module doc); a value at a bound keeps half the Laplace volume (log 2 per value into
    log det H). Posterior spreads sd sqrt(diag H^+). ``ms``: each channel's mean squared
    residual over sigma_c^2 (the stacked residual times sqrt(tau_c)); for a reading that fits
    the rotor delay, the rotor channels' over the samples read inside the log
    (:func:`read_inside`). A wind reading also gets its air force (:func:`_air_force`)."""
    states, reference, expl = prob.states, prob.reference, prob.expl
    names_all = reference.candidate.parameter_names
    chans = len(reference.sigma)
    mean, sd = np.asarray(expl.mean), np.asarray(expl.sd)
    if len(mean):
        # a value at a bound: the posterior there is half a Gaussian, half the Laplace volume
        logdet_h = np.linalg.slogdet(h)[1] + 2.0 * np.log(2.0) * at_bound
        post = sd * np.sqrt(np.clip(np.diag(np.linalg.pinv(h)), 0, None))
    else:
        logdet_h, post = 0.0, np.zeros(0)
    theta = mean + sd * z
    log_z = -0.5 * float(vec @ vec) - 0.5 * logdet_h - 0.5 * prob.marg.logdet + expl.log_prior
    n = prob.marg.j.shape[0]
    resid = vec[:n].reshape(-1, chans) * np.sqrt(reference.tau)
    keys = expl.parameter_names
    shift = {names_all[k]: float(prob.s_all[k] * d)
             for k, d in zip(prob.keep, vec[n:n + len(prob.keep)])}
    own = [expl.name == "signal_delay" or k != "delay.rotor" for k in keys]
    ms = np.mean(resid ** 2, axis=0)
    if expl.shift and reference.rotor and chans > 6:
        ms[6:] = read_inside(states.t, float(theta[-1]), resid[:, 6:], ms[6:])
    ev = Evidence(expl, dict(zip(keys, map(float, theta))), dict(zip(keys, map(float, post))),
                  dict(zip(keys, map(float, sd))),
                  {k: bool(p < DETERMINED * q) for k, p, q, o in zip(keys, post, sd, own) if o},
                  log_z, ms, np.mean(resid, axis=0) * reference.sigma,
                  shared_shift=shift)
    if expl.name == "wind":
        ev.air_force = _air_force(states, reference, prob.shared,
                                  own_effects(expl, np.clip(theta, prob.lower, prob.upper)))
    return ev
