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

__all__ = ["fit_motor_map", "load_exponent", "command_speed", "speed_of_command",
           "command_of_speed", "MAP_WINDOW_S", "MAP_MIN_RANGE"]


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
    a gap on the rotor channel; averaged over 0.5 s the lag costs < 1 %.

    Per rotor, the map is the straight line ``a + k command`` or the proportional gain
    through the origin ``k command`` (an ideal motor and ESC). The line needs both a range of
    commands of at least :data:`MAP_MIN_RANGE` of their mean and the data's support
    (:func:`_line_supported`: the Bayesian information criterion on the averaged samples,
    counted as one per window). Why the range: over a narrower one (a gentle path: the
    independent benchmark's Crazyflie references span 2 rad/s of 1565) the line's slope is
    noise, and the moving mean's leftover lag still favours it. Why the support: measured
    on the l2f source (an X500 whose rotor speed is exactly proportional to its command;
    references flown at mean commands 0.557-0.564, each rotor's range 5-6 %), the range
    alone took the line on three rotors, with intercepts of 8-11 rad/s, off by 0.3-0.5
    rad/s at the mean command 0.58 of a +160 g flight, 0.5 of the rotor channel's noise;
    the propeller reading's free speed-per-command exponent took that up and named the mass
    a propeller change at 100 %, twice."""
    from ..vehicle.params import MotorMap

    means = _window_means(flights)
    if means is None:
        return params
    command, speed, windows = means
    ends = []
    for i in range(speed.shape[1]):
        c, w = command[:, i], speed[:, i]
        if np.ptp(c) <= 0:
            return params
        slope, intercept = float(c @ w / (c @ c)), 0.0
        if np.ptp(c) >= MAP_MIN_RANGE * np.mean(np.abs(c)):
            line = np.polyfit(c, w, 1)
            if _line_supported(c, w, (slope, intercept), line, windows):
                slope, intercept = line
        ends.append([intercept, intercept + slope])
    return params.replace(motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array(ends),
                                             "fitted on the training flights (quadsim.gap)"))


#: window (s) of the moving mean on which the static motor map is fitted.
MAP_WINDOW_S = 0.5
#: relative range of the (averaged) commands below which the map is a proportional gain.
MAP_MIN_RANGE = 0.05


def load_exponent(flights: list[FlightStates], params: VehicleParams
                  ) -> tuple[float, float] | None:
    """How much faster a motor spins per command when its propeller's load torque falls, as
    the references' own command -> speed map says: (alpha, its spread) with a command giving
    (1 + change)^-alpha of its speed for a propeller whose thrust and drag torque per Omega^2
    change by ``change`` (:mod:`quadsim.effects.thrust_factor`); None where the commands span
    less than :data:`MAP_MIN_RANGE` of their mean (the slope is noise there).

    Physics: a motor driven by a duty cycle u at voltage V turns where
    ``u V = k Omega + (R d / k) Omega^2`` (back EMF and the resistive drop of the load
    torque d Omega^2). At a fixed command a load change d (1 + c) moves the speed by
    ``dln Omega / dc = -s / (1 + s)``, s = R d Omega / k^2 the load's share, and the map's
    elasticity is ``eps = dln Omega / dln u = (1 + s) / (1 + 2 s)``; so
    ``alpha = 1 / eps - 1``. A straight line ``Omega = a + k_u u`` through the hover speed
    h has eps = (h - a) / h there: ``alpha = a / (h - a)``. A speed-controlled motor (an ESC
    holding the commanded speed, most simulators) has a map through the origin: alpha 0.
    Per rotor, the line over the windows' means (:data:`MAP_WINDOW_S`, as the map) with its
    intercept's standard error (samples counted one per window); alpha's spread is that
    error (delta method) and the rotors' own spread, added in squares.

    Measured on each source's references: RotorPy (speed-commanded) 0.000 ± 0.002, l2f's
    fs vehicle 0.017 ± 0.012, PyFlyt 0.054 ± 0.029, Crazyflow 0.059 ± 0.027, multirotor
    (DC motors) 0.078 ± 0.003, the 20 real Crazyflie 2.1 Brushless nominal flights
    0.40 ± 0.08 (0.34-0.48 per rotor); the l2f X500's references span 4.9-6.8 % of their
    commands per rotor, too little (None). The textbook DC motor at 75 % voltage efficiency
    is 0.2, the prior where this returns None."""
    from ..vehicle.params import hover_speed

    means = _window_means(flights)
    if means is None:
        return None
    command, speed, windows = means
    windows = max(3.0, windows)
    hover = hover_speed(params)
    alpha, var = [], []
    for i in range(speed.shape[1]):
        c, w = command[:, i], speed[:, i]
        if np.ptp(c) < MAP_MIN_RANGE * np.mean(np.abs(c)) or len(c) < 3:
            return None
        slope, intercept = np.polyfit(c, w, 1)
        rss = float(np.sum((w - slope * c - intercept) ** 2))
        sxx = float(np.sum((c - c.mean()) ** 2))
        # the intercept's standard error, samples counted one per window
        se = np.sqrt(rss / (len(c) - 2) * (1 / len(c) + c.mean() ** 2 / sxx)
                     * len(c) / windows)
        if not hover > intercept:
            return None
        alpha.append(intercept / (hover - intercept))
        var.append((hover * se / (hover - intercept) ** 2) ** 2)
    alpha = np.asarray(alpha)
    spread = float(np.sqrt(np.mean(var) + (np.var(alpha, ddof=1) if len(alpha) > 1 else 0.0)))
    return float(alpha.mean()), spread


def _window_means(flights: list[FlightStates]) -> tuple | None:
    """The flights' commands and rotor speeds averaged over :data:`MAP_WINDOW_S` (moving
    mean, per flight, edges dropped; (M, R) each, pooled) and how many windows they span;
    None without a flight logging both."""
    usable = [f for f in flights if f.command is not None and f.rotor_speed is not None]
    if not usable:
        return None
    dt = [float(np.median(np.diff(f.t))) if len(f.t) > 1 else 1.0 for f in usable]
    command = np.concatenate([_moving_mean(f.command, w) for f, w in zip(usable, dt)])
    speed = np.concatenate([_moving_mean(f.rotor_speed, w) for f, w in zip(usable, dt)])
    windows = sum((f.t[-1] - f.t[0]) / MAP_WINDOW_S for f in usable if len(f.t) > 1)
    return command, speed, float(windows)


def _line_supported(c: np.ndarray, w: np.ndarray, gain: tuple, line, windows: float) -> bool:
    """Whether the straight line beats the gain through the origin by the Bayesian
    information criterion (one parameter more): ``n ln(RSS_gain / RSS_line) > ln n``, with
    n the number of independent samples, one per :data:`MAP_WINDOW_S` window of the
    flights (``windows``: the moving mean makes the samples within a window nearly one)."""
    n = max(float(windows), 2.0)
    rss_gain = float(np.sum((w - gain[0] * c - gain[1]) ** 2))
    rss_line = float(np.sum((w - np.polyval(line, c)) ** 2))
    if rss_line <= 0.0:
        return rss_gain > 0.0
    return n * np.log(max(rss_gain, 1e-300) / rss_line) > np.log(n)


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
