"""Fast MuJoCo path: the effects and MuJoCo's C ``mj_step`` in one compiled loop (numba).

Same physics as the step-by-step reference of :mod:`quadsim.sim.mujoco_engine` — the same
per-step recipe (rotor lag integrated with two RK4 half steps on the held command, actuators
driven by the step's Simpson mean ``Omega^2`` times the thrust scale, every other load
evaluated once per step at the predicted mid-step state and applied to the free joint
through ``qfrc_applied``) — but written as one numba kernel that also calls ``mj_step`` of
``libmujoco`` through ctypes on each simulation's own ``MjData``. A whole open-loop series
(or one control period under a controller) is one Python call; simulations of a batch run in
parallel threads (the kernel releases the GIL; MuJoCo is thread-safe across ``MjData``).
``tests/test_fast_mujoco.py`` checks that it matches the reference path to 1e-9 m.

Effects with a fast form (the kernel's own formulas, each a transcription of the effect's
module docstring): every effect of the library — motor_lag, thrust_curve, thrust_mismatch,
rotor_drag, blade_flapping, translational_lift, body_drag, ground_effect, gyroscopic, wind,
thrust_factor, rate_damping, battery_sag (its time model: the command times
sqrt(max(MIN_SCALE, 1 - rate t)) at every
rotor RK4 stage, then motor_lag's lag or SPEED_RESPONSE_S; thrust_factor's speed gain
(1 + change)^-alpha multiplies it), cable_payload (the kernel carries
the payload state p, v (6,) per simulation, integrated like the reference: two RK4 half steps
per timestep along the predicted body state) — and every effect that only changes the
parameter set (com_offset, mass_offset, inertia_error, canted_rotor). :func:`fast_form_problem`
names the first effect that has none (another class, a repeated effect, a parameter the
kernel does not know); the engine then uses the reference path —
never an approximation.

Optional: needs numba (``pip install -e '.[fast]'``); without it :func:`available` is False
and the engine uses the reference path. Units SI throughout (m, s, rad, N, N m).
"""

from __future__ import annotations

import ctypes
import functools
import os
import threading
from collections.abc import Sequence

import numpy as np

from ...core.frames import quat_normalize
from ...effects.base import EffectSet
from ...vehicle.params import VehicleParams
from ..analytic import BatchEffects
from .layout import GUST, MAX_ROTORS, WIDTH
from .layout import OFFSET as _OFFSET

__all__ = ["GUST", "MAX_ROTORS", "Kernel", "analytic_fast_rhs", "available", "encode",
           "fast_form_problem", "run_mujoco_fast"]


# Parameter names each fast form reads (an effect with other parameters has no fast form).
_KNOWN = {
    "motor_lag": {"time_constant", "time_constant_down"},
    "thrust_curve": {"linear", "offset", "centre", "quadratic"},
    "thrust_mismatch": {f"rotor_{i}" for i in range(1, MAX_ROTORS + 1)} | {"alpha", "torque_share"},
    "rotor_drag": {"coefficient", "axial_coefficient"},
    "blade_flapping": {"roll", "pitch", "coefficient"},
    "translational_lift": {"k_h"},
    "body_drag": {"cd_area", "cd_area_vertical", "per_axis"},
    "ground_effect": {"gain", "ground_height", "radius"},
    "gyroscopic": {"rotor_inertia"},
    "wind": {"vx", "vy", "vz", "gust", "bandwidth", "seed"},
    "battery_sag": {"rate", "full_voltage"},
    "thrust_factor": {"change", "alpha"},
    "rate_damping": {"x", "y", "z"},
    "cable_payload": {"mass", "length", "x", "y", "z", "axial_frequency", "damping_ratio"},
}
#: effects that only change the parameter set (apply_to_params)
_STATIC = {"com_offset", "mass_offset", "inertia_error", "canted_rotor"}
#: internal states the kernel carries per simulation (cable_payload: payload p, v)
PAYLOAD_STATES = 6

try:
    import numba
except ImportError:      # pragma: no cover - exercised when the extra is absent
    numba = None


def _library():
    import mujoco

    folder = os.path.dirname(mujoco.__file__)
    names = sorted(n for n in os.listdir(folder) if n.startswith("libmujoco.so")
                   or n.startswith("libmujoco.") and n.endswith(".dylib") or n == "mujoco.dll")
    if not names:
        return None
    lib = ctypes.CDLL(os.path.join(folder, names[0]))
    return np.array([ctypes.cast(lib.mj_step, ctypes.c_void_p).value,
                     ctypes.cast(lib.mj_getState, ctypes.c_void_p).value], dtype=np.int64)


def available() -> bool:
    """True when numba is installed and MuJoCo's C library can be called from it."""
    return _kernels() is not None


def _effect_problem(effect, seen: set) -> str | None:
    from ... import effects as library

    name = getattr(effect, "name", type(effect).__name__)
    if library.EFFECTS.get(name) is not type(effect):
        return f"effect {name!r} ({type(effect).__name__}) has no fast form"
    if name in seen:
        return f"effect {name!r} appears twice in one set"
    seen.add(name)
    if name in _STATIC:
        return None
    if name not in _KNOWN or set(effect.values()) != _KNOWN[name]:
        return f"effect {name!r} has parameters the fast form does not know"
    return None


def fast_form_problem(sets: Sequence[EffectSet], params: Sequence[VehicleParams]) -> str | None:
    """Why these effect sets cannot run on the fast path (None: they can)."""
    if _kernels() is None:
        return "numba is not installed (pip install -e '.[fast]')"
    if params[0].rotor_count > MAX_ROTORS:
        return f"more than {MAX_ROTORS} rotors"
    for effect_set in {id(s): s for s in sets}.values():
        seen: set = set()
        for effect in effect_set.effects:
            problem = _effect_problem(effect, seen)
            if problem:
                return problem
    for effect_set, p in zip(sets, params):
        for effect in effect_set.effects:
            if effect.name == "ground_effect" and effect.gain != 0.0 \
                    and not (effect.radius or p.rotor_radius) > 0.0:
                return "ground_effect without a rotor radius"
            if effect.name == "thrust_mismatch":
                values = effect.values()
                if values["torque_share"] != 1.0:
                    return "thrust_mismatch with a torque share other than 1"
                if any(values[f"rotor_{i}"] != 0.0
                       for i in range(p.rotor_count + 1, MAX_ROTORS + 1)):
                    return "thrust_mismatch beyond the vehicle's rotors"
    return None


def encode(sets: Sequence[EffectSet], params: Sequence[VehicleParams]) -> tuple[np.ndarray, bool]:
    """(B, WIDTH) effect parameters for the kernel and whether any rotor has lag dynamics.
    Call only when :func:`fast_form_problem` returned None."""
    rows = np.zeros((len(params), WIDTH))
    from ...effects.base import SPEED_RESPONSE_S

    rows[:, _OFFSET["mismatch"]:_OFFSET["mismatch"] + MAX_ROTORS] = 1.0
    rows[:, _OFFSET["rotor_speed_gain"]:_OFFSET["rotor_speed_gain"] + MAX_ROTORS] = 1.0
    rows[:, _OFFSET["thrust_gain"]] = rows[:, _OFFSET["speed_gain"]] = 1.0
    # a speed factor (battery) without a lag effect: the rotor follows with SPEED_RESPONSE_S
    rows[:, _OFFSET["tau_up"]] = rows[:, _OFFSET["tau_down"]] = SPEED_RESPONSE_S
    lags = [s.has_rotor_dynamics() for s in sets]
    if any(lags) and not all(lags):
        raise ValueError("either every simulation of a batch has rotor dynamics or none")
    lag = bool(lags) and all(lags)
    done: dict[tuple[int, int], int] = {}   # a (set, params) pair seen before: copy its row
    for i, (row, effect_set, p) in enumerate(zip(rows, sets, params)):
        seen = done.setdefault((id(effect_set), id(p)), i)
        if seen != i:
            row[:] = rows[seen]
            continue
        row[_OFFSET["air_density"]] = p.air_density
        row[_OFFSET["gravity"]] = p.gravity
        row[_OFFSET["com"]:_OFFSET["com"] + 3] = p.com
        for effect in effect_set.effects:
            v = effect.values()
            put = functools.partial(_put, row)
            if effect.name == "motor_lag" and v["time_constant"] > 0.0:
                put("tau_up", v["time_constant"])
                put("tau_down", v["time_constant_down"] if v["time_constant_down"] > 0.0
                    else v["time_constant"])
            elif effect.name == "thrust_mismatch":
                put("mismatch", [1.0 + v[f"rotor_{i}"] for i in range(1, MAX_ROTORS + 1)])
                gains = effect.rotor_speed_factor(MAX_ROTORS)
                if gains is not None:
                    put("rotor_speed_gain", gains)
            elif effect.name == "battery_sag":
                put("battery_rate", v["rate"])
            elif effect.name == "thrust_factor":
                put("thrust_gain", 1.0 + v["change"])
                put("speed_gain", effect.speed_gain())
            elif effect.name == "rate_damping":
                put("rate_damping", [v["x"], v["y"], v["z"]])
            elif effect.name == "cable_payload" and v["mass"] > 0.0:
                attach = np.array([v["x"], v["y"], v["z"]])
                put("payload_mass", v["mass"])
                put("payload_length", v["length"])
                put("payload_attach", attach)
                put("payload_arm", attach - p.com)
                put("payload_stiffness", effect.stiffness)
                put("payload_damping", effect.damping)
            elif effect.name == "ground_effect":
                put("ground_gain", v["gain"])
                put("ground_height", v["ground_height"])
                put("ground_radius", v["radius"] or p.rotor_radius)
            elif effect.name == "thrust_curve":
                # expanded about zero speed: q W^2 + (l - 2 q c) W + (o - l c + q c^2)
                q, c = v["quadratic"], v["centre"]
                put("curve_quadratic", q)
                put("curve_linear", v["linear"] - 2.0 * q * c)
                put("curve_offset", v["offset"] - v["linear"] * c + q * c * c)
            elif effect.name == "rotor_drag":
                put("rotor_drag", v["coefficient"])
                put("rotor_drag_axial", v["axial_coefficient"])
            elif effect.name == "blade_flapping":
                roll, pitch = effect.axes          # the z row takes their mean
                put("blade_flapping", [roll, pitch, 0.5 * (roll + pitch)])
            elif effect.name == "translational_lift":
                put("translational_lift", v["k_h"])
            elif effect.name == "body_drag":
                put("body_drag", [v["cd_area"], v["cd_area"], v["cd_area_vertical"]])
                put("body_drag_axes", v["per_axis"])
            elif effect.name == "gyroscopic":
                put("rotor_inertia", v["rotor_inertia"])
            elif effect.name == "wind":
                put("wind_mean", [v["vx"], v["vy"], v["vz"]])
                if v["gust"] > 0.0:
                    put("gust_amplitude", v["gust"] * np.sqrt(2.0 / GUST))
                    put("gust_frequency", effect._frequencies)
                    put("gust_phase", effect._phases.ravel())
    return rows, lag


_CACHE: dict = {}


def _put(row: np.ndarray, key: str, value) -> None:
    row[_OFFSET[key]:_OFFSET[key] + np.size(value)] = value


def _kernels():
    if "run" in _CACHE:
        return _CACHE["run"]
    _CACHE["run"] = None
    if numba is None:
        return None
    functions = _library()
    if functions is None:
        return None
    from . import kernel as _fast_kernel

    _CACHE["functions"] = functions
    _CACHE["run"] = _fast_kernel.run
    return _CACHE["run"]


class Kernel:
    """Advance B MuJoCo simulations (one MjModel/MjData each) with the compiled loop.

    ``models``/``datas``: the per-simulation MjModel and MjData (states already set, forward
    computed); ``body_id`` the vehicle body; ``consts`` the per-simulation rotor geometry."""

    def __init__(self, models, datas, body_id: int, rotor_arm: np.ndarray,
                 rotor_axis: np.ndarray, rotor_spin: np.ndarray, rotor_position: np.ndarray,
                 effect_rows: np.ndarray, lag: bool, active: bool, nthread: int = 0,
                 extra: np.ndarray | None = None):
        self.run = _kernels()
        self.datas = datas
        self.models = models            # keep the objects alive while their addresses are used
        b = len(datas)
        self.addr = np.zeros((b, 8), dtype=np.int64)
        for i, (m, d) in enumerate(zip(models, datas)):
            self.addr[i] = [m._address, d._address, d.qpos.ctypes.data, d.qvel.ctypes.data,
                            d.qacc.ctypes.data, d.ctrl.ctypes.data,
                            d.qfrc_applied.ctypes.data + 8 * int(m.body_dofadr[body_id]), 0]
        self.rotor_arm = np.ascontiguousarray(rotor_arm, dtype=float)
        self.rotor_axis = np.ascontiguousarray(rotor_axis, dtype=float)
        self.rotor_spin = np.ascontiguousarray(rotor_spin, dtype=float)
        self.rotor_position = np.ascontiguousarray(rotor_position, dtype=float)
        self.rows = np.ascontiguousarray(effect_rows, dtype=float)
        #: (B, 6) internal effect states (cable_payload's payload position and velocity,
        #: world), advanced in place
        self.extra = np.zeros((b, PAYLOAD_STATES)) if extra is None \
            else np.ascontiguousarray(extra, dtype=float)
        self.lag, self.active = bool(lag), bool(active)
        self.threads = nthread
        self._pool = None

    def advance(self, commands: np.ndarray, omega: np.ndarray, k0: int, substeps: int,
                dt: float, period: float, out: np.ndarray, status: np.ndarray) -> None:
        """Run ``commands`` (B, K, R) over K periods from period k0; ``omega`` (B, R) actual
        rotor speeds (updated); writes the state at the end of each period into ``out``
        (B, K, 13 + R) and the first failing period + 1 of a diverged simulation into
        ``status`` (B,) (0 = fine; such a simulation is not stepped further)."""
        commands = np.ascontiguousarray(commands)
        batch = len(self.datas)
        threads = self.threads or os.cpu_count() or 1
        chunks = np.array_split(np.arange(batch), min(threads, batch))

        def part(idx):
            sl = slice(idx[0], idx[-1] + 1)
            self.run(_CACHE["functions"], self.addr[sl], commands[sl], omega[sl], k0, substeps,
                     dt, period, self.rotor_arm[sl], self.rotor_axis[sl], self.rotor_spin,
                     self.rotor_position[sl], self.rows[sl], self.extra[sl], self.lag,
                     self.active, out[sl],
                     status[sl])

        if len(chunks) == 1:
            part(chunks[0])
            return
        list(_thread_pool(len(chunks)).map(part, chunks))

    def close(self) -> None:
        """Kept for callers; the worker threads are shared between runs (:func:`_thread_pool`)."""


_THREADS: dict[int, object] = {}


def _thread_pool(count: int):
    """A process-wide pool of ``count`` worker threads (made once: starting and joining
    threads per simulation call cost as much as a few thousand steps)."""
    with _POOL_LOCK:
        pool = _THREADS.get(count)
        if pool is None:
            from concurrent.futures import ThreadPoolExecutor

            pool = _THREADS[count] = ThreadPoolExecutor(count, thread_name_prefix="quadsim")
        return pool


#: MjData of finished runs kept for reuse (creating one costs ~1-2 ms through the Python
#: binding, as much as a hundred steps): per model at most as many as fit in _POOL_BYTES
#: (arena + buffer of each), at most _POOL_MODELS models.
_POOL: dict[int, tuple] = {}
_POOL_BYTES, _POOL_MODELS = 256 * 2**20, 8
_POOL_LOCK = threading.Lock()


def _take_data(model):
    """An MjData of ``model`` in its reset state (mj_resetData: as if newly made)."""
    import mujoco

    with _POOL_LOCK:
        entry = _POOL.get(id(model))
        data = entry[1].pop() if entry and entry[0] is model and entry[1] else None
    if data is None:
        return mujoco.MjData(model)
    mujoco.mj_resetData(model, data)
    return data


def _give_data(model, data) -> None:
    with _POOL_LOCK:
        entry = _POOL.get(id(model))
        if entry is None or entry[0] is not model:
            while len(_POOL) >= _POOL_MODELS:
                del _POOL[next(iter(_POOL))]
            entry = _POOL[id(model)] = (model, [])
        if (len(entry[1]) + 1) * (model.narena + model.nbuffer) <= _POOL_BYTES:
            entry[1].append(data)


def run_fast(models, body_id: int, sets: Sequence[EffectSet], params: Sequence[VehicleParams],
             body, initial: dict, command_fn, periods: int, control_period: float,
             dt: float, nthread: int = 0) -> tuple[dict, np.ndarray]:
    """Run the whole simulation on the fast path (same contract as
    :func:`quadsim.sim.mujoco_engine.run_mujoco`). Returns the output dict and the status (B,)
    (0 = fine, else 1 + the index of the control period in which that simulation diverged;
    its samples from then on are NaN)."""
    import mujoco

    substeps = round(control_period / dt)
    batch, rotors = len(params), params[0].rotor_count
    datas = []
    for i, m in enumerate(models):
        d = _take_data(m)
        d.qpos[0:3], d.qpos[3:7] = initial["position"][i], quat_normalize(initial["quat"][i])
        d.qvel[0:3], d.qvel[3:6] = initial["velocity"][i], initial["body_rate"][i]
        mujoco.mj_forward(m, d)
        # The reference path's first mid-step prediction sees zero accelerations (its bound
        # qacc is only filled by the first step); match it exactly.
        d.qacc[:] = 0.0
        datas.append(d)
    rows, lag = encode(sets, params)
    active = any(s.effects for s in sets)
    extra = np.zeros((batch, PAYLOAD_STATES))
    effects = BatchEffects(sets, params)
    if effects.state_size:      # the same start as the reference path (cable_payload only)
        extra[:, :effects.state_size] = effects.initial_state(initial)
    kernel = Kernel(models, datas, body_id, body.rotor_arm, body.rotor_axis, body.rotor_spin,
                    np.array([p.rotor_positions for p in params]), rows, lag, active, nthread,
                    extra)
    omega = np.array(initial["rotor_speed"], dtype=float)
    status = np.zeros(batch, dtype=np.int64)
    ends = np.empty((batch, periods, 13 + rotors))
    first = {"t": np.zeros(batch), "position": initial["position"].copy(),
             "velocity": initial["velocity"].copy(),
             "quat": np.array([d.qpos[3:7] for d in datas]),
             "body_rate": initial["body_rate"].copy(), "rotor_speed": omega.copy()}
    try:
        commands = _drive(kernel, command_fn, first, ends, omega, status, batch, rotors,
                          periods, substeps, dt, control_period)
    finally:
        kernel.close()
        for m, d in zip(models, datas):
            _give_data(m, d)
    out = {"position": np.concatenate([first["position"][:, None], ends[:, :, 0:3]], 1),
           "velocity": np.concatenate([first["velocity"][:, None], ends[:, :, 3:6]], 1),
           "quat": np.concatenate([first["quat"][:, None], ends[:, :, 6:10]], 1),
           "body_rate": np.concatenate([first["body_rate"][:, None], ends[:, :, 10:13]], 1)}
    if lag:
        out["rotor_speed"] = np.concatenate([first["rotor_speed"][:, None], ends[:, :, 13:]], 1)
    else:
        out["rotor_speed"] = np.concatenate([commands, commands[:, -1:]], 1)
    out["rotor_command"] = np.concatenate([commands, commands[:, -1:]], 1)
    return out, status


def analytic_rhs(sets: Sequence[EffectSet], params: Sequence[VehicleParams], body):
    """Compiled right-hand side for :mod:`quadsim.sim.analytic` (the same equations as
    ``state_derivative``, every effect in the kernel): ``rhs(t, y, command) -> dy/dt``.
    Call only when :func:`fast_form_problem` returned None."""
    from . import kernel as _fast_kernel

    rows, lag = encode(sets, params)
    active = any(s.effects for s in sets)
    size = max(s.state_size() for s in sets)
    hub = np.ascontiguousarray([p.rotor_positions for p in params], dtype=float)
    arrays = [np.ascontiguousarray(a, dtype=float) for a in (
        body.rotor_arm, body.rotor_axis, body.rotor_spin, hub, body.allocation, body.mass,
        body.com, body.inertia, body.inertia_inv, body.gravity, body.thrust_factor,
        body.drag_factor)]

    def rhs(t: float, y: np.ndarray, command: np.ndarray) -> np.ndarray:
        out = np.empty_like(y)
        _fast_kernel.analytic_rhs(float(t), y, command, lag, active, size, rows, *arrays,
                                  out)
        return out

    return rhs


def _drive(kernel, command_fn, first, ends, omega, status, batch, rotors, periods, substeps,
           dt, control_period) -> np.ndarray:
    """The whole open-loop series in one kernel call, or one call per control period with
    the controller in between (vectorised over the batch). Returns the commands (B, N, R)."""
    series = getattr(command_fn, "series", None)
    if series is not None:
        commands = np.ascontiguousarray(series[:, :periods], dtype=float)
        kernel.advance(commands, omega, 0, substeps, dt, control_period, ends, status)
    else:
        commands = np.empty((batch, periods, rotors))
        # one period's end states in a C-contiguous buffer: a slice ends[:, k:k + 1] is not,
        # and numba would compile the kernel a second time for that layout (~15 s, cold cache)
        step = np.empty((batch, 1, ends.shape[2]))
        state = first
        for k in range(periods):
            if k:
                row = ends[:, k - 1].copy()
                if status.any():      # a diverged simulation's controller sees its start
                    row[status > 0] = np.concatenate([first["position"], first["velocity"],
                                                      first["quat"], first["body_rate"],
                                                      first["rotor_speed"]], 1)[status > 0]
                state = {"t": np.full(batch, k * control_period), "position": row[:, 0:3],
                         "velocity": row[:, 3:6], "quat": row[:, 6:10],
                         "body_rate": row[:, 10:13], "rotor_speed": row[:, 13:].copy()}
            commands[:, k] = command_fn(k, state)
            kernel.advance(commands[:, k:k + 1], omega, k, substeps, dt, control_period,
                           step, status)
            ends[:, k] = step[:, 0]
    return commands


def _sets_by_simulation(effects: BatchEffects, count: int) -> list:
    sets = [None] * count
    for effect_set, _, idx in effects.groups:
        for i in idx:
            sets[i] = effect_set
    return sets


def analytic_fast_rhs(params: Sequence[VehicleParams], effects: BatchEffects, body):
    """The compiled right-hand side for :func:`quadsim.sim.analytic.run_analytic` (its
    ``rhs``), or None when these effects have no fast form (the engine then evaluates
    ``state_derivative``)."""
    sets = _sets_by_simulation(effects, len(params))
    if fast_form_problem(sets, params) is not None:
        return None
    return analytic_rhs(sets, params, body)


def run_mujoco_fast(params: Sequence[VehicleParams], effects: BatchEffects, initial: dict,
                    command_fn, periods: int, control_period: float, *, timestep: float,
                    nthread: int = 0, require: bool = False) -> dict | None:
    """:func:`quadsim.sim.mujoco_engine.run_mujoco` on the compiled path (same contract and
    output), or None when it cannot run these effects (``require``: ``InputError`` naming
    what prevents it instead). Raises ``SimulationError`` (with ``.partial``) on divergence."""
    import mujoco

    from ...core.errors import InputError, SimulationError
    from ..analytic import STATE_BOUND, body_arrays
    from ..mujoco_engine import BODY_NAME, check_memory, compiled_models

    sets = _sets_by_simulation(effects, len(params))
    problem = fast_form_problem(sets, params)
    if problem:
        if require:
            raise InputError(f"mujoco engine: fast path unavailable: {problem}")
        return None
    substeps = int(round(control_period / timestep))
    models = compiled_models(params, timestep)
    check_memory(models[0], len(params), periods, params[0].rotor_count)
    body = body_arrays(params)
    body_id = mujoco.mj_name2id(models[0], mujoco.mjtObj.mjOBJ_BODY, BODY_NAME)
    out, status = run_fast(models, body_id, sets, params, body, initial, command_fn, periods,
                           control_period, timestep, nthread)
    if status.any():
        bad = np.flatnonzero(status)
        raise SimulationError(
            f"mujoco engine: simulation(s) {bad.tolist()} diverged before t = "
            + ", ".join(f"{status[i] * control_period:.4g}" for i in bad)
            + f" s (NaN, MuJoCo reset after a bad acceleration, or state beyond "
            f"{STATE_BOUND:g}); the others' results are in this error's .partial",
            partial=out, diverged=bad.tolist())
    assert substeps >= 1
    return out
