"""The state convention shared by every engine, logger, viewer and diagnosis.

A :class:`Trajectory` holds time series with an optional leading batch axis:

* ``t`` (N,) time (s)
* ``position`` (..., N, 3) world position of the body-frame origin (m), z up
* ``velocity`` (..., N, 3) world velocity of the body-frame origin (m/s)
* ``quat`` (..., N, 4) attitude, scalar-first (w, x, y, z), body to world
* ``body_rate`` (..., N, 3) angular velocity in the body frame (rad/s)
* ``rotor_speed`` (..., N, R) actual rotor speeds (rad/s)
* ``rotor_command`` (..., N, R) commanded rotor speeds (rad/s), if different

The 12-state vector of the linear analysis is
``[x, y, z, vx, vy, vz, roll, pitch, yaw, p, q, r]`` with Z-Y-X Euler angles
(:mod:`quadsim.core.frames`) and body rates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.frames import quat_to_euler

STATE12_NAMES = ("x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r")
STATE12_UNITS = ("m", "m", "m", "m/s", "m/s", "m/s", "rad", "rad", "rad", "rad/s", "rad/s",
                 "rad/s")


@dataclass(frozen=True)
class Trajectory:
    """Time series of one or a batch of flights (see module docstring for shapes/frames)."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    body_rate: np.ndarray
    rotor_speed: np.ndarray
    rotor_command: np.ndarray | None = None
    engine: str = ""
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        n = len(self.t)
        for name in ("position", "velocity", "quat", "body_rate", "rotor_speed"):
            value = getattr(self, name)
            if value.shape[-2] != n:
                raise ValueError(f"Trajectory.{name}: {value.shape[-2]} samples, t has {n}")

    @property
    def euler(self) -> np.ndarray:
        """(..., N, 3) roll, pitch, yaw (rad), Z-Y-X."""
        return quat_to_euler(self.quat)

    def state12(self) -> np.ndarray:
        """(..., N, 12) ``[x, y, z, vx, vy, vz, roll, pitch, yaw, p, q, r]``."""
        return np.concatenate([self.position, self.velocity, self.euler, self.body_rate], -1)

    def select(self, index) -> Trajectory:
        """One member of a batch (index on the leading axis)."""
        pick = lambda a: None if a is None else a[index]  # noqa: E731
        return Trajectory(self.t, pick(self.position), pick(self.velocity), pick(self.quat),
                          pick(self.body_rate), pick(self.rotor_speed),
                          pick(self.rotor_command), self.engine, dict(self.meta))
