"""``cable_payload`` as the per-flight evidence fits it: the swing driven by the logged motion.

The engines carry the payload's state (:mod:`quadsim.effects.cable_payload`); a log does not.
It does not need to: the payload's motion depends only on the motion of its attachment point
and on itself, and the attachment's motion *is* logged. So the swing is integrated along the
flight from the logged vehicle motion, and the cable's pull on the vehicle follows -- a
one-way coupling that is exact for the flown trajectory (the vehicle's reaction to the pull
is already in the log).

Model: an inextensible cable of length L from the attachment point (body origin plus the
fixed offset ``x, y, z``, the engine's default 0) to a point payload of mass m; unit vector q
from attachment to payload, angular velocity w of the cable (w . q = 0), attachment
acceleration a (world, the time derivative of the logged velocity), e = g_vec - a the
effective gravity seen from the accelerating attachment (the rigid-link limit of the
engine's model; Sreenath, Lee & Kumar, CDC 2013, eq. 2-4)::

    dq/dt = w x q
    dw/dt = q x e / L
    T     = m (q . e + L |w|^2)          cable tension (N), >= 0 (a slack cable pulls nothing)
    F     = T q                          pull on the vehicle, world, at the attachment
    tau   = (r_a - c) x R^T F            its torque about the CoM (body)

integrated by RK4 between the log's samples (a linearly interpolated between them), q
renormalised and w kept normal to q after each step; a time jump (stacked flights) restarts
it hanging still. No swing damping (as in the engines, where only the cable's axial spring
is damped), so the swing the payload already had at the first sample never dies out: it is
fitted with the payload, as four nuisance parameters (lean and swing rate along world x and
y, :func:`start_state`) with priors centred on hanging still (10 deg, 0.5 rad/s:
:data:`START_PRIOR`); they are never part of the answer. Measured on a generated 6 s "steps"
flight (12 deg rms swing): starting hanging still 0.2 s after take-off, where the payload
already swung at 0.1 rad/s, the modelled direction was off by up to 4.8 deg for the whole
flight, and the force residual of the true mass and length stayed at 4 mN (11 % of the
payload's weight); a start along the effective gravity was worse.

What the data fix: at frequencies well below the swing's own (f = sqrt(g / L) / 2 pi, 0.7 Hz
at 0.5 m) the payload follows the vehicle and the pull is m (g_vec - a): a rigid mass at the
attachment (``mass_offset``); the length shows only where the flight shakes the payload near
or above that frequency (turns, stops, a figure-8's reversals). A gentle flight determines
the mass, not the length (the answer then says so, and ``mass_offset`` ties with it).

Prior (:func:`prior`; each range about two spreads either side of its centre, the rule of
:func:`quadsim.gap.explanations.prior_spreads`): the mass N(0.3 M, (0.15 M)^2), payloads of micro
drones up to ~60 % of the vehicle's mass M (Crazyflie 2.1: 37 g, 15 g payload limit, Bitcraze
datasheet; :mod:`quadsim.gap.priors`), centred inside that range rather than on "off" -- the
reading says a payload hangs there, and at a zero mass the swing has no effect, so a fit
started there cannot move the length and the swing; the length N(0.55 m, (0.225 m)^2):
slung loads of micro drones hang on 0.1-1 m (the Crazyflie payload campaign behind the
``mixed/`` flights of the shared data flew ~0.5 m).

The integration is compiled with numba when it is installed (the same source runs as plain
Python otherwise): a minute of 100 Hz flight takes under 1 ms compiled, 0.6 s as Python, on
the 2-core x86_64 development machine. The first call after an install compiles (3.5 s CPU)
and caches the machine code on disk (numba's ``cache=True``: ``__pycache__`` beside this
file, or ``NUMBA_CACHE_DIR``); later processes load it (0.4 s). The attachment's
acceleration depends only on the logged motion: with a context's ``flight_memo`` (the
per-flight evidence) it is derived once per flight.

Example::

    >>> swing = CableSwing(mass=0.0074, length=0.5)
    >>> force, torque, angle = swing.pull(states, params)   # world N, body N m, rad
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..core.frames import quat_to_rotmat
from ..effects.base import EffectLoads, EffectParameter
from ..effects.cable_payload import CablePayload
from ..vehicle.params import VehicleParams

__all__ = ["FITTED", "LENGTH_PRIOR_M", "MASS_PRIOR", "START_PRIOR", "CableSwing", "prior",
           "start_state", "swing"]

#: prior of the payload mass, in units of the vehicle's mass: centre and spread (module doc).
MASS_PRIOR = (0.3, 0.15)
#: prior of the cable length (m): centre and spread (module doc).
LENGTH_PRIOR_M = (0.55, 0.225)


#: prior spreads of the swing at the first sample: lean (rad, 10 deg) and rate (rad/s).
START_PRIOR = (0.17, 0.5)
#: the fitted parameters: the payload, and the swing at the first sample (nuisance).
FITTED = ("mass", "length", "lean_x", "lean_y", "rate_x", "rate_y")


def prior(params: VehicleParams) -> tuple[list[float], list[float]]:
    """(means, spreads) of :data:`FITTED` (kg, m, rad, rad, rad/s, rad/s; module doc)."""
    lean, rate = START_PRIOR
    return ([MASS_PRIOR[0] * params.mass, LENGTH_PRIOR_M[0], 0.0, 0.0, 0.0, 0.0],
            [MASS_PRIOR[1] * params.mass, LENGTH_PRIOR_M[1], lean, lean, rate, rate])


try:        # the same source, compiled when numba is installed (module doc)
    import numba

    def _compiled(fn):
        try:
            return numba.njit(cache=True)(fn)
        except RuntimeError:    # no writable cache location: compiled in every process
            return numba.njit(fn)
except ImportError:         # pragma: no cover - numba is an optional extra
    def _compiled(fn):
        return fn


@_compiled
def _rate(qx, qy, qz, wx, wy, wz, ax, ay, az, gravity, length):
    """(dq/dt, dw/dt) of the cable at attachment acceleration a (module doc)."""
    ex, ey, ez = -ax, -ay, -gravity - az
    return (wy * qz - wz * qy, wz * qx - wx * qz, wx * qy - wy * qx,
            (qy * ez - qz * ey) / length, (qz * ex - qx * ez) / length,
            (qx * ey - qy * ex) / length)


@_compiled
def _swing_kernel(t, accel, length, gravity, q0, w0, out_q, out_w):
    """RK4 of the cable's direction q and angular velocity w along the samples (module doc);
    ``accel`` (N, 3) the attachment's acceleration (world); ``q0``, ``w0`` the start; a
    time jump restarts hanging still. Fills ``out_q``, ``out_w``."""
    n = t.shape[0]
    dt0 = t[1] - t[0] if n > 1 else 1.0
    for k in range(n):
        if k == 0:
            for i in range(3):
                out_q[k, i], out_w[k, i] = q0[i], w0[i]
            continue
        if abs((t[k] - t[k - 1]) - dt0) > 0.5 * dt0:      # a time jump: a new flight
            out_q[k, 0], out_q[k, 1], out_q[k, 2] = 0.0, 0.0, -1.0
            out_w[k, 0], out_w[k, 1], out_w[k, 2] = 0.0, 0.0, 0.0
            continue
        h = t[k] - t[k - 1]
        qx, qy, qz = out_q[k - 1, 0], out_q[k - 1, 1], out_q[k - 1, 2]
        wx, wy, wz = out_w[k - 1, 0], out_w[k - 1, 1], out_w[k - 1, 2]
        a0x, a0y, a0z = accel[k - 1, 0], accel[k - 1, 1], accel[k - 1, 2]
        a1x, a1y, a1z = accel[k, 0], accel[k, 1], accel[k, 2]
        amx, amy, amz = 0.5 * (a0x + a1x), 0.5 * (a0y + a1y), 0.5 * (a0z + a1z)
        k1 = _rate(qx, qy, qz, wx, wy, wz, a0x, a0y, a0z, gravity, length)
        c = 0.5 * h
        k2 = _rate(qx + c * k1[0], qy + c * k1[1], qz + c * k1[2], wx + c * k1[3],
                   wy + c * k1[4], wz + c * k1[5], amx, amy, amz, gravity, length)
        k3 = _rate(qx + c * k2[0], qy + c * k2[1], qz + c * k2[2], wx + c * k2[3],
                   wy + c * k2[4], wz + c * k2[5], amx, amy, amz, gravity, length)
        k4 = _rate(qx + h * k3[0], qy + h * k3[1], qz + h * k3[2], wx + h * k3[3],
                   wy + h * k3[4], wz + h * k3[5], a1x, a1y, a1z, gravity, length)
        s = h / 6.0
        qx += s * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
        qy += s * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
        qz += s * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        wx += s * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
        wy += s * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
        wz += s * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5])
        norm = math.sqrt(qx * qx + qy * qy + qz * qz)
        qx, qy, qz = qx / norm, qy / norm, qz / norm
        along = wx * qx + wy * qy + wz * qz
        out_q[k, 0], out_q[k, 1], out_q[k, 2] = qx, qy, qz
        out_w[k, 0], out_w[k, 1], out_w[k, 2] = wx - along * qx, wy - along * qy, wz - along * qz


def _swing_floats(t: list, accel: list, length: float, gravity: float, q0, w0
                  ) -> tuple[list, list]:
    """:func:`_swing_kernel`'s steps on Python floats (``t`` a list, ``accel`` a list of
    3-lists), for when it is not compiled: the same operations in the same order (the same
    numbers), without the per-element indexing of numpy arrays that dominates the
    uncompiled kernel. Returns the lists of q and w rows."""
    rate = getattr(_rate, "py_func", _rate)
    n = len(t)
    dt0 = t[1] - t[0] if n > 1 else 1.0
    out_q, out_w = [None] * n, [None] * n
    out_q[0], out_w[0] = [float(v) for v in q0], [float(v) for v in w0]
    for k in range(1, n):
        if abs((t[k] - t[k - 1]) - dt0) > 0.5 * dt0:      # a time jump: a new flight
            out_q[k], out_w[k] = [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]
            continue
        h = t[k] - t[k - 1]
        qx, qy, qz = out_q[k - 1]
        wx, wy, wz = out_w[k - 1]
        a0x, a0y, a0z = accel[k - 1]
        a1x, a1y, a1z = accel[k]
        amx, amy, amz = 0.5 * (a0x + a1x), 0.5 * (a0y + a1y), 0.5 * (a0z + a1z)
        k1 = rate(qx, qy, qz, wx, wy, wz, a0x, a0y, a0z, gravity, length)
        c = 0.5 * h
        k2 = rate(qx + c * k1[0], qy + c * k1[1], qz + c * k1[2], wx + c * k1[3],
                  wy + c * k1[4], wz + c * k1[5], amx, amy, amz, gravity, length)
        k3 = rate(qx + c * k2[0], qy + c * k2[1], qz + c * k2[2], wx + c * k2[3],
                  wy + c * k2[4], wz + c * k2[5], amx, amy, amz, gravity, length)
        k4 = rate(qx + h * k3[0], qy + h * k3[1], qz + h * k3[2], wx + h * k3[3],
                  wy + h * k3[4], wz + h * k3[5], a1x, a1y, a1z, gravity, length)
        s = h / 6.0
        qx += s * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
        qy += s * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
        qz += s * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        wx += s * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
        wy += s * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
        wz += s * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5])
        norm = math.sqrt(qx * qx + qy * qy + qz * qz)
        qx, qy, qz = qx / norm, qy / norm, qz / norm
        along = wx * qx + wy * qy + wz * qz
        out_q[k] = [qx, qy, qz]
        out_w[k] = [wx - along * qx, wy - along * qy, wz - along * qz]
    return out_q, out_w


def start_state(lean: tuple = (0.0, 0.0), rate: tuple = (0.0, 0.0)
                ) -> tuple[np.ndarray, np.ndarray]:
    """(q0, w0) of a cable leaning by ``lean`` (rad, towards world +x, +y: the horizontal
    components of q are their sines) and swinging at ``rate`` (rad/s: d/dt of those
    components): q0 = (sin a_x, sin a_y, -sqrt(1 - ...)), w0 = q0 x dq0/dt (w0 . q0 = 0)."""
    sx = float(np.clip(np.sin(lean[0]), -0.95, 0.95))
    sy = float(np.clip(np.sin(lean[1]), -0.95, 0.95))
    horiz = min(sx * sx + sy * sy, 0.95)
    q0 = np.array([sx, sy, -np.sqrt(1.0 - horiz)])
    dx = rate[0] * np.sqrt(max(1.0 - sx * sx, 0.0))
    dy = rate[1] * np.sqrt(max(1.0 - sy * sy, 0.0))
    dq = np.array([dx, dy, -(q0[0] * dx + q0[1] * dy) / q0[2]])
    return q0 / np.linalg.norm(q0), np.cross(q0, dq)


def swing(t: np.ndarray, accel: np.ndarray, length: float, gravity: float,
          start: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cable direction q (N, 3) and angular velocity w (N, 3, rad/s) along a flight whose
    attachment point accelerates by ``accel`` (N, 3, world m/s^2) at times ``t`` (s), from
    ``start`` = (q0, w0) (default: hanging still, :func:`start_state`)."""
    t = np.ascontiguousarray(t, dtype=float)
    accel = np.ascontiguousarray(accel, dtype=float)
    q0, w0 = start_state() if start is None else start
    q, w = np.empty_like(accel), np.empty_like(accel)
    if len(t) and hasattr(_swing_kernel, "py_func"):         # compiled (numba)
        _swing_kernel(t, accel, float(length), float(gravity), np.asarray(q0, float),
                      np.asarray(w0, float), q, w)
    elif len(t):
        rows_q, rows_w = _swing_floats(t.tolist(), accel.tolist(), float(length),
                                       float(gravity), np.asarray(q0, float).tolist(),
                                       np.asarray(w0, float).tolist())
        q[:], w[:] = rows_q, rows_w
    return q, w


#: window (s) of the Savitzky-Golay derivative that turns the logged velocity into the
#: attachment's acceleration: its response falls off above ~4 Hz (slung-load swings are
#: 0.5-1.6 Hz for 0.1-1 m cables); the difference of a 100 Hz velocity log is noise-dominated
#: (measured on generated flights with 0.01 m/s velocity noise: 0.14 m/s^2 RMS, which a 7 g
#: payload turns into 1 mN of force noise, as much as the force residual of a nominal flight).
ACCEL_WINDOW_S = 0.25


def _derivative(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """d x / d t (N, 3), Savitzky-Golay (cubic, :data:`ACCEL_WINDOW_S`) per stretch of
    uniform samples (a time jump starts a new one)."""
    from scipy.signal import savgol_filter

    if len(t) < 3:
        return np.zeros_like(x)
    dt = np.diff(t)
    cut = np.nonzero(np.abs(dt - dt[0]) > 0.5 * dt[0])[0] + 1
    out = np.zeros_like(x)
    for piece in np.split(np.arange(len(t)), cut):
        if len(piece) < 3:
            continue
        step = float(t[piece[1]] - t[piece[0]])
        window = min(len(piece) - (1 - len(piece) % 2), 2 * int(ACCEL_WINDOW_S / (2 * step)) + 1)
        if window >= 5:
            out[piece] = savgol_filter(x[piece], window, 3, deriv=1, delta=step, axis=0)
        else:
            out[piece] = np.gradient(x[piece], t[piece], axis=0)
    return out


class CableSwing(CablePayload):
    """``cable_payload`` without an internal state: the swing integrated from the logged
    motion (module doc). Fitted: ``mass`` and ``length``; the attachment ``x, y, z`` (body,
    m) is held at the engine's default."""

    parameters = tuple(
        EffectParameter("length", "m", 0.5, 0.05, 5.0, "cable length") if p.name == "length"
        else p for p in CablePayload.parameters) + (
        EffectParameter("lean_x", "rad", 0.0, -1.0, 1.0,
                        "cable's lean from the vertical towards world +x at the first sample"),
        EffectParameter("lean_y", "rad", 0.0, -1.0, 1.0,
                        "cable's lean from the vertical towards world +y at the first sample"),
        EffectParameter("rate_x", "rad/s", 0.0, -5.0, 5.0, "swing rate along x at the start"),
        EffectParameter("rate_y", "rad/s", 0.0, -5.0, 5.0, "swing rate along y at the start"))

    #: the swing at the first sample is fitted with the payload, never part of an answer
    facts = dataclasses.replace(CablePayload.facts,
                                nuisance=("lean_x", "lean_y", "rate_x", "rate_y"))

    def state_size(self) -> int:
        return 0

    def pull(self, t, position, velocity, quat, body_rate, params: VehicleParams, *,
             rotation: np.ndarray | None = None, memo: dict | None = None):
        """Cable pull on the vehicle: force (N, 3, world N), torque about the CoM (N, 3, body
        N m) and the swing angle from the vertical (N,, rad). ``rotation``: ``quat``'s
        matrices when the caller has them; ``memo``: a dict kept across calls on the same
        logged motion (the attachment's acceleration is kept there per attachment point)."""
        rot = quat_to_rotmat(quat) if rotation is None else rotation
        arm = np.array([self.x, self.y, self.z])
        key = ("cable_accel", self.x, self.y, self.z)
        accel = None if memo is None else memo.get(key)
        if accel is None:
            moving = velocity + np.einsum("bij,bj->bi", rot, np.cross(body_rate, arm))
            accel = _derivative(t, moving)
            if memo is not None:
                memo[key] = accel
        q, w = self._swing(t, accel, params.gravity, memo)
        e = -accel
        e[:, 2] -= params.gravity
        tension = self.mass * (np.einsum("bi,bi->b", q, e)
                               + self.length * np.einsum("bi,bi->b", w, w))
        force = np.maximum(tension, 0.0)[:, None] * q
        torque = np.cross(arm - params.com, np.einsum("bji,bj->bi", rot, force))
        return force, torque, np.arccos(np.clip(-q[:, 2], -1.0, 1.0))

    #: swings kept per flight (:meth:`_swing`): a fit's Jacobian and its next step
    KEPT_SWINGS = 16

    def _swing(self, t, accel, gravity: float, memo: dict | None):
        """:func:`swing` of this cable; with a ``memo`` (one flight's logged motion) the
        last :data:`KEPT_SWINGS` are kept by their inputs: the swing does not depend on the
        payload's mass (it only scales the pull) nor on the rotor speeds (a rotor-delay
        shift), so those evaluations reuse it."""
        key = (self.length, self.lean_x, self.lean_y, self.rate_x, self.rate_y,
               self.x, self.y, self.z, float(gravity))
        kept = None if memo is None else memo.setdefault("cable_swings", {})
        if kept is not None and key in kept:
            return kept[key]
        value = swing(t, accel, self.length, gravity,
                      start_state((self.lean_x, self.lean_y), (self.rate_x, self.rate_y)))
        if kept is not None:
            if len(kept) >= self.KEPT_SWINGS:
                del kept[next(iter(kept))]
            kept[key] = value
        return value

    def loads(self, ctx):
        if self.mass == 0.0:
            return None
        force, torque, _ = self.pull(ctx.t, ctx.position, ctx.velocity, ctx.quat,
                                     ctx.body_rate, ctx.params, rotation=ctx.rotmat(),
                                     memo=ctx.flight_memo)
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.force_world, loads.torque_body = force, torque
        return loads

