"""One front door to both engines: :func:`simulate` -> :class:`quadsim.vehicle.state.Trajectory`.

``engine="mujoco"`` steps the MJCF with RK4 (:mod:`quadsim.sim.mujoco_engine`);
``engine="analytic"`` integrates the Newton–Euler equations with ``solve_ivp`` / DOP853
(:mod:`quadsim.sim.analytic`). Both take the same inputs and return the same state convention.

Inputs are rotor speed commands (rad/s), held constant over each control period (zero-order
hold) in both engines, and clipped to the rotor range ``[min_speed, max_speed]``:

* ``rotor_speed_series``: (N, R) or (B, N, R) commands, one row per control period, or
* ``controller(t, state) -> (B, R)``: called once per control period with ``t`` (B,) and the
  snapshot ``state``, a dict of (B, ...) arrays ``t, position, velocity, quat, body_rate,
  rotor_speed`` (the shared convention of :mod:`quadsim.vehicle.state`), or
* neither: every rotor held at hover speed.

Batching: B simulations run together when any of ``initial`` (arrays with a leading axis),
``rotor_speed_series`` (3-D), ``params`` or ``effects`` (sequences, one per simulation) has a
batch axis; the trajectory then has a leading batch axis too. Example::

    >>> import numpy as np
    >>> from quadsim.vehicle.params import load_params, hover_speed
    >>> from quadsim.sim.engines import simulate, initial_state
    >>> p = load_params("physical")
    >>> start = initial_state(position=(0, 0, 1), euler=(0.261, 0.261, 0.261))
    >>> series = np.full((500, 4), hover_speed(p))
    >>> m = simulate(p, engine="mujoco", initial=start, rotor_speed_series=series,
    ...              duration=5.0, control_period=0.01)
    >>> a = simulate(p, engine="analytic", initial=start, rotor_speed_series=series,
    ...              duration=5.0, control_period=0.01)
    >>> float(np.abs(m.position - a.position).max()) < 1e-4
    True

Samples are taken at the control period boundaries ``t_k = k * control_period``,
k = 0..N; ``rotor_command[k]`` is the command held over [t_k, t_k+1) (the last one repeated at
t_N); ``rotor_speed[k]`` the actual speed at t_k (equal to the command without rotor dynamics).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..core.errors import InputError
from ..core.frames import euler_to_quat, quat_normalize
from ..effects.base import Effect, EffectSet
from ..vehicle.params import VehicleParams, hover_speed
from ..vehicle.state import Trajectory
from .analytic import ATOL, RTOL, BatchEffects, body_arrays, run_analytic

__all__ = ["simulate", "initial_state", "ENGINES", "Controller"]

ENGINES = ("mujoco", "analytic")
Controller = Callable[[np.ndarray, dict], np.ndarray]


def initial_state(*, position=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0), euler=None,
                  quat=None, body_rate=(0.0, 0.0, 0.0), rotor_speed=None) -> dict:
    """An initial state: world position (m) and velocity (m/s) of the body origin, attitude as
    Z-Y-X Euler angles (rad) or quaternion wxyz, body rates (rad/s), actual rotor speeds
    (rad/s; default hover). Each may carry a leading batch axis."""
    if euler is not None and quat is not None:
        raise InputError("initial state: give euler or quat, not both")
    if quat is None:
        quat = euler_to_quat(np.zeros(3) if euler is None else np.asarray(euler, float))
    state = {"position": position, "velocity": velocity, "quat": quat, "body_rate": body_rate}
    state = {k: np.asarray(v, dtype=float) for k, v in state.items()}
    if rotor_speed is not None:
        state["rotor_speed"] = np.asarray(rotor_speed, dtype=float)
    return state


def _batch_size(params, effects, initial: dict, series, batch: int | None) -> tuple[int, bool]:
    sizes = []
    if not isinstance(params, VehicleParams):
        sizes.append(len(params))
    if isinstance(effects, (list, tuple)) and effects and all(
            e is None or isinstance(e, EffectSet) for e in effects):
        sizes.append(len(effects))           # one EffectSet per simulation
    sizes += [np.shape(v)[0] for v in initial.values() if np.ndim(v) == 2]
    if series is not None and np.ndim(series) == 3:
        sizes.append(np.shape(series)[0])
    if batch is not None:
        sizes.append(batch)
    if len(set(sizes)) > 1:
        raise InputError(f"inconsistent batch sizes {sorted(set(sizes))} across params, "
                         "effects, initial state and rotor_speed_series")
    return (sizes[0] if sizes else 1), bool(sizes)


def _as_effect_set(effects) -> EffectSet:
    if effects is None:
        return EffectSet()
    if isinstance(effects, EffectSet):
        return effects
    if isinstance(effects, Effect):
        return EffectSet((effects,))
    return EffectSet(tuple(effects))


def _effective_params(params, effects, batch: int):
    """Per-simulation effect sets and effect-modified parameter sets (shared objects stay
    shared, so a batch without per-simulation changes compiles one model)."""
    base = [params] * batch if isinstance(params, VehicleParams) else list(params)
    if isinstance(effects, (list, tuple)) and effects and all(
            e is None or isinstance(e, EffectSet) for e in effects):
        sets = [_as_effect_set(e) for e in effects]
    else:
        sets = [_as_effect_set(effects)] * batch
    cache: dict[tuple[int, int], VehicleParams] = {}
    modified = []
    for p, s in zip(base, sets):
        key = (id(p), id(s))
        if key not in cache:
            cache[key] = s.apply_to_params(p)
        modified.append(cache[key])
    return sets, modified


def _open_loop(fn, series: np.ndarray):
    """Mark a command source that ignores the state: ``fn.series`` (B, N, R) holds every
    command, so an engine may run the whole series in one call."""
    fn.series = series
    return fn


def _command_source(params: list[VehicleParams], controller, series, periods: int,
                    batch: int) -> Callable[[int, dict], np.ndarray]:
    rotors = params[0].rotor_count
    low = np.array([p.min_speed for p in params])[:, None]
    high = np.array([p.max_speed for p in params])[:, None]
    if controller is not None and series is not None:
        raise InputError("give a controller or a rotor_speed_series, not both")
    if series is not None:
        series = np.asarray(series, dtype=float)
        series = np.broadcast_to(series, (batch,) + series.shape[-2:])
        if series.shape[-1] != rotors or series.shape[1] < periods:
            raise InputError(f"rotor_speed_series: expected (N >= {periods}, {rotors}) "
                             f"commands, got {series.shape[1:]}")
        if not np.all(np.isfinite(series)):
            raise InputError("rotor_speed_series: contains NaN or infinite values")
        clipped = np.clip(series[:, :periods], low[:, None], high[:, None])
        return _open_loop(lambda k, state: clipped[:, k], clipped)
    if controller is None:
        hover = np.array([hover_speed(p) for p in params])[:, None] * np.ones((1, rotors))
        held = np.clip(hover, low, high)
        return _open_loop(lambda k, state: held,
                          np.broadcast_to(held[:, None], (batch, periods, rotors)))

    def from_controller(k: int, state: dict) -> np.ndarray:
        command = np.asarray(controller(state["t"], state), dtype=float)
        command = np.broadcast_to(command, (batch, rotors))
        if not np.all(np.isfinite(command)):
            raise InputError(f"controller returned NaN or infinite commands at t = "
                             f"{state['t'][0]:.4g} s")
        return np.clip(command, low, high)

    return from_controller


def _initial_arrays(initial: dict, params: list[VehicleParams], batch: int) -> dict:
    shapes = {"position": 3, "velocity": 3, "quat": 4, "body_rate": 3}
    out = {}
    for name, size in shapes.items():
        value = np.asarray(initial.get(name, np.eye(4)[0] if name == "quat" else np.zeros(3)),
                           dtype=float)
        if value.shape[-1] != size or value.ndim > 2:
            raise InputError(f"initial state: {name} must have shape ({size},) or (B, {size})")
        if not np.all(np.isfinite(value)):
            raise InputError(f"initial state: {name} contains NaN or infinite values")
        out[name] = np.broadcast_to(value, (batch, size)).copy()
    if np.any(np.linalg.norm(out["quat"], axis=1) < 1e-9):
        raise InputError("initial state: quat must not be zero")
    out["quat"] = quat_normalize(out["quat"])
    rotors = params[0].rotor_count
    speed = initial.get("rotor_speed")
    if speed is None:
        speed = np.array([hover_speed(p) for p in params])[:, None] * np.ones(rotors)
    out["rotor_speed"] = np.broadcast_to(np.asarray(speed, float), (batch, rotors)).copy()
    return out


def simulate(params: VehicleParams | Sequence[VehicleParams], *, engine: str = "mujoco",
             initial: dict | None = None, controller: Controller | None = None,
             rotor_speed_series: np.ndarray | None = None, duration: float,
             control_period: float = 0.01, effects=None, timestep: float | None = None,
             rtol: float = RTOL, atol: float = ATOL, nthread: int = 0,
             batch: int | None = None, fast: bool | None = None) -> Trajectory:
    """Simulate one or a batch of flights in ``engine`` ("mujoco" or "analytic").

    ``effects``: None, an Effect, an :class:`EffectSet`, or a sequence of EffectSets (one per
    simulation). ``timestep`` (MuJoCo, s) must divide ``control_period`` (default: the largest
    <= 1 ms that does); ``rtol``/``atol`` are the analytic solver's tolerances. Raises
    :class:`~quadsim.core.errors.ModelError` if MuJoCo refuses the parameter set and
    :class:`~quadsim.core.errors.SimulationError` if a run diverges. ``fast``: None uses the
    compiled kernels when they can (:mod:`quadsim.sim.compiled`), False the reference paths;
    True requires the compiled MuJoCo path."""
    if engine not in ENGINES:
        raise InputError(f"unknown engine {engine!r}: valid engines are {', '.join(ENGINES)}")
    if not (control_period > 0 and duration > 0):
        raise InputError("duration and control_period must be positive")
    periods = int(round(duration / control_period))
    if abs(periods * control_period - duration) > 1e-9 * duration or periods < 1:
        raise InputError(f"duration {duration} s is not a whole number of control periods "
                         f"({control_period} s)")
    initial = initial_state() if initial is None else initial
    size, batched = _batch_size(params, effects, initial, rotor_speed_series, batch)
    sets, modified = _effective_params(params, effects, size)
    if len({p.rotor_count for p in modified}) != 1:
        raise InputError("all parameter sets of a batch must have the same number of rotors")
    batch_effects = BatchEffects(sets, modified)
    start = _initial_arrays(initial, modified, size)
    command_fn = _command_source(modified, controller, rotor_speed_series, periods, size)
    if engine == "mujoco":
        from .mujoco_engine import default_timestep, run_mujoco

        dt = timestep or default_timestep(control_period)
        out = None
        if fast is not False:
            from .compiled import run_mujoco_fast

            out = run_mujoco_fast(modified, batch_effects, start, command_fn, periods,
                                  control_period, timestep=dt, nthread=nthread,
                                  require=bool(fast))
        if out is None:
            out = run_mujoco(modified, batch_effects, start, command_fn, periods,
                             control_period, timestep=dt, nthread=nthread)
        meta = {"integrator": "MuJoCo RK4", "timestep": dt}
    else:
        rhs = None
        if fast is not False:
            from .compiled import analytic_fast_rhs

            rhs = analytic_fast_rhs(modified, batch_effects, body_arrays(modified))
        out = run_analytic(modified, batch_effects, start, command_fn, periods, control_period,
                           rtol=rtol, atol=atol, rhs=rhs)
        meta = {"integrator": "scipy solve_ivp DOP853", "rtol": rtol, "atol": atol}
    meta.update(control_period=control_period, params=[p.name for p in modified])
    if not batched:
        out = {k: v[0] for k, v in out.items()}
    return Trajectory(t=np.arange(periods + 1) * control_period, engine=engine, meta=meta, **out)
