"""The static command -> rotor-speed map of the gap diagnosis (fitted from data).

Logs normalise commands differently (``quadsim.fly``: speed / max_speed; the Crazyflie
firmware: PWM / 65535), so the rotor channel's static map is taken from the data (training
or reference flights): what the rotor channel then measures is the rotor *dynamics*, and
effects upstream of the speed (a battery's voltage, a motor lag) act on top of it.

Example::

    >>> from quadsim.gap.motor_map import fit_motor_map, speed_of_command
    >>> tuned = fit_motor_map([states], params)          # FlightStates with commands
    >>> speed_of_command(tuned, np.full((1, 4), 0.5))    # rad/s per rotor

Commands are normalised 0-1 (per rotor); speeds in rad/s.
"""

from __future__ import annotations

import numpy as np

from ..vehicle.params import VehicleParams
from .residual import FlightStates

__all__ = ["fit_motor_map", "command_speed", "speed_of_command", "command_of_speed",
           "MAP_WINDOW_S", "MAP_MIN_RANGE"]


def fit_motor_map(flights: list[FlightStates], params: VehicleParams) -> VehicleParams:
    """``params`` with a per-rotor straight-line map cmd (0-1) -> speed fitted on ``flights``.

    Logs normalise commands differently (``quadsim.fly``: speed / max_speed; the Crazyflie
    firmware: PWM / 65535), so the rotor channel's static map is taken from the (training or
    reference) data; what the channel then measures is the rotor *dynamics*.

    The map is static, so it is fitted on both signals averaged over
    :data:`MAP_WINDOW_S` (moving mean, per flight, edges dropped): a measured speed that
    follows the command with a lag tau (motor, ESC telemetry, filtering) regressed on the
    raw command has its slope shrunk to the command's autocorrelation at tau (a
    30 ms lag on a 2 Hz manoeuvre: cos(2 pi 2 0.03) = 0.93), and a vehicle flying at other
    commands than the training flights (heavier, faster) would then show the map's error as
    a gap on the rotor channel; averaged over 0.5 s the lag costs < 1 %. Commands spanning
    less than :data:`MAP_MIN_RANGE` of their mean (a gentle path: the independent
    benchmark's Crazyflie references span 2 rad/s of 1565) cannot fix a slope: the map is
    then the proportional gain through the origin."""
    from ..vehicle.params import MotorMap

    usable = [f for f in flights if f.command is not None and f.rotor_speed is not None]
    if not usable:
        return params
    dt = [float(np.median(np.diff(f.t))) if len(f.t) > 1 else 1.0 for f in usable]
    command = np.concatenate([_moving_mean(f.command, w) for f, w in zip(usable, dt)])
    speed = np.concatenate([_moving_mean(f.rotor_speed, w) for f, w in zip(usable, dt)])
    ends = []
    for i in range(speed.shape[1]):
        c, w = command[:, i], speed[:, i]
        if np.ptp(c) <= 0:
            return params
        if np.ptp(c) < MAP_MIN_RANGE * np.mean(np.abs(c)):
            # too narrow a range of commands to fix a slope (a gentle path: the line's slope
            # would be noise, and a flight at other commands would read its error as a gap):
            # the one-parameter map through the origin, speed = k command
            slope, intercept = float(c @ w / (c @ c)), 0.0
        else:
            slope, intercept = np.polyfit(c, w, 1)
        ends.append([intercept, intercept + slope])
    return params.replace(motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array(ends),
                                             "fitted on the training flights (quadsim.gap)"))


#: window (s) of the moving mean on which the static motor map is fitted.
MAP_WINDOW_S = 0.5
#: relative range of the (averaged) commands below which the map is a proportional gain.
MAP_MIN_RANGE = 0.05


def _moving_mean(x: np.ndarray, dt: float) -> np.ndarray:
    """(N, C) moving mean over MAP_WINDOW_S ('valid' part; the signal itself when shorter)."""
    n = max(1, int(round(MAP_WINDOW_S / dt)))
    if len(x) <= n:
        return x
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    return (c[n:] - c[:-n]) / n


def command_speed(states: FlightStates, params: VehicleParams) -> np.ndarray | None:
    """Commanded rotor speed (N, R) rad/s from normalised commands: the parameter set's motor
    map, else ``command * max_speed``. None without commands."""
    if states.command is None:
        return None
    return speed_of_command(params, states.command)


def _map_units(params: VehicleParams, command: np.ndarray) -> np.ndarray:
    """Normalised 0-1 command -> the motor map's own command unit (0-1 spans its table)."""
    mm = params.motor_map
    if mm.command_unit == "1":
        return command
    return mm.command[0] + command * (mm.command[-1] - mm.command[0])


def speed_of_command(params: VehicleParams, command: np.ndarray) -> np.ndarray:
    """Steady rotor speed (rad/s) of normalised commands (..., R): the motor map (a map in
    other units, e.g. PWM, is spanned by 0-1 over its table), else ``command * max_speed``."""
    if params.motor_map is not None:
        return params.motor_map.speed_of(_map_units(params, command))
    return command * params.max_speed


def command_of_speed(params: VehicleParams, speed: np.ndarray) -> np.ndarray:
    """Inverse of :func:`speed_of_command` (N, R) (monotone part of the map)."""
    if params.motor_map is None:
        return speed / params.max_speed
    mm = params.motor_map
    raw = np.stack([np.interp(speed[:, i], mm.speed[i], mm.command)
                    for i in range(speed.shape[1])], -1)
    if mm.command_unit == "1":
        return raw
    return (raw - mm.command[0]) / (mm.command[-1] - mm.command[0])
