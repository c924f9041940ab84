"""Rotations, batched over leading axes.

Quaternions are scalar-first ``(w, x, y, z)`` and rotate body-frame vectors into the world
frame (body-to-world). Euler angles are roll, pitch, yaw (phi, theta, psi) in the Z-Y-X
convention: ``R = Rz(psi) @ Ry(theta) @ Rx(phi)``, the report's eq. 3.34 convention.
Shapes: quaternions (..., 4), rotation matrices (..., 3, 3), vectors (..., 3).
"""

from __future__ import annotations

import numpy as np


def quat_normalize(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """Body-to-world rotation matrices (..., 3, 3) from unit quaternions (..., 4)."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p * q, (..., 4)."""
    pw, px, py, pz = np.moveaxis(np.asarray(p, dtype=float), -1, 0)
    qw, qx, qy, qz = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.stack([
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ], -1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    return np.asarray(q, dtype=float) * np.array([1.0, -1.0, -1.0, -1.0])


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Body-frame vectors (..., 3) into the world frame."""
    return np.einsum("...ij,...j->...i", quat_to_rotmat(q), v)


def rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """World-frame vectors (..., 3) into the body frame."""
    return np.einsum("...ji,...j->...i", quat_to_rotmat(q), v)


def euler_to_quat(euler: np.ndarray) -> np.ndarray:
    """(roll, pitch, yaw) (..., 3) in rad -> quaternion (..., 4), Z-Y-X convention."""
    roll, pitch, yaw = np.moveaxis(np.asarray(euler, dtype=float) * 0.5, -1, 0)
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), \
        np.cos(yaw), np.sin(yaw)
    return np.stack([
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ], -1)


def quat_to_euler(q: np.ndarray) -> np.ndarray:
    """Quaternion (..., 4) -> (roll, pitch, yaw) (..., 3) in rad, Z-Y-X convention."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], -1)


def quat_derivative(q: np.ndarray, body_rate: np.ndarray) -> np.ndarray:
    """dq/dt (..., 4) for body angular velocity (..., 3) (rad/s): 0.5 * q * (0, w)."""
    pure = np.concatenate([np.zeros(np.shape(body_rate)[:-1] + (1,)), body_rate], -1)
    return 0.5 * quat_multiply(q, pure)


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) with skew(a) @ b == cross(a, b)."""
    x, y, z = np.moveaxis(np.asarray(v, dtype=float), -1, 0)
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1),
                     np.stack([-y, x, o], -1)], -2)
