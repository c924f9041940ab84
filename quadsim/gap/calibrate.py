"""The reference model: the nominal parameter set calibrated on the reference flights, with
its residual statistics as the noise model of every later comparison.

A flight's gap is what it does that *this* model does not. Whatever every reference flight
shares -- the real thrust and drag factors, the command -> speed map, the motors' lag, rotor
drag, the real inertia, aerodynamic rate damping -- is absorbed here once, so it no longer
leaks into each flight's comparison (a 53 ms motor lag is then judged against the
references' own 7 ms, not against zero).

Stages
------
1. Static command -> speed map per rotor (:func:`quadsim.gap.motor_map.fit_motor_map`) on the
   references (commands logged).
2. One bounded least-squares fit (:func:`quadsim.gap.fitting.fit_candidate`) of the shared
   parameters :data:`SHARED` on all reference flights together: relative b and d
   (``nominal_refit``; d by instrumental variables), the rotor-drag coefficient, the
   relative inertia error xx, yy, zz, rate damping x, y, z, the rotors' spin inertia
   (gyroscopic torque) and, with commands, the motor time constant and, with a battery
   voltage log, the speed per command following vbat / V_full (the map "with lag and
   voltage"). On the 20 real nominal Crazyflie flights, a reference model without the last
   two left every nominal flight judged against the others named ``gyroscopic`` (0.3-0.5 g
   cm^2) or ``battery_sag`` (V_full 3.7 V): effects every nominal flight shares; a steady
   wind (vx, vy: every nominal flight showed the same 2.5 mN air force along world +y).
   Then :data:`REFINE_STEPS` pooled Gauss-Newton steps (:func:`_refine`). Its values are theta_ref, its standard errors se_pool (correlation-widened).
3. Between-flight scatter: one Gauss-Newton step from theta_ref on each reference flight
   alone gives that flight's value theta_j and standard error se_j; the scatter is the
   method-of-moments random-effect variance ``tau^2 = max(0, var_j(theta_j) - mean_j se_j^2)``.
   The *reference uncertainty* of a parameter is ``s_ref = sqrt(se_pool^2 + tau^2)``: what a
   new nominal flight may show (the pooled value is known to se_pool, a flight scatters by
   tau).
4. Noise model per channel c (Fx Fy Fz Mx My Mz in N, N m; rotor_1..R in rad/s): sigma_c =
   RMS of the calibrated model's residual over the reference flights (so a systematic model
   error all references share counts as "normal"), and the integrated autocorrelation time
   tau_c (samples at the fit rate, 1 + 2 sum rho_k up to the first rho < 0.05): a flight of
   N samples carries N_eff,c = N / tau_c independent samples on that channel.
5. Lack-of-fit statistics: per reference flight and channel the log of its mean squared
   residual over sigma_c^2; their mean per channel and one spread pooled over channels
   (degrees of freedom C (n - 1)); a flight is compared with them in :mod:`.judge`.
6. Signal delays (:mod:`quadsim.logs.delays`): each signal's mean and spread over the
   references (ms).

Example::

    >>> ref = calibrate(prepare(nominal_logs, params), params)
    >>> ref.theta, ref.s_ref, ref.sigma        # shared values, their uncertainty, noise
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import InputError
from ..vehicle.params import VehicleParams
from .baseline import BASELINE  # noqa: F401  (registers the nominal_refit pseudo-effect)
from .fitting import (
    Candidate,
    _bounds,
    _correlation_time,
    _typical,
    fit_candidate,
    fit_motor_map,
    noise_floor,
    noise_scale,
    residuals,
)

__all__ = ["SHARED", "Reference", "calibrate", "shared_candidate", "weighted_residual",
           "jacobian", "FD_STEP"]

#: shared parameter groups (effect, fitted parameters); motor_lag only with commands.
SHARED = (("nominal_refit", ("thrust", "drag")),
          ("rotor_drag", ("coefficient",)),
          ("inertia_error", ("xx", "yy", "zz")),
          ("rate_damping", ("x", "y", "z")),
          ("gyroscopic", ("rotor_inertia",)),
          ("wind", ("vx", "vy")),
          ("motor_lag", ("time_constant",)),
          ("battery_sag", ("full_voltage",)))

#: groups that need logged commands (they act on the command -> speed channel) ...
NEEDS_COMMANDS = {"motor_lag", "battery_sag"}
#: ... and a logged battery voltage (the speed per command follows vbat / V_full).
NEEDS_VBAT = {"battery_sag"}

#: finite-difference step of the Jacobians, in units of each parameter's typical size
#: (:func:`quadsim.gap.fitting._typical`): the same relative step the fits use (diff_step).
FD_STEP = 1e-3


def shared_candidate(rotor: bool, vbat: bool = False) -> Candidate:
    """The shared parameters as one candidate: :data:`SHARED` less the groups the logs
    cannot show (no commands: motor lag and battery; no voltage: battery)."""
    parts = tuple((name, {}, fitted) for name, fitted in SHARED
                  if (rotor or name not in NEEDS_COMMANDS) and (vbat or name not in NEEDS_VBAT))
    return Candidate("reference", parts)


@dataclass
class Reference:
    """The calibrated reference model and its noise model (module doc).

    ``params``: the nominal set with the data's motor map; ``candidate``/``theta``: the shared
    parameters and their values (theta_ref); ``se_pool``, ``scatter``: their pooled standard
    error and between-flight spread (``s_ref`` combines both); ``sigma`` (C,): residual RMS
    per channel (N, N m, rad/s); ``tau`` (C,): correlation time per channel (samples);
    ``lof_mean`` (C,), ``lof_sd``, ``lof_dof``: lack-of-fit statistics; ``delays_ms``: signal
    -> (mean, sd, count) over the references; ``names``: the reference flights."""

    params: VehicleParams
    rotor: bool
    candidate: Candidate
    theta: np.ndarray
    se_pool: np.ndarray
    scatter: np.ndarray
    sigma: np.ndarray
    tau: np.ndarray
    lof_mean: np.ndarray
    lof_sd: float
    lof_dof: int
    delays_ms: dict
    names: list
    identified: dict

    @property
    def s_ref(self) -> np.ndarray:
        return np.sqrt(self.se_pool ** 2 + self.scatter ** 2)

    @property
    def weights(self) -> np.ndarray:
        """Per-channel weight of a squared residual: 1 / (sigma_c^2 tau_c)."""
        return 1.0 / (self.sigma ** 2 * self.tau)

    def values(self) -> dict:
        return dict(zip(self.candidate.parameter_names, map(float, self.theta)))

    def effects(self, theta: np.ndarray | None = None) -> list:
        return self.candidate.effects(self.theta if theta is None else theta)


def weighted_residual(states, reference: Reference, effects: list) -> np.ndarray:
    """Residual (N, C) of ``effects`` on ``states``, each channel times
    ``1 / (sigma_c sqrt(tau_c))``: its squared sum is the log-likelihood's -2x (module doc)."""
    r = residuals(states, reference.params, effects, rotor_channel=reference.rotor)
    return r * np.sqrt(reference.weights)


def jacobian(states, reference: Reference, columns: list[int], build) -> np.ndarray:
    """Forward-difference Jacobian (N C, len(columns)) of the weighted residual with respect
    to the shared parameters ``columns`` at theta_ref (``build(theta)`` -> effects)."""
    typical = _typical(reference.candidate, reference.params)
    _, upper = _bounds(reference.candidate, reference.params)
    base = weighted_residual(states, reference, build(reference.theta)).ravel()
    out = np.empty((base.size, len(columns)))
    for j, k in enumerate(columns):
        theta = reference.theta.copy()
        h = FD_STEP * typical[k]
        if theta[k] + h > upper[k]:      # a value at its upper bound: step down
            h = -h
        theta[k] += h
        out[:, j] = (weighted_residual(states, reference, build(theta)).ravel() - base) / h
    return out


def _scatter(flights, reference: Reference) -> np.ndarray:
    """Method-of-moments between-flight variance of each shared parameter (module doc,
    stage 3): one Gauss-Newton step per reference flight from theta_ref."""
    k = len(reference.theta)
    values, variances = [], []
    for f in flights:
        jac = jacobian(f, reference, list(range(k)), reference.candidate.effects)
        r = weighted_residual(f, reference, reference.effects()).ravel()
        info = jac.T @ jac
        cov = np.linalg.pinv(info)
        values.append(reference.theta - cov @ (jac.T @ r))
        variances.append(np.clip(np.diag(cov), 0, None))
    values, variances = np.asarray(values), np.asarray(variances)
    if len(values) < 2:
        return np.zeros(k)
    return np.sqrt(np.clip(values.var(axis=0, ddof=1) - variances.mean(axis=0), 0, None))


#: pooled Gauss-Newton steps after the bounded fit (:func:`_refine`).
REFINE_STEPS = 2


def _refine(states, params, rotor, cand, theta, sigma) -> np.ndarray:
    """Pooled Gauss-Newton steps from the bounded fit, summing each flight's information
    (the bounded fit stops after a few dozen evaluations of 12-14 parameters; on the real
    nominal Crazyflie flights it left the rotors' spin inertia at its bound 0 while every
    flight alone asked for 0.3-0.5 g cm^2). Levenberg-Marquardt steps with a unit ridge in
    units of each parameter's typical size, clipped to the bounds."""
    lower, upper = _bounds(cand, params)
    typical = _typical(cand, params)
    dt = float(states[0].t[1] - states[0].t[0])
    for k, name in enumerate(cand.parameter_names):
        if name == "motor_lag.time_constant":      # fitting.fit_candidate: the Heun sub-step
            lower[k] = max(lower[k], dt / 4)
    probe = Reference(params, rotor, cand, theta.copy(), np.zeros_like(theta),
                      np.zeros_like(theta), sigma, np.ones_like(sigma),
                      np.zeros_like(sigma), 1.0, 1, {}, [], {})
    for _ in range(REFINE_STEPS):
        info = np.zeros((len(theta), len(theta)))
        grad = np.zeros(len(theta))
        for f in states:
            jac = jacobian(f, probe, list(range(len(theta))), cand.effects)
            r = weighted_residual(f, probe, probe.effects()).ravel()
            info += jac.T @ jac
            grad += jac.T @ r
        # Levenberg-Marquardt: a unit ridge in units of each parameter's typical size, so a
        # direction the data do not fix (a wind with no drag to act through) does not move
        info_z = info * np.outer(typical, typical) + np.eye(len(theta))
        step = -typical * np.linalg.solve(info_z, typical * grad)
        probe.theta = np.clip(probe.theta + step, lower, upper)
    return probe.theta


def calibrate(flights, params: VehicleParams) -> Reference:
    """The reference model from prepared reference flights (:class:`quadsim.gap.diagnose.Flight`
    or their ``fit`` states); see the module doc. Raises InputError for fewer than two."""
    states = [getattr(f, "fit", f) for f in flights]
    if len(states) < 2:
        raise InputError("--reference: give at least 2 nominal flights")
    rotor = all(s.command is not None for s in states)
    if rotor:
        params = fit_motor_map(states, params)
    dt = float(states[0].t[1] - states[0].t[0])
    sigma0 = noise_scale(np.concatenate([residuals(s, params, [], rotor_channel=rotor)
                                         for s in states]), dt, floor=noise_floor(params, rotor))
    vbat = rotor and all(s.vbat is not None and bool(np.all(np.isfinite(s.vbat)))
                         for s in states)
    cand = shared_candidate(rotor, vbat)
    fit = fit_candidate(cand, states, params, sigma0, rotor_channel=rotor, max_nfev=40)
    theta = _refine(states, params, rotor, cand, fit.theta, sigma0)
    per_flight = [residuals(s, params, cand.effects(theta), rotor_channel=rotor)
                  for s in states]
    pooled = np.concatenate(per_flight)
    sigma = np.maximum(np.sqrt(np.mean(pooled ** 2, axis=0)), noise_floor(params, rotor))
    tau = np.array([np.mean([_correlation_time(r[:, [c]] / sigma[c]) for r in per_flight])
                    for c in range(pooled.shape[1])])
    log_ms = np.log([np.mean(r ** 2, axis=0) / sigma ** 2 for r in per_flight])
    mean = log_ms.mean(axis=0)
    dof = max(1, log_ms.size - log_ms.shape[1])
    spread = float(np.sqrt(np.sum((log_ms - mean) ** 2) / dof))
    delays = {}
    for key in {k for f in flights for k in getattr(f, "delays_ms", {})}:
        v = [f.delays_ms[key] for f in flights if getattr(f, "delays_ms", {}).get(key) is not None]
        if v:
            delays[key] = (float(np.mean(v)), float(np.std(v, ddof=1)) if len(v) > 1 else 0.0,
                           len(v))
    ref = Reference(params, rotor, cand, theta, fit.stderr.copy(),
                    np.zeros_like(fit.theta), sigma, tau, mean, spread, dof, delays,
                    [getattr(f, "name", "") for f in flights],
                    dict(zip(cand.parameter_names, map(bool, fit.identifiable))))
    ref.scatter = _scatter(states, ref)
    return ref
