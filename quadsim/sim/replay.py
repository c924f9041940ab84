"""Model flights to look at: an LQR hover-and-step flight in both engines, and a measured log
replayed through the model by multiple shooting.

:func:`step_flight` flies :func:`step_reference` (hover at 1 m, x step 0.5 m at 1 s, z step
0.5 m at 3 s, yaw step 0.5 rad at 5 s) with an LQR on the hover linearisation, in MuJoCo and
the analytic Newton-Euler model. :func:`replay_log` drives the model with a log's measured
rotor speeds (rad/s, zero-order hold at the log's median sample period), restarting from the
measured state every ``horizon`` seconds: an open-loop quadrotor drifts away within a second or
two, so one open-loop run over a whole flight would show little. All segments run as one
batch. Units SI (m, m/s, rad, rad/s, s).

Example::

    >>> from quadsim.sim.replay import replay_log
    >>> runs = replay_log(load_params("crazyflie21"), measured_trajectory, horizon=1.0)
    >>> runs["mujoco"].position.shape                 # (N, 3), on the log's time base

The command ``python -m quadsim.view`` records these in rerun.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import InputError
from ..vehicle.params import VehicleParams
from ..vehicle.state import Trajectory
from .engines import initial_state, simulate
from .linear import LQRController

__all__ = ["ENGINES", "replay_log", "step_flight", "step_reference"]

ENGINES = ("mujoco", "analytic")


def step_reference(t: np.ndarray, *, start=(0.0, 0.0, 1.0), step_x: float = 0.5,
                   step_z: float = 0.5, step_yaw: float = 0.5) -> np.ndarray:
    """Desired 12-state (B, 12) at times t (B,): hover at ``start``, x step (m) at 1 s, z step
    (m) at 3 s, yaw step (rad) at 5 s."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    target = np.zeros((len(t), 12))
    target[:, :3] = start
    target[:, 0] += np.where(t >= 1.0, step_x, 0.0)
    target[:, 2] += np.where(t >= 3.0, step_z, 0.0)
    target[:, 8] = np.where(t >= 5.0, step_yaw, 0.0)
    return target


def step_flight(params: VehicleParams, *, engines=ENGINES, duration: float = 7.0,
                control_period: float = 0.01) -> dict[str, Trajectory]:
    """LQR hover-and-step flight (:func:`step_reference`) in each engine."""
    controller = LQRController(params, position=(0.0, 0.0, 1.0), reference=step_reference)
    start = initial_state(position=(0.0, 0.0, 1.0))
    return {engine: simulate(params, engine=engine, initial=start, controller=controller,
                             duration=duration, control_period=control_period)
            for engine in engines}


def _segments(t: np.ndarray, horizon: float, period: float) -> tuple[np.ndarray, int]:
    """Start times of the shooting segments and the number of control periods in each."""
    span = t[-1] - t[0]
    horizon = span if horizon <= 0 or horizon > span else horizon
    steps = max(1, int(round(horizon / period)))
    count = max(1, int(np.floor(span / (steps * period) + 1e-9)))
    return t[0] + np.arange(count) * steps * period, steps


def _interp(t_from: np.ndarray, values: np.ndarray, t_to: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t_to, t_from, values[:, k]) for k in range(values.shape[1])], -1)


def replay_log(params: VehicleParams, measured: Trajectory, *, engines=ENGINES,
               horizon: float = 1.0) -> dict[str, Trajectory]:
    """Drive the model with the measured rotor speeds (zero-order hold at the log's median
    sample period), restarting from the measured state every ``horizon`` s (<= 0: one run
    over the whole log). All segments run as one batch; the result is stitched back into one
    trajectory per engine (segment ends dropped where the next segment starts)."""
    t = np.asarray(measured.t, dtype=float)
    if measured.rotor_speed.shape[-1] != params.rotor_count:
        raise InputError(f"log has {measured.rotor_speed.shape[-1]} rotor speed columns, model "
                         f"{params.name!r} has {params.rotor_count} rotors (rotor_1..rotor_"
                         f"{params.rotor_count} in rad/s are needed to drive it)")
    period = float(np.median(np.diff(t)))
    starts, steps = _segments(t, horizon, period)
    grid = starts[:, None] + np.arange(steps)[None, :] * period  # (B, steps)
    series = _interp(t, measured.rotor_speed, grid.ravel()).reshape(len(starts), steps, -1)
    quat = _interp(t, measured.quat, starts)
    start = initial_state(position=_interp(t, measured.position, starts),
                          velocity=_interp(t, measured.velocity, starts),
                          quat=quat / np.linalg.norm(quat, axis=-1, keepdims=True),
                          body_rate=_interp(t, measured.body_rate, starts),
                          rotor_speed=series[:, 0])
    return {engine: _stitch(simulate(params, engine=engine, initial=start,
                                     rotor_speed_series=series, duration=steps * period,
                                     control_period=period, batch=len(starts)), starts)
            for engine in engines}


def _stitch(batch: Trajectory, starts: np.ndarray) -> Trajectory:
    """One trajectory from a (B, n+1) batch of consecutive segments starting at ``starts``."""
    last = len(starts) - 1

    def join(values):
        if values is None:
            return None
        return np.concatenate([values[i, : None if i == last else -1] for i in range(last + 1)])

    t = np.concatenate([starts[i] + batch.t[: None if i == last else -1]
                        for i in range(last + 1)])
    return Trajectory(t, join(batch.position), join(batch.velocity), join(batch.quat),
                      join(batch.body_rate), join(batch.rotor_speed), join(batch.rotor_command),
                      batch.engine, dict(batch.meta))
