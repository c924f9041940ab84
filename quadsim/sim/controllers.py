"""Geometric tracking controller on SE(3) (Lee, Leok & McClamroch, CDC 2010), batched.

Given a reference (:mod:`quadsim.sim.paths`) and the state snapshot that
:func:`quadsim.sim.engines.simulate` passes to a controller (dict of (B, ...) arrays ``t,
position, velocity, quat, body_rate``), it returns rotor speeds (B, R) (rad/s) through the
geometry-derived mixer :func:`quadsim.vehicle.rotors.speeds_for`. Law (world z up, e3 = (0, 0, 1))::

    e_x = x - x_d,  e_v = v - v_d,  e_i = integral of e_x dt
    F   = -k_x e_x - k_v e_v - k_i e_i + m g e3 + m a_d            desired force (world)
    f   = F . R e3                                                 collective thrust
    b3d = F / |F|,  b2d = b3d x (cos psi_d, sin psi_d, 0) / |.|,  b1d = b2d x b3d
    e_R = vee(R_d^T R - R^T R_d) / 2,   e_w = w - R^T R_d (0, 0, psi_d')
    M   = -k_R e_R - k_w e_w + w x J w                             body torque about the CoM

Gains follow from natural frequencies and damping, scaled by the *model's* mass and inertia
(``k_x = m wn^2``, ``k_v = 2 zeta m wn``, ``k_R = J wa^2``, ``k_w = 2 zeta J wa`` per axis),
so one setting suits the 37 g Crazyflie and the 0.84 kg testbed. The controller knows only
the nominal parameter set: unmodelled effects show as tracking errors, which is the point.
The integral term (``k_i = m wi^3``) removes steady offsets from, e.g., an unknown payload.

Example::

    >>> from quadsim.sim.controllers import GeometricController
    >>> from quadsim.sim.paths import make_reference
    >>> ctrl = GeometricController(params, make_reference("figure8", speed=1.0))
    >>> traj = simulate(params, controller=ctrl, initial=ctrl.initial_state(), duration=10)

The controller keeps the integral as state: use a fresh one per simulation.
"""

from __future__ import annotations

import numpy as np

from ..core.frames import quat_to_rotmat
from ..vehicle.params import VehicleParams
from ..vehicle.rotors import mixer
from .paths import Reference

__all__ = ["GeometricController", "desired_rotation"]


def _vee(matrix: np.ndarray) -> np.ndarray:
    return np.stack([matrix[..., 2, 1], matrix[..., 0, 2], matrix[..., 1, 0]], axis=-1)


def desired_rotation(force: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """R_d (B, 3, 3) whose z axis is along ``force`` (B, 3) and whose heading is ``yaw``."""
    b3 = force / np.linalg.norm(force, axis=-1, keepdims=True)
    heading = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=-1)
    b2 = np.cross(b3, heading)
    b2 /= np.linalg.norm(b2, axis=-1, keepdims=True)
    b1 = np.cross(b2, b3)
    return np.stack([b1, b2, b3], axis=-1)


class GeometricController:
    """Lee et al. (2010) tracking controller; ``ctrl(t, state) -> (B, R)`` rotor speeds."""

    def __init__(self, params: VehicleParams, reference: Reference, *,
                 position_frequency: float = 2.0, attitude_frequency: float = 15.0,
                 integral_frequency: float = 0.5, damping: float = 0.9):
        self.params = params
        self.reference = reference
        mass, inertia = params.mass, np.diag(params.inertia)
        self.k_x = mass * position_frequency**2
        self.k_v = 2 * damping * mass * position_frequency
        self.k_i = mass * integral_frequency**3
        self.k_r = inertia * attitude_frequency**2
        self.k_w = 2 * damping * inertia * attitude_frequency
        self._integral = None
        self._last_t = None
        self._mixer_t = mixer(params).T     # once: speeds_for would rebuild it every period

    def initial_state(self) -> dict:
        """The reference's state at t = 0 (position, velocity, level attitude, yaw)."""
        start = self.reference(np.zeros(1))
        yaw = float(start.yaw[0])
        return {"position": start.position[0], "velocity": start.velocity[0],
                "quat": np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]),
                "body_rate": np.zeros(3)}

    def _integrate(self, t: np.ndarray, error: np.ndarray) -> np.ndarray:
        if self._integral is None or self._integral.shape != error.shape:
            self._integral = np.zeros_like(error)
        elif self._last_t is not None:
            dt = np.clip(t - self._last_t, 0.0, None)[:, None]
            self._integral = self._integral + error * dt
        self._last_t = t.copy()
        return self._integral

    def wrench(self, t: np.ndarray, state: dict) -> np.ndarray:
        """[thrust (N), Mx, My, Mz (N m)] (B, 4) for the state snapshot at times t (B,)."""
        p = self.params
        ref = self.reference(t)
        rot = quat_to_rotmat(state["quat"])
        error_x = state["position"] - ref.position
        error_v = state["velocity"] - ref.velocity
        integral = self._integrate(np.asarray(t, dtype=float), error_x)
        force = (-self.k_x * error_x - self.k_v * error_v - self.k_i * integral
                 + p.mass * ref.acceleration)
        force[:, 2] += p.mass * p.gravity
        thrust = np.einsum("bi,bi->b", force, rot[:, :, 2])
        rot_d = desired_rotation(force, ref.yaw)
        error_r = 0.5 * _vee(np.einsum("bji,bjk->bik", rot_d, rot)
                             - np.einsum("bji,bjk->bik", rot, rot_d))
        rate_d = np.einsum("bji,bjk,bk->bi", rot, rot_d,
                           np.stack([0 * ref.yaw_rate, 0 * ref.yaw_rate, ref.yaw_rate], -1))
        rate = state["body_rate"]
        error_w = rate - rate_d
        momentum = rate * np.diag(p.inertia)
        torque = -self.k_r * error_r - self.k_w * error_w + np.cross(rate, momentum)
        return np.concatenate([thrust[:, None], torque], axis=1)

    def __call__(self, t: np.ndarray, state: dict) -> np.ndarray:
        # = rotors.speeds_for(params, wrench) with the mixer computed once
        omega2 = self.wrench(np.asarray(t, dtype=float), state) @ self._mixer_t
        omega2 = np.clip(omega2, self.params.min_speed**2, self.params.max_speed**2)
        return np.sqrt(np.maximum(omega2, 0.0))
