"""Equation-error fitting of candidate effects (the "which" of the gap diagnosis).

For a candidate effect with values theta, every sample of every flight gives a residual
(measured Newton–Euler wrench minus model wrench, :mod:`quadsim.gap.residual`, plus a rotor-speed
channel when the log has commands), divided per channel by the noise scale ``sigma``. The
effect's fittable parameters, their typical sizes and fit windows are what the effect declares
(``facts``, :mod:`quadsim.effects.facts`; :data:`FIT_SPEC` is a read-only view) and are found
with bounded ``scipy.optimize.least_squares``; confidence intervals come from the Jacobian at
the solution, widened by the residuals' correlation time (the smoothed samples are not
independent).

A *candidate* is a tuple of (effect name, fixed values, fitted parameter names). Some effects
need a companion to be seen at all (``facts.companions``): ``wind`` acts only through drag, so
the ``wind`` candidate fits the mean wind together with the rotor-drag coefficient. The
diagnosis' own effects and fit forms are declared in :mod:`quadsim.gap.fitmodels`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from types import MappingProxyType

import numpy as np
from scipy.optimize import least_squares

from ..core.errors import ModelError
from ..effects import EFFECTS
from ..effects.facts import arm_length
from ..effects.thrust_curve import hover_thrust_per_speed
from ..vehicle.params import VehicleParams
from .fitmodels import (
    FIT_EFFECTS,
    LOCAL_EFFECTS,
    CantedRotorFit,
    build_effect,
    effect_class,
    facts_for,
)
from .memo import flight_memo, memoised, rotor_key, wrench_key
from .motor_map import (  # re-exported: the diagnosis' public fitting names
    command_of_speed,
    command_speed,
    fit_motor_map,
    speed_of_command,
)
from .residual import FlightStates, measured_wrench, model_wrench
from .rotor_channel import min_time_constant, rotor_residual

__all__ = [
    "BASELINE",
    "FIT_SPEC",
    "LOCAL_EFFECTS",
    "NOISE_FLOOR",
    "NO_OFF_VALUE",
    "UPSTREAM_OF_SPEED",
    "Candidate",
    "CantedRotorFit",
    "Fit",
    "arm_length",
    "candidates_for",
    "command_of_speed",
    "command_speed",
    "correlation_time",
    "curve_bound",
    "drag_refit_iv",
    "effect_class",
    "fit_candidate",
    "fit_motor_map",
    "flight_memo",
    "noise_floor",
    "noise_scale",
    "parameter_bounds",
    "residuals",
    "speed_of_command",
    "stack_states",
    "typical_scales",
]

#: parameters whose "off" value does not switch their effect off (with a voltage log the sag
#: (V / V_full)^2 acts for every V_full), so "significantly away from off" does not apply:
#: each effect's ``facts.no_off_value`` (a read-only view)
NO_OFF_VALUE = frozenset(f"{name}.{p}" for name, cls in EFFECTS.items()
                         for p in cls.facts.no_off_value)

#: a fitted value within this fraction of its typical size from a bound is "at the bound".
AT_BOUND = 1e-3
#: a standard error below this fraction of the parameter's typical size is not credible.
ABSURD_CI = 1e-6

#: library effects acting upstream of the measured rotor speed (command -> speed channel
#: only): each effect's ``facts.upstream_of_speed`` (a read-only view)
UPSTREAM_OF_SPEED = frozenset(name for name, cls in EFFECTS.items()
                              if cls.facts.upstream_of_speed)

#: the step unit of a fitted parameter whose effect declares no typical scale for it
DEFAULT_SCALE = 1.0


@dataclass(frozen=True)
class Candidate:
    """Effects to fit together: ``parts`` = ((effect name, fixed values, fitted names), ...);
    ``base``: effects already in the model (a diagnosed model as the starting point, e.g.
    ``python -m quadsim.gap --effects-file``), applied first and never fitted."""

    name: str
    parts: tuple[tuple[str, dict, tuple[str, ...]], ...]
    base: tuple = ()

    @property
    def parameter_names(self) -> list[str]:
        return [f"{name}.{p}" for name, _, fitted in self.parts for p in fitted]

    @property
    def fixed_values(self) -> dict[str, float]:
        """The values held fixed, ``effect.parameter`` -> value (e.g. a canted rotor's index)."""
        return {f"{name}.{p}": float(v) for name, fixed, _ in self.parts for p, v in fixed.items()}

    def effects(self, theta: np.ndarray) -> list:
        """The base effects, then each part built with its fixed values and its fitted ones
        from ``theta`` (in :attr:`parameter_names` order). An effect is its class and its
        values, set once: a part whose values a step of ``theta`` did not move is the same
        object as before (:func:`_built`)."""
        out, k = list(self.base), 0
        for name, fixed, fitted in self.parts:
            values = dict(fixed)
            for p in fitted:
                values[p] = float(theta[k])
                k += 1
            try:
                out.append(_built(name, tuple(values.items())))
            except TypeError:           # a fixed value that is not hashable: built anew
                out.append(build_effect(name, values))
        return out

    def combine(self, other: Candidate) -> Candidate:
        return Candidate(f"{self.name}+{other.name}", self.parts + other.parts, self.base)


@lru_cache(maxsize=4096)
def _built(name: str, values: tuple) -> object:
    """:func:`build_effect` of ``name`` with ``values`` ((parameter, value), ...), kept: a
    fit builds the same effect for every step that moves another part."""
    return build_effect(name, dict(values))


@dataclass
class Fit:
    """A fitted candidate: parameter values, standard errors, 95 % CI half-widths, cost."""

    candidate: Candidate
    theta: np.ndarray
    stderr: np.ndarray
    correlation: np.ndarray
    cost: float
    identifiable: list[bool] = field(default_factory=list)
    significant: list[bool] = field(default_factory=list)

    def params(self) -> dict[str, float]:
        return dict(zip(self.candidate.parameter_names, map(float, self.theta)))

    def ci(self) -> dict[str, float]:
        return dict(zip(self.candidate.parameter_names, map(float, 1.96 * self.stderr)))

    def effects(self) -> list:
        return self.candidate.effects(self.theta)


def _fit_spec_entry(cls: type) -> tuple:
    facts = cls.facts
    fitted = None if facts.per_rotor else tuple(facts.fitted)

    def typical(params: VehicleParams, facts=facts) -> list[float]:
        return [facts.scale_of(p).size(params) for p in facts.fitted_for(params.rotor_count)]

    return fitted, dict(facts.fixed), typical


#: effect -> (parameters to fit, fixed values, typical magnitude of each fitted parameter
#: as a function of the vehicle), for every effect the diagnosis fits: a read-only view of
#: the effects' ``facts`` (:mod:`quadsim.effects.facts`; None: one per rotor). Unlisted
#: parameters stay at their ``off`` value.
FIT_SPEC = MappingProxyType({name: _fit_spec_entry(cls) for name, cls in FIT_EFFECTS.items()
                             if cls.facts.fitted or cls.facts.per_rotor})


def candidates_for(params: VehicleParams, has_commands: bool,
                   has_vbat: bool = False) -> list[Candidate]:
    """The candidate list for a vehicle: every effect of the library that the data can show,
    in name order, as each declares it (``facts``).

    An effect upstream of the measured rotor speed (``facts.upstream_of_speed``: a motor
    lag, a battery) needs commands: it is fitted on the command -> speed channel only (with
    measured rotor speeds it does not change the wrench); one with companions is fitted with
    them (wind with the rotor drag: wind alone exerts no force); one with a discrete index
    (``facts.one_per_rotor``: a canted rotor) is one candidate per rotor (the diagnosis keeps
    the one that fits the training flights best); with a voltage log an effect fits its
    ``facts.with_voltage_log`` parameters instead."""
    out = []
    for name in sorted(EFFECTS):
        facts = EFFECTS[name].facts
        fitted = facts.fitted_for(params.rotor_count)
        if not fitted or (facts.upstream_of_speed and not has_commands):
            continue
        if facts.one_per_rotor:      # a discrete index: one candidate per rotor
            out += [Candidate(name, ((name, {facts.one_per_rotor: float(k + 1)}, fitted),))
                    for k in range(params.rotor_count)]
            continue
        if has_vbat and facts.with_voltage_log:
            fitted = tuple(facts.with_voltage_log)
        known = {p.name for p in EFFECTS[name].parameters}
        fitted = tuple(p for p in fitted if p in known)
        if fitted:
            companions = tuple((c.effect, {}, tuple(c.fitted)) for c in facts.companions)
            out.append(Candidate(name, ((name, dict(facts.fixed), fitted),) + companions))
    return out


def typical_scales(candidate: Candidate, params: VehicleParams) -> np.ndarray:
    """The typical size of each fitted parameter of ``candidate`` for ``params`` (its unit):
    the effect's declared scale (``facts.scales``), else :data:`DEFAULT_SCALE`."""
    scales = []
    for name, _, fitted in candidate.parts:
        facts = facts_for(name)
        for p in fitted:
            scale = facts.scale_of(p)
            scales.append(DEFAULT_SCALE if scale is None else scale.size(params))
    return np.asarray(scales, dtype=float)


def curve_bound(params: VehicleParams) -> float:
    """The largest thrust-curve slope a fit takes (N s/rad): the hover thrust per rad/s of
    hover speed, ``b Omega_h``, a linear term carrying the whole hover thrust (fs's stand
    curve, 0.785 + 9.16 a + 18.0 a^2 N, needs 0.81 of it about its hover speed; the effect's
    own range is +-1 N s/rad, for any vehicle)."""
    return hover_thrust_per_speed(params)


def parameter_bounds(candidate: Candidate, params: VehicleParams
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of each fitted parameter of ``candidate``: its declared bounds, within
    the effect's fit window for this vehicle where it declares one (``facts.windows``)."""
    lower, upper = [], []
    for name, _, fitted in candidate.parts:
        cls = effect_class(name)
        specs = {p.name: p for p in cls.parameters}
        for p in fitted:
            lo, hi = specs[p].lower, specs[p].upper
            window = cls.facts.window_of(p)
            if window is not None:
                lo, hi = max(lo, window.low(params)), min(hi, window.high(params))
            lower.append(lo)
            upper.append(hi)
    return np.asarray(lower), np.asarray(upper)


def _start_off(candidate: Candidate) -> np.ndarray:
    """The "off" value of each fitted parameter."""
    off = []
    for name, _, fitted in candidate.parts:
        specs = {p.name: p for p in effect_class(name).parameters}
        off += [specs[p].off for p in fitted]
    return np.asarray(off, dtype=float)


def _start(candidate: Candidate, lower: np.ndarray, upper: np.ndarray,
           typical: np.ndarray) -> np.ndarray:
    off = []
    for name, _fixed, fitted in candidate.parts:
        specs = {p.name: p for p in effect_class(name).parameters}
        off += [specs[p].off for p in fitted]
    x0 = np.asarray(off, dtype=float)
    # Start strictly inside the bounds (least_squares' trust region needs it); an effect
    # whose "off" value sits on a bound starts a tenth of its typical size away from it.
    x0 = np.where(x0 <= lower, lower + 0.1 * typical, x0)
    x0 = np.where(x0 >= upper, upper - 0.1 * typical, x0)
    return np.clip(x0, lower + 1e-12 * typical, upper - 1e-12 * typical)


def stack_states(flights: list[FlightStates]) -> FlightStates:
    """Several flights as one sample set (each keeps its own time axis; the rotor channel
    skips the boundaries)."""
    if len(flights) == 1:
        return flights[0]

    def cat(name):
        values = [getattr(f, name) for f in flights]
        return None if any(v is None for v in values) else np.concatenate(values)

    first = flights[0]
    return FlightStates(*(cat(n) for n in ("t", "position", "velocity", "accel_world", "quat",
                                           "body_rate", "body_accel", "specific_force",
                                           "rotor_speed", "rotor_accel", "command", "vbat")),
                        first.accel_source, first.window_s, first.polyorder, "stacked",
                        all(f.pose for f in flights))


def residuals(states: FlightStates, params: VehicleParams, effects: list, *,
              rotor_channel: bool, memo: dict | None = None) -> np.ndarray:
    """Unscaled residual (N, C): Fx Fy Fz Mx My Mz (N, N m) [+ rotor_1..R (rad/s)].

    The force channels are compared as specific force times the *nominal* mass
    (``(F_meas - F_model) * m / m_vehicle``): an unmodelled force that the log carries
    (drag a candidate does not model) then weighs the same for every candidate. In newtons
    of the candidate's own vehicle, a candidate that adds mass would also scale every
    unexplained force by m'/m and lose against an equivalent thrust scale (measured: a 4 g
    payload on the Crazyflie with unmodelled drag explained 0.865 of the gap against 0.882
    for -10 % thrust per Omega^2).

    The torque channels likewise are angular acceleration times the *nominal* inertia,
    ``I (I_v^-1 (M_meas - M_model))`` = ``I (w_dot_meas - w_dot_model)`` with ``I_v`` the
    candidate vehicle's inertia: the measured angular acceleration (a differentiated, noisy
    gyro) then enters every candidate's residual with weight one. In newtons-metres of the
    candidate's own inertia the gyro noise would be scaled by ``I_v``, and least squares
    would shrink ``I_v`` to shrink the noise (errors in variables: measured on 8 s
    inverse-dynamics flights of the testbed with gyro noise 0.1 rad/s and no inertia error:
    xx -14 %, zz -79 %; in this form +1.2 ± 4.3 %, -1.9 ± 21 %; with a true +30 % on xx, yy:
    +12 % before, +31 ± 6 % now; docs/gap.md)."""
    if memo is None:
        force, torque, vehicle = model_wrench(states, params, effects)
    else:
        rotation, motion = flight_memo(memo, states)
        force, torque, vehicle = memoised(
            memo, wrench_key(states, params, effects), states,
            lambda: model_wrench(states, params, effects, rotation=rotation,
                                 flight_memo=motion))
    if memo is None:
        meas_force, meas_torque = measured_wrench(states, vehicle)
    else:       # what the motion implies: the same for every rotor timing of one flight
        motion = (states.body_rate, states.body_accel, states.specific_force)
        key = ("measured", *map(id, motion), vehicle.mass, vehicle.com.tobytes(),
               vehicle.inertia.tobytes())
        meas_force, meas_torque = memoised(memo, key, motion,
                                           lambda: measured_wrench(states, vehicle))
    torque_residual = meas_torque - torque
    if vehicle.inertia is not params.inertia and not np.array_equal(vehicle.inertia,
                                                                     params.inertia):
        torque_residual = torque_residual @ _inertia_map(
            np.asarray(vehicle.inertia, dtype=float).tobytes(),
            np.asarray(params.inertia, dtype=float).tobytes())
    parts = [(meas_force - force) * (params.mass / vehicle.mass), torque_residual]
    if rotor_channel:
        if memo is None:
            parts.append(rotor_residual(states, params, effects))
        else:
            parts.append(memoised(memo, rotor_key(states, params, effects), states,
                               lambda: rotor_residual(states, params, effects)))
    return np.concatenate(parts, axis=1)


@lru_cache(maxsize=256)
def _inertia_map(vehicle_inertia: bytes, nominal_inertia: bytes) -> np.ndarray:
    """``I_v^-1 I`` (3, 3) of two inertia matrices given as their float64 bytes (kept: a fit
    evaluates many models with the same inertia); read-only."""
    out = np.linalg.solve(np.frombuffer(vehicle_inertia).reshape(3, 3),
                          np.frombuffer(nominal_inertia).reshape(3, 3))
    out.flags.writeable = False
    return out


#: the noise scale of a channel is at least this fraction of its operating point (weight,
#: weight x arm, hover speed): on noiseless (simulated) logs "noise" would otherwise be
#: round-off and any integration difference would count as a gap.
NOISE_FLOOR = 1e-3


def noise_floor(params: VehicleParams, rotor_channel: bool) -> np.ndarray:
    """Smallest noise scale per channel (see :data:`NOISE_FLOOR`)."""
    hover = np.sqrt(params.weight / (params.rotor_count * params.thrust_factor))
    floors = [params.weight] * 3 + [params.weight * arm_length(params)] * 3
    if rotor_channel:
        floors += [hover] * params.rotor_count
    return NOISE_FLOOR * np.asarray(floors)


def noise_scale(residual: np.ndarray, dt: float, window_s: float = 0.5,
                floor: np.ndarray | None = None) -> np.ndarray:
    """Per-channel noise scale: robust spread of the residual after removing its slow part
    (moving average over ``window_s``), so that a slowly acting effect does not inflate it;
    at least ``floor`` (:func:`noise_floor`)."""
    n = max(3, int(round(window_s / dt)) | 1)
    kernel = np.ones(n) / n
    slow = np.stack([np.convolve(c, kernel, mode="same") for c in residual.T], -1)
    fast = residual - slow
    mad = np.median(np.abs(fast - np.median(fast, axis=0)), axis=0) * 1.4826
    tiny = 1e-9 * (np.abs(residual).max(axis=0) + 1e-12)
    return np.maximum(mad, tiny if floor is None else np.maximum(tiny, floor))


def correlation_time(e: np.ndarray, max_lag: int = 200) -> float:
    """Integrated autocorrelation time (samples) of the scaled residual, for CI widening."""
    x = e - e.mean(axis=0)
    var = np.sum(x * x)
    if var <= 0:
        return 1.0
    tau = 1.0
    for lag in range(1, min(max_lag, len(x) - 1)):
        rho = np.sum(x[lag:] * x[:-lag]) / var
        if rho < 0.05:
            break
        tau += 2 * rho
    return float(tau)


def drag_refit_iv(states: FlightStates, params: VehicleParams, candidate: Candidate,
                  theta: np.ndarray, k: int) -> tuple[float, float]:
    """Relative change of the drag-torque factor d (``nominal_refit.drag``) by instrumental
    variables, and its standard error.

    The yaw torque is linear in d: Mz = (1 + delta) x + o, with x = d sum_i s_i Omega_i^2 (N m,
    s_i the rotor's spin sign) and o the rest of the model's yaw torque. Least squares on
    *measured* rotor speeds is an errors-in-variables regression: noise e on Omega_i enters x
    as d sum_i 2 s_i Omega_i e_i, and the slope is attenuated by var(x) / (var(x) + var(e_x))
    (regression dilution). Near hover with little yaw the true x hardly varies, so the
    attenuation is almost total and the least-squares refit goes to delta = -1 (measured:
    Crazyflie hover flown closed loop by ``quadsim.fly`` with rotor-speed noise 0.5 % of hover
    gave -0.9 at the bound, docs/gap.md). The instrument z is the same regressor computed from
    the *commanded* speeds (the motor map of the commands): correlated with the true speeds,
    not with their measurement noise, so
    ``1 + delta = sum z (Mz_meas - o) / sum z x`` is consistent (Wald/IV estimator; motor lag
    between command and speed does not bias it, it only weakens the instrument).
    Standard error: ``s_u sqrt(sum z^2) / |sum z x|`` (s_u the RMS of Mz_meas - o - (1+delta) x),
    widened by the residual's correlation time. A weak instrument (no yaw commanded) gives a
    wide interval, so d is then reported as not identified instead of a confident -90 %.
    Returns (nan, nan) when the rotor speeds or commands are missing."""
    if states.command is None or states.rotor_speed is None:
        return float("nan"), float("nan")
    effects = candidate.effects(theta)
    plus = theta.copy()
    plus[k] += 1.0
    effects_plus = candidate.effects(plus)
    _, torque, vehicle = model_wrench(states, params, effects)
    _, torque_plus, _ = model_wrench(states, params, effects_plus)
    cmd = command_speed(states, params)
    _, zt, _ = model_wrench(states, params, effects, rotor_speed=cmd)
    _, zt_plus, _ = model_wrench(states, params, effects_plus, rotor_speed=cmd)
    x = torque_plus[:, 2] - torque[:, 2]          # d sum s_i Omega_i^2 (N m per unit delta)
    z = zt_plus[:, 2] - zt[:, 2]                  # the same from the commanded speeds
    _, measured = measured_wrench(states, vehicle)
    y = measured[:, 2] - (torque[:, 2] - (1.0 + theta[k]) * x)   # Mz_meas - o
    zx = float(z @ x)
    if not np.isfinite(zx) or abs(zx) <= 0.0:
        return float("nan"), float("nan")
    gain = float(z @ y) / zx
    u = y - gain * x
    tau = correlation_time(u[:, None])
    se = float(np.sqrt(np.mean(u * u) * float(z @ z) * tau) / abs(zx))
    return gain - 1.0, se


def flagged(candidate: Candidate, flag: str) -> list[int]:
    """Indices of ``candidate``'s fitted parameters that their effect lists in its facts'
    ``flag`` (:class:`quadsim.effects.facts.EffectFacts`: ``rotor_time_constants``,
    ``starts_at_logged_voltage``, ``instrumented``)."""
    out, k = [], 0
    for name, _, fitted in candidate.parts:
        listed = getattr(facts_for(name), flag)
        out += [k + i for i, p in enumerate(fitted) if p in listed]
        k += len(fitted)
    return out


def fit_candidate(candidate: Candidate, flights: list[FlightStates], params: VehicleParams,
                  sigma: np.ndarray, *, rotor_channel: bool, start: np.ndarray | None = None,
                  max_nfev: int = 60) -> Fit:
    """Bounded least squares of ``candidate`` on ``flights`` (already decimated)."""
    typical = typical_scales(candidate, params)
    lower, upper = parameter_bounds(candidate, params)
    # a rotor time constant is at least one sub-step of the rotor channel (min_time_constant)
    step = min_time_constant(float(flights[0].t[1] - flights[0].t[0])) \
        if len(flights[0].t) > 1 else 0.0
    for k in flagged(candidate, "rotor_time_constants"):
        lower[k] = max(lower[k], step)
    x0 = _start(candidate, lower, upper, typical) if start is None else np.clip(
        start, lower + 1e-12 * typical, upper - 1e-12 * typical)
    for k in flagged(candidate, "starts_at_logged_voltage") if start is None else ():
        # Start where the sag is neutral on average: the full voltage at the highest logged.
        x0[k] = np.clip(max(float(np.nanmax(s.vbat)) for s in flights), lower[k], upper[k])

    stacked = stack_states(flights)
    size = len(stacked.t) * len(sigma)
    memo: dict = {}     # the residual parts one parameter does not move (:func:`residuals`)

    def fun(z):
        # The solver works in units of each parameter's typical size, so that finite
        # differences and trust regions suit parameters from 1e-8 kg m^2 to volts.
        try:
            effects = candidate.effects(x0 + z * typical)
            return (residuals(stacked, params, effects, rotor_channel=rotor_channel,
                              memo=memo) / sigma).ravel()
        except ModelError:
            # Parameters that make the vehicle non-physical (e.g. inertia breaking the
            # triangle inequality) are walls, not crashes.
            return np.full(size, 1e3)

    z_lower, z_upper = (lower - x0) / typical, (upper - x0) / typical
    result = least_squares(fun, np.zeros_like(x0), bounds=(z_lower, z_upper),
                           diff_step=1e-4, max_nfev=max_nfev, method="trf", x_scale=1.0)
    theta = x0 + result.x * typical
    jac, res = result.jac / typical, result.fun
    dof = max(1, res.size - len(x0))
    s2 = float(res @ res) / dof
    inflation = correlation_time(res.reshape(-1, len(sigma)))
    cov = np.linalg.pinv(jac.T @ jac) * s2 * inflation
    stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
    for k in flagged(candidate, "instrumented") if stacked.command is not None else ():
        value, se = drag_refit_iv(stacked, params, candidate, theta, k)
        if np.isfinite(value) and np.isfinite(se):
            theta[k] = float(np.clip(value, lower[k], upper[k]))
            cov[k, :] = cov[:, k] = 0.0
            cov[k, k] = se ** 2
            stderr[k] = se
    denom = np.outer(stderr, stderr)
    corr = np.divide(cov, denom, out=np.zeros_like(cov), where=denom > 0)
    column = np.linalg.norm(jac, axis=0) * typical
    # A parameter is identified when the data move the residual and its CI is narrower
    # than half the plausible range.
    span = upper - lower
    # Never identified: a value at a bound (the optimum lies beyond it, its CI means
    # nothing) or an absurdly narrow interval (a flat or degenerate Jacobian direction, e.g.
    # "wind.vy = 29.99 +- 4e-21 m/s").
    at_bound = (theta - lower <= AT_BOUND * typical) | (upper - theta <= AT_BOUND * typical)
    absurd = stderr < ABSURD_CI * typical
    identifiable = [bool(c > 1e-6 * np.sqrt(res.size) and 1.96 * se < 0.5 * sp
                         and not b and not a)
                    for c, se, sp, b, a in zip(column, stderr, span, at_bound, absurd)]
    off = _start_off(candidate)
    significant = [bool(abs(th - o) > 1.96 * se) or name in NO_OFF_VALUE
                   for th, o, se, name in zip(theta, off, stderr, candidate.parameter_names)]
    return Fit(candidate, theta, stderr, corr, float(result.cost), identifiable, significant)


#: the nominal refit's candidate (:class:`quadsim.gap.fitmodels.NominalRefit`): the
#: parameter set's b and d re-identified; a shared group of the reference model
#: (:mod:`.calibrate`) and the held-out reading "b and d are off"
BASELINE = Candidate("nominal_refit", (("nominal_refit", {}, ("thrust", "drag")),))
