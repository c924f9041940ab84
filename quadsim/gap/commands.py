"""Diagnosis from motor commands alone: a command -> rotor-speed model identified on
reference flights that have both, then rotor speeds synthesised for logs that have only
commands, so that the same gap diagnosis runs on them.

Model (per rotor i; u normalised command 0-1, V battery voltage in V, Omega in rad/s)::

    Omega_ss,i = a_i + b_i u_i + c_i u_i (V - V_ref)          steady state (c_i = 0 without vbat)
    tau dOmega_i/dt = Omega_ss,i - Omega_i                    first-order motor lag, one tau

The voltage term is the first-order effect of a falling battery (a brushed or brushless
motor's no-load speed is proportional to the applied voltage u V); ``V_ref`` is the median
reference voltage. The lag is discretised on the log's median step dt with
``alpha = exp(-dt / tau)`` and the input averaged over the step (no half-sample bias):
``y_k = alpha y_(k-1) + (1 - alpha) (x_k + x_(k-1)) / 2`` (``scipy.signal.lfilter``). Because
the filter is linear, ``a, b, c`` are an ordinary least-squares fit of the filtered features
``[1, u, u (V - V_ref)]`` for each tau; tau is chosen by bounded scalar minimisation of the
pooled squared error (``scipy.optimize.minimize_scalar``, 0.5 ms .. 0.5 s; tau = 0 is tried
too). Samples whose speed, command or voltage is NaN are left out of the fit.

Synthesis (:func:`synthesise_speeds`): the model driven by the log's commands (and vbat;
V_ref where vbat is missing); the synthesised log keeps no commands by default
(``keep_commands=False``) so that the diagnosis does not score a rotor channel that would
compare the model with itself.

Without any log with rotor speeds (a command-only fleet) the model comes from the parameter
set instead (:func:`command_model_from_params`): its ``[motor_map]``, voltage gain and time
constant, as ``python -m quadsim.identify --logs`` writes them from command-only logs (the
command -> thrust map from the accelerometer). ``gap`` synthesises speeds for every
command-only log it is given — positional, ``--holdout`` and ``--reference``
(:func:`synthesise_all`).

What is lost without measured speeds: the rotor channel (measured speed minus the speed the
commands predict) disappears, so effects that act *between* command and speed are fixed to
the reference: ``motor_lag`` cannot be fitted and a change of lag reads as an attitude-
dynamics change (confusable with ``inertia_error``); a rotor that turns slower for the same
command (a weaker motor, a sagging battery beyond the reference's range) is seen only through
its thrust, i.e. as ``thrust_mismatch``/``mass_offset`` rather than in the rotor channel.

Example::

    >>> from quadsim.gap.commands import fit_command_model, synthesise_speeds
    >>> model = fit_command_model(reference_logs)          # logs with rotor_*, cmd_*, vbat
    >>> model.tau, model.rms                               # s, rad/s
    >>> only_cmd = synthesise_speeds(log_without_speeds, model)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.signal import lfilter

from ..core.errors import InputError
from ..logs.flightlog import FlightLog

__all__ = ["CommandModel", "MapCommandModel", "command_model_from_params", "fit_command_model",
           "synthesise_all", "synthesise_speeds", "without_speeds"]

TAU_BOUNDS = (5e-4, 0.5)


@dataclass(frozen=True)
class CommandModel:
    """a, b, c (R,) rad/s; v_ref V (NaN: no voltage term); tau s; rms rad/s of the fit on the
    reference; samples used; source (the reference logs)."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    v_ref: float
    tau: float
    rms: float
    samples: int
    source: str

    @property
    def rotor_count(self) -> int:
        return len(self.a)

    def speeds(self, t: np.ndarray, command: np.ndarray, vbat: np.ndarray | None) -> np.ndarray:
        """Rotor speeds (N, R) rad/s for commands (N, R) and vbat (N,) V or None."""
        features = _features(command, vbat, self.v_ref)
        ss = self.a + self.b * features[1] + self.c * features[2]
        return _lag(ss, _step(t), self.tau)


def _step(t: np.ndarray) -> float:
    return float(np.median(np.diff(t)))


def _features(command, vbat, v_ref):
    u = np.asarray(command, dtype=float)
    if vbat is None or not np.isfinite(v_ref):
        dv = np.zeros(len(u))
    else:
        dv = np.where(np.isfinite(vbat), np.asarray(vbat, float) - v_ref, 0.0)
    return np.ones_like(u), u, u * dv[:, None]


def _lag(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """First-order lag of x (N, ...) along axis 0, starting at rest at x[0]."""
    if tau <= 0:
        return x
    alpha = np.exp(-dt / tau)
    b = [(1 - alpha) / 2, (1 - alpha) / 2]
    # lfilter (direct form II transposed): y0 = b0 x0 + z; z = (1 - b0) x0 starts at rest.
    zi = x[0] - b[0] * x[0]
    y, _ = lfilter(b, [1.0, -alpha], x, axis=0, zi=zi[None] if np.ndim(zi) else [zi])
    return y


def fit_command_model(logs: Sequence[FlightLog]) -> CommandModel:
    """Identify the command -> speed model on logs with rotor speeds and commands (each
    airborne stretch of a log of several take-offs alone: the lag never runs across the
    ground span between them)."""
    usable = [p for g in logs if g.rotor_speed is not None and g.rotor_command is not None
              for p in g.parts()]
    if not usable:
        raise InputError("command model: the reference logs need both rotor_* (speeds) and "
                         "cmd_* (commands)")
    counts = {g.rotor_count for g in usable}
    if len(counts) != 1:
        raise InputError(f"command model: reference logs disagree on the rotor count {counts}")
    with_v = all(g.vbat is not None for g in usable)
    v_ref = float(np.nanmedian(np.concatenate([g.vbat for g in usable]))) if with_v else np.nan
    flights = [(_step(g.t), _features(g.rotor_command, g.vbat if with_v else None, v_ref),
                g.rotor_speed) for g in usable]

    def solve(tau: float):
        rows, targets = [], []
        for dt, feats, speed in flights:
            filt = [_lag(f, dt, tau) for f in feats]
            ok = np.isfinite(speed) & np.all([np.isfinite(f) for f in filt], axis=0)
            rows.append((filt, ok))
            targets.append(speed)
        coef, sse, n = [], 0.0, 0
        for i in range(usable[0].rotor_count):
            a_mat = np.concatenate([np.stack([f[:, i] for f in filt], 1)[ok[:, i]]
                                    for (filt, ok) in rows])
            y = np.concatenate([s[:, i][ok[:, i]] for s, (_, ok) in zip(targets, rows)])
            if not with_v:
                a_mat = a_mat[:, :2]
            sol, *_ = np.linalg.lstsq(a_mat, y, rcond=None)
            sse += float(np.sum((a_mat @ sol - y) ** 2))
            n += len(y)
            coef.append(np.append(sol, 0.0) if not with_v else sol)
        return np.array(coef), sse, n

    best = minimize_scalar(lambda lt: solve(np.exp(lt))[1], bounds=np.log(TAU_BOUNDS),
                           method="bounded", options={"xatol": 0.01})
    tau = float(np.exp(best.x))
    coef, sse, n = solve(tau)
    coef0, sse0, _ = solve(0.0)
    if sse0 <= sse:
        tau, coef, sse = 0.0, coef0, sse0
    names = ", ".join(str(g.path) for g in usable[:3]) + (" ..." if len(usable) > 3 else "")
    return CommandModel(coef[:, 0], coef[:, 1], coef[:, 2], v_ref, tau, float(np.sqrt(sse / n)),
                        n, f"fitted on {len(usable)} reference log(s): {names}")


def synthesise_speeds(log: FlightLog, model: CommandModel, *,
                      keep_commands: bool = False) -> FlightLog:
    """``log`` with rotor speeds from its commands (and vbat) through ``model``; each airborne
    stretch of a log of several take-offs (:attr:`FlightLog.segments`) alone."""
    name = log.path or "log"
    if log.rotor_command is None:
        raise InputError(f"{name}: cmd_1..cmd_N: no commands to synthesise rotor speeds from")
    if log.rotor_count != model.rotor_count:
        raise InputError(f"{name}: cmd_1..cmd_N: {log.rotor_count} commands, the command model "
                         f"has {model.rotor_count} rotors")
    speed = np.concatenate([model.speeds(p.t, p.rotor_command, p.vbat) for p in log.parts()])
    note = (f"{name}: rotor speeds synthesised from commands (tau {model.tau * 1e3:.1f} ms, "
            f"fit rms {model.rms:.3g} rad/s, {model.source})")
    return dataclasses.replace(log, rotor_speed=speed,
                               rotor_command=log.rotor_command if keep_commands else None,
                               notes=log.notes + (note,))


def without_speeds(log: FlightLog) -> FlightLog:
    """The log with its rotor-speed columns removed (what a command-only log looks like)."""
    return dataclasses.replace(log, rotor_speed=None)


@dataclass(frozen=True)
class MapCommandModel:
    """The command -> speed model of a parameter set: ``motor_map.speed_at(command, vbat)``
    (piecewise linear per rotor, voltage gain about the reference voltage) through the
    first-order lag ``time_constant`` (tau, s); rms = nan (not fitted here); source."""

    params: object
    tau: float
    source: str
    rms: float = float("nan")

    @property
    def rotor_count(self) -> int:
        return self.params.rotor_count

    def speeds(self, t: np.ndarray, command: np.ndarray, vbat: np.ndarray | None) -> np.ndarray:
        mm = self.params.motor_map
        steady = mm.speed_at(np.asarray(command, float), vbat)
        return _lag(steady, _step(t), self.tau)


def command_model_from_params(params) -> MapCommandModel:
    """The parameter set's motor map as a command model; InputError without one."""
    mm = params.motor_map
    if mm is None:
        raise InputError(f"{params.path or params.name}: motor_map: logs without rotor speeds "
                         "need a command -> speed map: give --command-reference LOG... (logs "
                         "with rotor speeds and commands) or a parameter set with a "
                         "[motor_map] (python -m quadsim.identify --logs ... writes one, also "
                         "from command-only logs)")
    return MapCommandModel(params, float(mm.time_constant),
                           f"the motor map of {params.path or params.name} ({mm.source})")


@dataclass(frozen=True)
class BalancedModel:
    """A command model whose rotors' thrusts are rescaled by ``factors`` (R,) (relative
    thrust per rotor, ``Omega_i -> Omega_i sqrt(factors_i)``): :func:`balance_rotors`."""

    model: object
    factors: np.ndarray

    @property
    def rotor_count(self) -> int:
        return self.model.rotor_count

    @property
    def tau(self) -> float:
        return self.model.tau

    @property
    def rms(self) -> float:
        return self.model.rms

    @property
    def source(self) -> str:
        return (f"{self.model.source}, per-rotor thrust balanced on the references' mean roll "
                f"and pitch torque (x {', '.join(f'{f:.3f}' for f in self.factors)})")

    def speeds(self, t, command, vbat):
        return self.model.speeds(t, command, vbat) * np.sqrt(self.factors)


def balance_rotors(logs: Sequence[FlightLog], model, params) -> BalancedModel:
    """``model`` with per-rotor thrust factors ``1 + delta_i`` that make the reference
    ``logs``' (command-only) mean roll and pitch torque of the rotors equal to what their gyro
    says it was, ``mean(I w_dot + w x I w)`` (w_dot: the rate change over each stretch over its
    duration). ``delta`` moves neither the total thrust nor the yaw torque at the references'
    mean squared speeds (it lies in the null space of those two rows of the allocation
    matrix), so a flight's weight and yaw readings stay the references'.

    Why: the parameter set's command -> speed map is not the fleet's motors rotor by rotor;
    the difference is a roll/pitch torque every flight shares, which the per-flight reference
    model has no shared parameter to hold, so each calm flight was named ``com_offset``
    (tests/test_commands_wind.py). A map identified from commands only is the same for every
    rotor (``identify --logs``), so the fleet's own rotor imbalance is the same case."""
    from ..vehicle.rotors import allocation_matrix

    alloc = allocation_matrix(params)
    inertia = params.inertia
    squares, targets, weights = [], [], []
    for log in logs:
        for part in log.parts():
            if part.body_rate is None or part.rotor_command is None or len(part.t) < 3:
                continue
            w = part.body_rate
            duration = float(part.t[-1] - part.t[0])
            w_dot = (w[-1] - w[0]) / duration
            gyro_torque = inertia @ w_dot + np.mean(np.cross(w, w @ inertia.T), axis=0)
            speed = model.speeds(part.t, part.rotor_command, part.vbat)
            squares.append(np.mean(np.square(speed), axis=0))
            targets.append(gyro_torque[:2])
            weights.append(duration)
    if not squares:
        return BalancedModel(model, np.ones(model.rotor_count))
    weights = np.asarray(weights) / np.sum(weights)
    mean_sq = np.average(squares, axis=0, weights=weights)
    target = np.average(targets, axis=0, weights=weights)
    kept_rows = alloc[[2, 5]] * mean_sq              # thrust and yaw per relative change
    _, _, vt = np.linalg.svd(kept_rows)
    null = vt[2:].T                                  # (R, R - 2): moves neither
    moved = alloc[3:5] * mean_sq                     # roll, pitch torque per relative change
    now = moved.sum(axis=1)
    c, *_ = np.linalg.lstsq(moved @ null, target - now, rcond=None)
    delta = null @ c
    return BalancedModel(model, np.clip(1.0 + delta, 0.5, 1.5))


def synthesise_all(groups: dict[str, Sequence[FlightLog] | None], params,
                   reference: Sequence[FlightLog] | None = None):
    """Every command-only log in ``groups`` (role -> logs) gets synthesised speeds: the model
    is fitted on ``reference`` logs that have speeds, else the parameter set's motor map,
    balanced rotor by rotor on the command-only logs of the ``"reference"`` role when there
    are some (:func:`balance_rotors`: per flight, the references are the fleet). Returns
    (groups with the same keys, the model or None when no log needed one)."""
    needing = [g for logs in groups.values() for g in (logs or []) if g.rotor_speed is None]
    if not needing:
        return groups, None
    measured = [g for g in (reference or []) if g.rotor_speed is not None
                and g.rotor_command is not None]
    model = fit_command_model(measured) if measured else command_model_from_params(params)
    fleet = [g for g in groups.get("reference") or [] if g.rotor_speed is None]
    if not measured and fleet:      # a command-only fleet: its own rotor balance
        model = balance_rotors(fleet, model, params)
    out = {role: (None if logs is None else
                  [synthesise_speeds(g, model) if g.rotor_speed is None else g for g in logs])
           for role, logs in groups.items()}
    return out, model
