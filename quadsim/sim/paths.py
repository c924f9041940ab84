"""Reference paths for closed-loop flights: position, velocity, acceleration and yaw of t.

Every path is a :class:`Reference`: call it with times ``t`` of any shape (...,) (s) to get a
:class:`ReferenceSample` with world-frame ``position``, ``velocity``, ``acceleration``
(..., 3) (m, m/s, m/s^2; z up) and ``yaw``, ``yaw_rate`` (...,) (rad, rad/s). Derivatives are
analytic (tests check them against finite differences), so a tracking controller can use the
acceleration as feed-forward.

Paths (``make_reference(name, speed=..., height=..., size=..., duration=...)``):

* ``hover``: hold (0, 0, height).
* ``steps``: a square of four set points (side ``size``), moved between with quintic
  (minimum-jerk) blends of ``size / speed`` seconds, holding each for the same time.
* ``figure8``: x = A sin(w t), y = (A/2) sin(2 w t), A = size, peak speed ``speed``:
  w = speed / (A sqrt 2).
* ``lissajous``: x = A sin(3 w t), y = A sin(2 w t + pi/4), z = height + (A/4) sin(w t),
  w = speed / (A sqrt 13), so the horizontal speed never exceeds ``speed``.
* ``sweep``: a circle of radius ``size`` whose speed rises linearly from 0.2 ``speed`` to
  ``speed`` over ``duration`` (a speed sweep in one flight).
* ``takeoff``: from 0.05 m above the ground up to ``height`` and back down (min-jerk, rate
  ``speed``), with hovers near the ground, to excite the ground effect.

Example::

    >>> from quadsim.sim.paths import make_reference
    >>> ref = make_reference("figure8", speed=1.0, height=1.0, size=1.0)
    >>> s = ref(np.linspace(0, 10, 101))
    >>> s.position.shape, float(np.linalg.norm(s.velocity, axis=-1).max())   # ((101, 3), 1.0)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..core.errors import InputError

__all__ = ["GROUND_CLEARANCE", "PATHS", "Reference", "ReferenceSample", "make_reference"]

#: height (m) of the take-off/landing path's lowest point above the ground.
GROUND_CLEARANCE = 0.05


@dataclass(frozen=True)
class ReferenceSample:
    """Reference at times t: position, velocity, acceleration (..., 3) world; yaw, yaw_rate."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    yaw: np.ndarray
    yaw_rate: np.ndarray


@dataclass(frozen=True)
class Reference:
    """A named path: ``ref(t) -> ReferenceSample``; ``settings`` records its parameters."""

    name: str
    settings: dict
    function: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
    yaw_function: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None

    def __call__(self, t) -> ReferenceSample:
        t = np.asarray(t, dtype=float)
        position, velocity, acceleration = self.function(t)
        if self.yaw_function is None:
            yaw, yaw_rate = np.zeros(t.shape), np.zeros(t.shape)
        else:
            yaw, yaw_rate = self.yaw_function(t)
        return ReferenceSample(position, velocity, acceleration, yaw, yaw_rate)


def _stack(*columns) -> np.ndarray:
    return np.stack(np.broadcast_arrays(*columns), axis=-1)


def _minimum_jerk(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic blend 0 -> 1 on s in [0, 1] (clipped) and its 1st/2nd derivatives in s."""
    s = np.clip(s, 0.0, 1.0)
    return (10 * s**3 - 15 * s**4 + 6 * s**5, 30 * s**2 - 60 * s**3 + 30 * s**4,
            60 * s - 180 * s**2 + 120 * s**3)


def _hover(height: float):
    def f(t):
        zero = np.zeros(t.shape)
        return _stack(zero, zero, zero + height), _stack(zero, zero, zero), _stack(zero, zero, zero)
    return f


def _waypoints(points: np.ndarray, move: float, hold: float):
    """Visit ``points`` (K, 3) cyclically: min-jerk move of ``move`` s, then hold ``hold`` s."""
    leg = move + hold

    def f(t):
        index = np.floor(np.maximum(t, 0.0) / leg).astype(int)
        start = points[index % len(points)]
        end = points[(index + 1) % len(points)]
        blend, rate, curvature = _minimum_jerk((t - index * leg) / move)
        delta = end - start
        return (start + blend[..., None] * delta, (rate / move)[..., None] * delta,
                (curvature / move**2)[..., None] * delta)
    return f


def _figure8(size: float, height: float, omega: float):
    a, b = size, size / 2

    def f(t):
        s1, c1, s2, c2 = np.sin(omega * t), np.cos(omega * t), np.sin(2 * omega * t), \
            np.cos(2 * omega * t)
        zero = np.zeros(t.shape)
        return (_stack(a * s1, b * s2, zero + height),
                _stack(a * omega * c1, 2 * b * omega * c2, zero),
                _stack(-a * omega**2 * s1, -4 * b * omega**2 * s2, zero))
    return f


def _lissajous(size: float, height: float, omega: float):
    a, c, phase = size, size / 4, np.pi / 4

    def f(t):
        wx, wy, wz = 3 * omega, 2 * omega, omega
        return (_stack(a * np.sin(wx * t), a * np.sin(wy * t + phase), height + c * np.sin(wz * t)),
                _stack(a * wx * np.cos(wx * t), a * wy * np.cos(wy * t + phase),
                       c * wz * np.cos(wz * t)),
                _stack(-a * wx**2 * np.sin(wx * t), -a * wy**2 * np.sin(wy * t + phase),
                       -c * wz**2 * np.sin(wz * t)))
    return f


def _sweep(radius: float, height: float, v0: float, v1: float, duration: float):
    slope = (v1 - v0) / duration

    def f(t):
        phase = (v0 * t + 0.5 * slope * t**2) / radius
        rate = (v0 + slope * t) / radius
        accel = slope / radius
        c, s = np.cos(phase), np.sin(phase)
        zero = np.zeros(t.shape)
        return (_stack(radius * s, radius * (1 - c), zero + height),
                _stack(radius * rate * c, radius * rate * s, zero),
                _stack(radius * (accel * c - rate**2 * s), radius * (accel * s + rate**2 * c),
                       zero))
    return f


def _takeoff(height: float, speed: float):
    low, rise = GROUND_CLEARANCE, max(height - GROUND_CLEARANCE, 1e-3)
    move = 1.875 * rise / speed  # min-jerk peak speed is 1.875 x mean speed
    hold = 2.0
    points = np.array([[0.0, 0.0, low], [0.0, 0.0, height]])
    return _waypoints(points, move, hold), 2 * (move + hold)


def make_reference(name: str, *, speed: float = 1.0, height: float = 1.0, size: float = 1.0,
                   duration: float = 20.0) -> Reference:
    """The reference path ``name`` (see the module docstring); speed (m/s), height and size
    (m), duration (s) of the flight (used by ``sweep``)."""
    for label, value in (("speed", speed), ("size", size), ("duration", duration)):
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"path {name}: {label} must be positive, got {value}")
    if not (np.isfinite(height) and height > GROUND_CLEARANCE):
        raise InputError(f"path {name}: height must exceed {GROUND_CLEARANCE} m, got {height}")
    settings = {"speed": speed, "height": height, "size": size, "duration": duration}
    if name == "hover":
        function = _hover(height)
    elif name == "steps":
        square = np.array([[0, 0, 0], [size, 0, 0], [size, size, 0], [0, size, 0]]) + \
            [0, 0, height]
        function = _waypoints(square, 1.875 * size / speed, 1.875 * size / speed)
    elif name == "figure8":
        function = _figure8(size, height, speed / (size * np.sqrt(2.0)))
    elif name == "lissajous":
        # peak horizontal speed of (3 a w cos, 2 a w cos) is at most a w sqrt(13)
        function = _lissajous(size, height, speed / (size * np.sqrt(13.0)))
    elif name == "sweep":
        function = _sweep(size, height, 0.2 * speed, speed, duration)
    elif name == "takeoff":
        function, period = _takeoff(height, speed)
        settings["period"] = period
    else:
        raise InputError(f"unknown path {name!r}; valid: {', '.join(PATHS)}")
    return Reference(name, settings, function)


PATHS = ("hover", "steps", "figure8", "lissajous", "sweep", "takeoff")
