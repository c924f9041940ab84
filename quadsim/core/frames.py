"""Rotations, batched over leading axes.

Quaternions are scalar-first ``(w, x, y, z)`` and rotate body-frame vectors into the world
frame (body-to-world). Euler angles are roll, pitch, yaw (phi, theta, psi) in the Z-Y-X
convention: ``R = Rz(psi) @ Ry(theta) @ Rx(phi)``, the report's eq. 3.34 convention.
Shapes: quaternions (..., 4), rotation matrices (..., 3, 3), vectors (..., 3).
"""

from __future__ import annotations

import numpy as np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (length 3), broadcast over the leading axes: the same
    products as ``np.cross``, whose axis handling costs several times the arithmetic on
    the small and (N, 3) arrays of the engines, the effects and the residual."""
    out = np.empty(np.broadcast_shapes(np.shape(a), np.shape(b)))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


#: the columns (y, z, x) and (z, x, y) of a vector's components: a x b is
#: ``a[NEXT] * b[AFTER] - a[AFTER] * b[NEXT]`` (:func:`rolled`, :func:`cross_rolled`)
NEXT, AFTER = np.array([1, 2, 0]), np.array([2, 0, 1])


def rolled(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The components of vectors ``v`` (N, 3) taken in the orders (y, z, x) and (z, x, y),
    (N, 3) each: the factors of :func:`cross_rolled`, to take once for a vector crossed
    with many others."""
    return v.take(NEXT, axis=1), v.take(AFTER, axis=1)


def cross_rolled(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]
                 ) -> np.ndarray:
    """a x b (N, 3) from :func:`rolled` ``a`` and ``b``: the products and differences of
    :func:`cross` (the same numbers), in three array operations on the whole (N, 3) arrays
    instead of nine on their columns."""
    return a[0] * b[1] - a[1] * b[0]


def quat_normalize(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """Body-to-world rotation matrices (..., 3, 3) from unit quaternions (..., 4)."""
    q = np.asarray(q, dtype=float)
    # Flat columns filled in place: this runs at every MuJoCo step with effects on, where
    # stacking small arrays cost more than the arithmetic.
    w, x, y, z = q.reshape(-1, 4).T
    xx, yy, zz, xy, xz, yz, wx, wy, wz = x * x, y * y, z * z, x * y, x * z, y * z, w * x, \
        w * y, w * z
    out = np.empty((9, w.size))
    out[0], out[1], out[2] = 1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)
    out[3], out[4], out[5] = 2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)
    out[6], out[7], out[8] = 2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)
    return out.T.reshape(q.shape[:-1] + (3, 3))


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
    q = np.asarray(q, dtype=float)
    w = np.asarray(body_rate, dtype=float)
    out = np.empty(np.broadcast_shapes(q.shape[:-1], w.shape[:-1]) + (4,))
    out[..., 0] = -q[..., 1] * w[..., 0] - q[..., 2] * w[..., 1] - q[..., 3] * w[..., 2]
    out[..., 1] = q[..., 0] * w[..., 0] + q[..., 2] * w[..., 2] - q[..., 3] * w[..., 1]
    out[..., 2] = q[..., 0] * w[..., 1] - q[..., 1] * w[..., 2] + q[..., 3] * w[..., 0]
    out[..., 3] = q[..., 0] * w[..., 2] + q[..., 1] * w[..., 1] - q[..., 2] * w[..., 0]
    return 0.5 * out


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) with skew(a) @ b == cross(a, b)."""
    x, y, z = np.moveaxis(np.asarray(v, dtype=float), -1, 0)
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1),
                     np.stack([-y, x, o], -1)], -2)


def levelling_quat(specific_force: np.ndarray) -> np.ndarray:
    """The body-to-world quaternion (4,) with no yaw that turns the body-frame specific force
    ``specific_force`` (3,; m/s^2, the accelerometer's a - g) to the world's +z: the tilt an
    accelerometer reads where the vehicle does not accelerate (at rest, or in a steady
    hover). Rotation about the axis f x e_z by the angle between them (the identity where f
    points up already, or where it has no length or is not finite: no tilt to read; f
    pointing straight down: 180 deg about x)."""
    f = np.asarray(specific_force, dtype=float)
    size = float(np.linalg.norm(f))
    if not np.isfinite(size) or size < 1e-9:        # m/s^2: no direction to read
        return np.array([1.0, 0.0, 0.0, 0.0])
    u = f / size
    axis = np.array([u[1], -u[0], 0.0])          # u x e_z
    s, c = float(np.linalg.norm(axis)), float(u[2])
    if s < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0]) if c > 0 else np.array([0.0, 1.0, 0.0, 0.0])
    half = 0.5 * np.arctan2(s, c)
    return np.concatenate([[np.cos(half)], np.sin(half) * axis / s])


def integrate_body_rate(t: np.ndarray, body_rate: np.ndarray, q0: np.ndarray) -> np.ndarray:
    """Body-to-world quaternions (N, 4) from ``q0`` (4,) at ``t[0]`` along the body angular
    velocity ``body_rate`` (N, 3, rad/s) sampled at ``t`` (N, s): between samples k and k+1
    the rotation s_k = exp(h w_m / 2) with w_m the mean of the two rates and h the step
    (exact for a rate constant in direction over the step; second order otherwise), and
    q_k = q0 s_1 ... s_k, normalised. The ordered products are formed by a prefix scan
    (Hillis-Steele: log2 N passes of whole-array Hamilton products, each keeping the earlier
    factor on the left): the same products as one at a time, to round-off
    (tests/test_imu_swing.py). Gyro dead reckoning: its error grows with the rate's bias
    times the time."""
    t = np.asarray(t, dtype=float)
    w = np.asarray(body_rate, dtype=float)
    n = len(t)
    q0 = quat_normalize(q0)
    if n == 0:
        return np.empty((0, 4))
    mid = 0.5 * (w[1:] + w[:-1]) * np.diff(t)[:, None]          # rotation vectors (rad)
    angle = np.linalg.norm(mid, axis=1)
    half = 0.5 * angle
    scale = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    prefix = np.vstack([q0, np.column_stack([np.cos(half), mid * scale[:, None]])])
    step = 1
    while step < n:                     # prefix[k] <- prefix[k - step] * prefix[k]
        prefix[step:] = quat_multiply(prefix[:-step], prefix[step:])
        step *= 2
    return quat_normalize(prefix)
