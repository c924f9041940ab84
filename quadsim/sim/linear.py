"""Linear analysis about hover: analytic Jacobians -> python-control ``StateSpace``, LQR.

State (12): ``[x, y, z, vx, vy, vz, roll, pitch, yaw, p, q, r]`` (world position and velocity
of the body origin, Z-Y-X Euler angles, body rates; :mod:`quadsim.vehicle.state`). Input (R):
rotor speeds (rad/s) about the hover speeds. Hover: level, yaw ``yaw0``, rotor speeds from the
mixer so that thrust balances weight with no torque (unequal if the CoM is off-centre).

Linearised at hover (omega = 0, so the omega x I omega and CoM-lever terms in omega vanish),
with F0 = (0, 0, T0) the hover thrust, Rz the yaw rotation, c the CoM, A_f / A_t the force
and torque rows of :func:`quadsim.vehicle.rotors.allocation_matrix`, U0 = diag(Omega0)::

    d(pos)/dt   = vel
    d(vel)/dt   = (1/m) [Rz skew(e_x) F0, Rz skew(e_y) F0, skew(e_z) Rz F0] d(euler)
                  + (1/m) Rz 2 A_f U0 du + Rz skew(c) I^-1 2 A_t U0 du
    d(euler)/dt = body rates                      (eq. 3.36 at level attitude)
    d(rates)/dt = I^-1 2 A_t U0 du

:func:`dynamics_jacobian_fd` differentiates either engine's full nonlinear dynamics by central
differences, to check the closed forms (tests do). Example::

    >>> from quadsim.vehicle.params import load_params
    >>> from quadsim import linear
    >>> p = load_params("physical")
    >>> sys = linear.linearize(p)
    >>> linear.is_controllable(sys)
    True
    >>> ctrl = linear.LQRController(p)       # usable as simulate(..., controller=ctrl)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import control
import numpy as np

from ..core.frames import euler_to_quat, quat_to_euler, skew
from ..vehicle.params import VehicleParams
from ..vehicle.rotors import allocation_matrix, speeds_for
from ..vehicle.state import STATE12_NAMES
from .analytic import BatchEffects, body_arrays, state_derivative

__all__ = ["hover_point", "linearize", "dynamics_jacobian_fd", "euler_rates",
           "is_controllable", "lqr_gain", "LQRController", "DEFAULT_LQR_SCALES"]

#: Bryson's-rule maximum deviations for the default LQR weights (SI units).
DEFAULT_LQR_SCALES = {"position": 0.5, "velocity": 1.0, "angle": 0.3, "rate": 2.0,
                      "rotor_speed": 80.0}


def hover_point(params: VehicleParams, *, position=(0.0, 0.0, 1.0), yaw0: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray]:
    """Hover state (12,) and rotor speeds (R,) (rad/s): weight balanced, no net torque."""
    x0 = np.zeros(12)
    x0[0:3], x0[8] = position, yaw0
    u0 = speeds_for(params, np.array([params.weight, 0.0, 0.0, 0.0]), clip=False)
    return x0, u0


def _rot_z(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def linearize(params: VehicleParams, *, yaw0: float = 0.0) -> control.StateSpace:
    """Closed-form linearisation about hover; outputs are the full state (C = I, D = 0)."""
    _, u0 = hover_point(params, yaw0=yaw0)
    alloc = allocation_matrix(params)
    force_u = 2.0 * alloc[:3] * u0                   # d(F_body)/d(Omega), (3, R)
    torque_u = 2.0 * alloc[3:] * u0                  # d(tau)/d(Omega), (3, R)
    hover_force = alloc[:3] @ u0**2
    rz = _rot_z(yaw0)
    inv_inertia = np.linalg.inv(params.inertia)
    a = np.zeros((12, 12))
    a[0:3, 3:6] = np.eye(3)
    a[3:6, 6] = rz @ skew(np.eye(3)[0]) @ hover_force / params.mass
    a[3:6, 7] = rz @ skew(np.eye(3)[1]) @ hover_force / params.mass
    a[3:6, 8] = skew(np.eye(3)[2]) @ rz @ hover_force / params.mass
    a[6:9, 9:12] = np.eye(3)
    b = np.zeros((12, params.rotor_count))
    b[3:6] = rz @ force_u / params.mass + rz @ skew(params.com) @ inv_inertia @ torque_u
    b[9:12] = inv_inertia @ torque_u
    inputs = [f"Omega{r.name}" for r in params.rotors]
    return control.ss(a, b, np.eye(12), np.zeros((12, params.rotor_count)),
                      states=list(STATE12_NAMES), inputs=inputs, outputs=list(STATE12_NAMES),
                      name=f"{params.name} hover")


def euler_rates(euler: np.ndarray, body_rate: np.ndarray) -> np.ndarray:
    """Z-Y-X Euler angle rates (..., 3) from body rates (eq. 3.36)."""
    roll, pitch = euler[..., 0], euler[..., 1]
    p, q, r = body_rate[..., 0], body_rate[..., 1], body_rate[..., 2]
    sr, cr, tp, cp = np.sin(roll), np.cos(roll), np.tan(pitch), np.cos(pitch)
    return np.stack([p + (q * sr + r * cr) * tp, q * cr - r * sr, (q * sr + r * cr) / cp], -1)


def _analytic_rate(params: VehicleParams) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    body = body_arrays([params])
    effects = BatchEffects(None, [params])

    def rate(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        y = np.concatenate([x[0:6], euler_to_quat(x[6:9]), x[9:12]])
        dy = state_derivative(0.0, y, body=body, effects=effects, command=u[None, :])
        return np.concatenate([dy[0:6], euler_rates(x[6:9], x[9:12]), dy[10:13]])

    return rate


def _mujoco_rate(params: VehicleParams) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    import mujoco

    from .mujoco_engine import compile_model

    model = compile_model(params, 1e-3)
    data = mujoco.MjData(model)

    def rate(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        data.qpos[:] = np.concatenate([x[0:3], euler_to_quat(x[6:9])])
        data.qvel[:] = np.concatenate([x[3:6], x[9:12]])
        data.ctrl[:] = u**2
        mujoco.mj_forward(model, data)
        return np.concatenate([x[3:6], data.qacc[0:3], euler_rates(x[6:9], x[9:12]),
                               data.qacc[3:6]])

    return rate


def dynamics_jacobian_fd(params: VehicleParams, engine: str, x0: np.ndarray, u0: np.ndarray,
                         *, step: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Central-difference Jacobians (A, B) of an engine's nonlinear dynamics at (x0, u0).

    ``engine``: "analytic" (:func:`quadsim.sim.analytic.state_derivative`) or "mujoco"
    (``mj_forward`` accelerations of the compiled model, ctrl = Omega^2)."""
    rate = _analytic_rate(params) if engine == "analytic" else _mujoco_rate(params)
    a = np.zeros((12, 12))
    b = np.zeros((12, len(u0)))
    for j in range(12):
        dx = np.zeros(12)
        dx[j] = step
        a[:, j] = (rate(x0 + dx, u0) - rate(x0 - dx, u0)) / (2 * step)
    for j in range(len(u0)):
        du = np.zeros(len(u0))
        du[j] = step * max(1.0, abs(u0[j]))
        b[:, j] = (rate(x0, u0 + du) - rate(x0, u0 - du)) / (2 * du[j])
    return a, b


def is_controllable(sys: control.StateSpace) -> bool:
    """True if the controllability matrix has full rank."""
    return bool(np.linalg.matrix_rank(control.ctrb(sys.A, sys.B)) == sys.nstates)


def lqr_gain(sys: control.StateSpace, *, scales: dict | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
    """LQR gain K (R, 12) and closed-loop poles, weights by Bryson's rule from ``scales``
    (maximum acceptable deviation per group, :data:`DEFAULT_LQR_SCALES`)."""
    s = {**DEFAULT_LQR_SCALES, **(scales or {})}
    per_state = np.repeat([s["position"], s["velocity"], s["angle"], s["rate"]], 3)
    q = np.diag(1.0 / per_state**2)
    r = np.eye(sys.ninputs) / s["rotor_speed"] ** 2
    gain, _, poles = control.lqr(sys, q, r)
    return np.asarray(gain), np.asarray(poles)


@dataclass
class LQRController:
    """Hover-stabilising LQR as an engine controller: ``Omega = Omega0 - K (x - x_ref(t))``.

    ``reference(t) -> (B, 12) or (12,)`` desired state (default: hover at ``position``, yaw
    ``yaw0``); yaw error is wrapped to [-pi, pi). Called as ``controller(t, state)`` with the
    engines' snapshot dict (see :mod:`quadsim.sim.engines`); returns (B, R) rotor speeds (rad/s)."""

    params: VehicleParams
    position: tuple[float, float, float] = (0.0, 0.0, 1.0)
    yaw0: float = 0.0
    scales: dict | None = None
    reference: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self):
        self.system = linearize(self.params, yaw0=self.yaw0)
        self.gain, self.closed_loop_poles = lqr_gain(self.system, scales=self.scales)
        self.hover_state, self.hover_speed = hover_point(self.params, position=self.position,
                                                         yaw0=self.yaw0)

    def __call__(self, t: np.ndarray, state: dict) -> np.ndarray:
        x = np.concatenate([state["position"], state["velocity"], quat_to_euler(state["quat"]),
                            state["body_rate"]], axis=-1)
        target = self.hover_state if self.reference is None else self.reference(t)
        error = x - target
        error[..., 6:9] = (error[..., 6:9] + np.pi) % (2 * np.pi) - np.pi
        return self.hover_speed - error @ self.gain.T
