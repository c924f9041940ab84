"""Least-squares fits of rotor curves with 95 % confidence intervals, and held-out scoring.

Models of a rotor quantity y (thrust N, or torque N m) against speed Omega (rad/s):

=====================  ==========================  ===================================
name                   y(Omega)                    parameters (SI)
=====================  ==========================  ===================================
``quadratic``          b Omega^2                   b (N s^2/rad^2 or N m s^2/rad^2)
``quadratic+linear``   b Omega^2 + c Omega         b, c (N s/rad)
``quadratic+offset``   b Omega^2 + c0              b, c0 (N)
``power``              k Omega^n                   k (N (s/rad)^n), n (-)
=====================  ==========================  ===================================

The three polynomial models are linear in their parameters and solved exactly; the power law
uses :func:`scipy.optimize.least_squares`. Intervals are Student-t intervals from the
covariance s^2 (J^T J)^-1 (valid for independent, equal-variance noise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

from ..core.errors import InputError
from ..vehicle.guards import figure_of_merit  # noqa: F401  (re-exported)

__all__ = [
    "MODELS",
    "Fit",
    "HeldOutScore",
    "Ratio",
    "StandFit",
    "figure_of_merit",
    "fit_curve",
    "fit_ratio",
    "fit_thrust_stand",
    "held_out_scores",
]

# name -> parameter names (and their units given y in N)
MODELS: dict[str, tuple[str, ...]] = {
    "quadratic": ("b",),
    "quadratic+linear": ("b", "c"),
    "quadratic+offset": ("b", "c0"),
    "power": ("k", "n"),
}
_POWER_REF_SPEED = 500.0  # rad/s, scales the power law so the solver sees O(1) numbers


def _design(model: str, speed: np.ndarray) -> np.ndarray:
    columns = {"quadratic": [speed**2], "quadratic+linear": [speed**2, speed],
               "quadratic+offset": [speed**2, np.ones_like(speed)]}[model]
    return np.stack(columns, axis=-1)


@dataclass(frozen=True)
class Fit:
    """A fitted curve y(Omega).

    ``params`` (P,), ``cov`` (P, P), ``ci95`` (P, 2) lower/upper, ``residuals`` (N,)
    measured minus fitted, ``dof`` = N - P."""

    model: str
    names: tuple[str, ...]
    params: np.ndarray
    cov: np.ndarray
    ci95: np.ndarray
    residuals: np.ndarray
    dof: int

    def __getitem__(self, name: str) -> float:
        return float(self.params[self.names.index(name)])

    def interval(self, name: str) -> tuple[float, float]:
        """95 % interval of one parameter."""
        low, high = self.ci95[self.names.index(name)]
        return float(low), float(high)

    @property
    def rms(self) -> float:
        """Root-mean-square residual (units of y)."""
        return float(np.sqrt(np.mean(self.residuals**2)))

    def predict(self, speed: np.ndarray) -> np.ndarray:
        """y at ``speed`` (rad/s), any shape."""
        return predict(self.model, self.params, np.asarray(speed, dtype=float))

    def to_json(self) -> dict:
        return {"model": self.model,
                "params": {n: float(v) for n, v in zip(self.names, self.params)},
                "ci95": {n: [float(lo), float(hi)] for n, (lo, hi) in zip(self.names, self.ci95)},
                "rms_residual": self.rms, "points": int(self.residuals.size), "dof": self.dof}


def predict(model: str, params: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Evaluate ``model`` with ``params`` at ``speed`` (rad/s)."""
    if model == "power":
        k, n = params
        return k * np.power(np.abs(speed), n)
    return _design(model, speed) @ params


def _fit_power(speed: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = speed / _POWER_REF_SPEED
    positive = (x > 0) & (y > 0)
    slope, intercept = np.polyfit(np.log(x[positive]), np.log(y[positive]), 1)

    def residual(p):
        return p[0] * np.power(x, p[1]) - y

    def jacobian(p):
        xn = np.power(x, p[1])
        return np.stack([xn, p[0] * xn * np.log(np.where(x > 0, x, 1.0))], axis=-1)

    sol = optimize.least_squares(residual, [math.exp(intercept), slope], jac=jacobian,
                                 method="lm", xtol=1e-14, ftol=1e-14)
    a, n = sol.x
    # back to k Omega^n: k = a / ref^n (delta method for the covariance)
    to_k = np.array([[_POWER_REF_SPEED**-n, -a * math.log(_POWER_REF_SPEED) * _POWER_REF_SPEED**-n],
                     [0.0, 1.0]])
    return np.array([a * _POWER_REF_SPEED**-n, n]), jacobian(sol.x), to_k


def fit_curve(speed, response, model: str = "quadratic", *, where: str = "data",
              factor_name: str = "b") -> Fit:
    """Least-squares fit of ``response`` (N or N m) against ``speed`` (rad/s), any shapes
    that flatten alike; only points with speed > 0 (a running rotor) are used.

    ``factor_name`` names the Omega^2 coefficient (``b`` for thrust, ``d`` for torque)."""
    if model not in MODELS:
        raise InputError(f"unknown thrust-curve model {model!r}; valid: {', '.join(MODELS)}")
    speed = np.asarray(speed, dtype=float).ravel()
    y = np.asarray(response, dtype=float).ravel()
    running = speed > 0
    speed, y = speed[running], y[running]
    names = MODELS[model]
    if model != "power":
        names = (factor_name,) + names[1:]
    if speed.size <= len(names):
        raise InputError(f"{where}: {speed.size} points with a running rotor, more than "
                         f"{len(names)} needed for the {model} model")
    if model == "power":
        params, jac, transform = _fit_power(speed, y)
    else:
        jac = _design(model, speed)
        params = np.linalg.lstsq(jac, y, rcond=None)[0]
        transform = np.eye(len(names))
    residuals = y - predict(model, params, speed)
    dof = speed.size - len(names)
    sigma2 = float(residuals @ residuals) / dof
    cov = transform @ (sigma2 * np.linalg.inv(jac.T @ jac)) @ transform.T
    half = stats.t.ppf(0.975, dof) * np.sqrt(np.diag(cov))
    return Fit(model, names, params, cov, np.stack([params - half, params + half], axis=-1),
               residuals, dof)


@dataclass(frozen=True)
class HeldOutScore:
    """One model scored on held-out data.

    ``rms`` (N) over every held-out point; ``bias_by_step`` / ``rms_by_step`` (K,) mean and
    RMS held-out residual (measured - predicted) at each command step."""

    model: str
    scheme: str
    rms: float
    bias_by_step: np.ndarray
    rms_by_step: np.ndarray
    stderr_by_step: np.ndarray

    def to_json(self) -> dict:
        return {"model": self.model, "scheme": self.scheme, "rms": self.rms,
                "bias_by_step": self.bias_by_step.tolist(),
                "rms_by_step": self.rms_by_step.tolist()}


def _step_statistics(residual: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean, RMS and standard error of the mean per column of ``residual`` (N, K), ignoring
    NaN (stopped rotor); columns without data get 0, 0, inf."""
    valid = np.isfinite(residual)
    counts = valid.sum(axis=0)
    filled = np.where(valid, residual, 0.0)
    safe = np.maximum(counts, 1)
    mean = filled.sum(axis=0) / safe
    rms = np.sqrt((filled**2).sum(axis=0) / safe)
    variance = (np.where(valid, residual - mean, 0.0) ** 2).sum(axis=0) / np.maximum(counts - 1, 1)
    stderr = np.where(counts > 1, np.sqrt(variance / safe), np.inf)
    return mean, rms, stderr


def held_out_scores(speed: np.ndarray, thrust: np.ndarray, *, axis: int, scheme: str,
                    models: tuple[str, ...] = tuple(MODELS)) -> list[HeldOutScore]:
    """Leave-one-out scores: ``speed``, ``thrust`` (M, T, K) (motor, trial, step); each slice
    along ``axis`` (0: leave one motor out, 1: leave one trial out) is predicted by a fit to
    the others. Stopped points (speed 0) are left out of the scores."""
    speed, thrust = np.asarray(speed, float), np.asarray(thrust, float)
    scores = []
    for model in models:
        residual = np.full(speed.shape, np.nan)
        for k in range(speed.shape[axis]):
            train = np.ones(speed.shape[axis], bool)
            train[k] = False
            fit = fit_curve(np.compress(train, speed, axis), np.compress(train, thrust, axis),
                            model, where=scheme)
            index = [slice(None)] * speed.ndim
            index[axis] = k
            held = speed[tuple(index)]
            residual[tuple(index)] = np.where(held > 0, thrust[tuple(index)] - fit.predict(held),
                                              np.nan)
        bias, rms_step, stderr = _step_statistics(residual.reshape(-1, speed.shape[-1]))
        scores.append(HeldOutScore(model, scheme, float(np.sqrt(np.nanmean(residual**2))),
                                   bias, rms_step, stderr))
    return scores


@dataclass(frozen=True)
class Ratio:
    """y = ratio * x through the origin: value, 95 % interval, points used."""

    value: float
    ci95: tuple[float, float]
    points: int

    def to_json(self) -> dict:
        return {"value": self.value, "ci95": list(self.ci95), "points": self.points}


def fit_ratio(x, y, *, where: str = "data") -> Ratio:
    """Least-squares y = r x (no intercept) with a Student-t 95 % interval on r.

    Used for the propeller's torque/thrust ratio d/b (m): torque = (d/b) thrust."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    if x.size < 2:
        raise InputError(f"{where}: {x.size} points, at least 2 needed for a ratio")
    sxx = float(x @ x)
    value = float(x @ y) / sxx
    residual = y - value * x
    half = stats.t.ppf(0.975, x.size - 1) * math.sqrt(float(residual @ residual)
                                                       / (x.size - 1) / sxx)
    return Ratio(value, (value - half, value + half), int(x.size))


@dataclass(frozen=True)
class StandFit:
    """b and d of one propeller from a thrust-stand sweep with torque, and d/b."""

    thrust: Fit   # quadratic: b (N s^2/rad^2)
    torque: Fit   # quadratic: d (N m s^2/rad^2)
    ratio: Ratio  # torque = (d/b) thrust (m)
    source: str

    def to_json(self) -> dict:
        return {"thrust": self.thrust.to_json(), "torque": self.torque.to_json(),
                "torque_thrust_ratio_m": self.ratio.to_json(), "source": self.source}


def fit_thrust_stand(sweep) -> StandFit:
    """Fit F = b Omega^2 and Q = d Omega^2 on a :class:`~quadsim.identify.benchdata.SpeedSweep` with
    torque, and the ratio Q = (d/b) F, over the points where the rotor turns."""
    if sweep.torque is None:
        raise InputError(f"{sweep.path}: torque: this sweep has no torque column")
    running = sweep.speed > 0
    return StandFit(fit_curve(sweep.speed, sweep.thrust, where=f"{sweep.path}: thrust"),
                    fit_curve(sweep.speed, np.abs(sweep.torque), where=f"{sweep.path}: torque",
                              factor_name="d"),
                    fit_ratio(sweep.thrust[running], np.abs(sweep.torque[running]),
                              where=f"{sweep.path}: torque"), sweep.source)
