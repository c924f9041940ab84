"""A rate gyro mounted askew: a sensor-side error no reading of the diagnosis covers (issue 47).

The gyro's axes are turned from the body axes by a small rotation: a flight controller on a
tilted deck or on soft vibration mounts, or the sensor's own axis misalignment. Each body
rate then leaks into the other axes' readings (Titterton & Weston, "Strapdown inertial
navigation technology", 2nd ed., IEE 2004, sec. 4.2 and 8.2: mounting misalignment and
cross-coupling errors of a gyro triad; MEMS gyros state a cross-axis sensitivity of +-1-2 %,
e.g. InvenSense MPU-6000/6050 product specification rev. 3.4, 2013, table 6.1)::

    omega_logged = R(rotvec) omega_true (+ the pipeline's bias and white noise)
    R(rotvec)    = exp([rotvec]_x)                  Rodrigues, rotvec = angle x unit axis (rad)

A cross-axis term of 1-2 % is a turn of 0.6-1.1 deg; a board on a tilted deck or soft
mounts adds 1-2 deg: :func:`draw_gyro_misalignment` turns by 1-3 deg about a random axis.

It is applied to the sensor pipeline's logged gyro (:mod:`.pipeline`), after the pipeline:
turning the pipeline's constant bias (0.003 rad/s per axis) with it moves that bias by less
than 2e-4 rad/s, and turns its isotropic white noise into noise of the same distribution,
so this equals turning the true rates before the sensor. Only the sensor-pipeline source
flies it (:data:`benchmarks.cases.PIPELINE_SENSOR`): the self-generated source has no
sensor stage to put it in, RotorPy's adapter builds its IMU unturned.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import VehicleParams

__all__ = ["GyroMisalignment", "draw_gyro_misalignment", "rotation_matrix"]


def rotation_matrix(rotvec) -> np.ndarray:
    """R = exp([rotvec]_x) (3, 3) of a rotation vector (rad), Rodrigues' formula."""
    rotvec = np.asarray(rotvec, dtype=float)
    angle = float(np.linalg.norm(rotvec))
    if angle == 0.0:
        return np.eye(3)
    k = rotvec / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * kx @ kx


@dataclass(frozen=True)
class GyroMisalignment:
    """The gyro's axes turned by ``rotvec`` (rad, body frame) from the body axes."""

    name: ClassVar[str] = "gyro_misalignment"
    rotvec: tuple[float, float, float]

    def values(self) -> dict:
        """The rotation vector's components (rad), as effects' ``values()`` give theirs."""
        return dict(zip(("x", "y", "z"), (float(v) for v in self.rotvec)))

    def apply(self, log: FlightLog) -> FlightLog:
        """``log`` with its body rates turned: omega_logged = R omega (module doc)."""
        return dataclasses.replace(log, body_rate=log.body_rate @ rotation_matrix(self.rotvec).T)


def draw_gyro_misalignment(params: VehicleParams, rng: np.random.Generator) -> list:
    """A turn of 1-3 deg about a uniformly random axis (module doc), as a one-element list
    (``params`` unused: the error is the sensor's, the same on every vehicle)."""
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    angle = np.radians(rng.uniform(1.0, 3.0))
    return [GyroMisalignment(tuple(float(a) for a in angle * axis))]
