"""Rotor forces and torques from rotor speeds, and the mixer, from rotor geometry alone.

Nothing here knows the layout ("+", "x", hexarotor): the allocation matrix is built from each
rotor's hub position, thrust axis and spin direction (see :mod:`quadsim.vehicle.params` for the
conventions). All functions take a leading batch axis: rotor speeds of shape ``(..., R)``.

Per rotor i with speed Omega_i (rad/s), position r_i, unit axis a_i, spin s_i (+1 ccw):

    thrust      f_i   = b * Omega_i^2 * a_i                       (N, body frame)
    drag torque tau_i = -s_i * d * Omega_i^2 * a_i                (N m, body frame)
    total torque about the CoM = sum_i (r_i - com) x f_i + tau_i

so ``wrench = A @ Omega^2`` with the 6 x R allocation matrix ``A`` of :func:`allocation_matrix`.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ModelError
from .params import VehicleParams


def allocation_matrix(params: VehicleParams, *, about: np.ndarray | None = None) -> np.ndarray:
    """The 6 x R matrix mapping squared rotor speeds (rad^2/s^2) to the body-frame wrench
    ``[Fx, Fy, Fz, Mx, My, Mz]`` (N, N m) about ``about`` (default: the CoM)."""
    point = params.com if about is None else np.asarray(about, dtype=float)
    axes = params.rotor_axes
    arms = params.rotor_positions - point
    forces = params.thrust_factor * axes
    cross = np.stack([arms[:, 1] * forces[:, 2] - arms[:, 2] * forces[:, 1],   # arms x forces
                      arms[:, 2] * forces[:, 0] - arms[:, 0] * forces[:, 2],
                      arms[:, 0] * forces[:, 1] - arms[:, 1] * forces[:, 0]], axis=-1)
    torques = cross - (params.rotor_spins * params.drag_factor)[:, None] * axes
    return np.vstack([forces.T, torques.T])


def rotor_wrench(params: VehicleParams, rotor_speed: np.ndarray, *,
                 thrust_scale: np.ndarray | float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame force (..., 3) and torque about the CoM (..., 3) from rotor speeds (..., R).

    ``thrust_scale`` (broadcast to (..., R)) multiplies each rotor's thrust and drag torque
    (effects such as per-rotor mismatch or battery sag use it)."""
    omega2 = np.square(np.asarray(rotor_speed, dtype=float)) * thrust_scale
    wrench = omega2 @ allocation_matrix(params).T
    return wrench[..., :3], wrench[..., 3:]


def mixer(params: VehicleParams) -> np.ndarray:
    """Map ``[collective thrust (N), Mx, My, Mz (N m)]`` to squared rotor speeds (R x 4).

    The least-norm inverse of the thrust-and-torque rows of the allocation matrix (exact for
    four rotors, minimum-norm for more). Raises if the layout cannot control all four."""
    allocation = allocation_matrix(params)[[2, 3, 4, 5], :]
    if np.linalg.matrix_rank(allocation) < 4:
        raise ModelError(
            f"{params.path or params.name}: rotor layout cannot produce independent thrust, "
            "roll, pitch and yaw (allocation matrix rank < 4)"
        )
    return np.linalg.pinv(allocation)


def speeds_for(params: VehicleParams, thrust_and_torque: np.ndarray, *, clip: bool = True
               ) -> np.ndarray:
    """Rotor speeds (..., R) in rad/s that produce ``[T, Mx, My, Mz]`` (..., 4).

    With ``clip`` the squared speeds are limited to the rotor's range first."""
    omega2 = np.asarray(thrust_and_torque, dtype=float) @ mixer(params).T
    if clip:
        omega2 = np.clip(omega2, params.min_speed**2, params.max_speed**2)
    return np.sqrt(np.maximum(omega2, 0.0))
