"""What the diagnosis fits, and how: the effects it fits beyond the library (a canted rotor by
its lean, a cable payload with its swing driven by the logged motion), the plausible magnitudes
and words the effects' facts give a reading, and equation-error least squares of candidate
effects over flights.

A cable payload's swing
-----------------------

``cable_payload`` as the per-flight evidence fits it: the swing driven by the logged motion.

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
    dw/dt = q x e / L - k w          k: the swing's damping rate (1/s)
    T     = m (q . e + L |w|^2)          cable tension (N), >= 0 (a slack cable pulls nothing)
    F     = T q                          pull on the vehicle, world, at the attachment
    tau   = (r_a - c) x R^T F            its torque about the CoM (body)

integrated by RK4 between the log's samples (a linearly interpolated between them), q
renormalised and w kept normal to q after each step; a stacked flight's first sample starts
at that flight's own swing where the stacked fit gives it one (:class:`Restart`,
:func:`quadsim.gap.diagnose.fit_own_starts`), any other time jump (an airborne stretch of
one log, a stacked flight without one) restarts it hanging still. The damping rate k is
fitted (prior N(0.5, 0.5^2) 1/s, at least 0: :data:`DAMPING_PRIOR`; the engines damp only
the cable's axial spring): an undamped model swing kept swinging after the real payload
hung still. The swing the payload already had at
the first sample is fitted with the payload too (lean and swing rate along world x and y,
:func:`start_state`) with priors centred on hanging still (10 deg, 0.5 rad/s:
:data:`START_PRIOR`); these and k are nuisance parameters, never part of the answer.
Why fitted: a start hanging still where the payload already swings leaves the modelled
direction off for the whole flight (CHANGELOG.md: Docstrings as contracts).

What the data fix: at frequencies well below the swing's own (f = sqrt(g / L) / 2 pi, 0.7 Hz
at 0.5 m) the payload follows the vehicle and the pull is m (g_vec - a): a rigid mass at the
attachment (``mass_offset``); the length shows only where the flight shakes the payload near
or above that frequency (turns, stops, a figure-8's reversals). A gentle flight determines
the mass, not the length (the answer then says so, and ``mass_offset`` ties with it).

Prior (:func:`prior`; each range about two spreads either side of its centre, the rule of
:func:`quadsim.gap.explanations.prior_spreads`): the mass N(0.3 M, (0.15 M)^2), payloads of micro
drones up to ~60 % of the vehicle's mass M (Crazyflie 2.1: 37 g, 15 g payload limit, Bitcraze
datasheet; :mod:`quadsim.gap.fitting`), centred inside that range rather than on "off" -- the
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

Fit forms beyond the library
----------------------------

The effects the diagnosis fits beyond the library, declared in one place.

:data:`FIT_FORMS`: library effects the diagnosis fits in a form of its own (a canted rotor by
its axis' horizontal lean, a cable payload with its swing driven by the logged motion);
:data:`PSEUDO_EFFECTS`: effects of the diagnosis that the library does not have (the nominal
refit of b and d, the motor map's gain, the references' drag under a quadratic law). Both are
static: built here from explicit imports, never filled by other modules, so what the
diagnosis can fit does not depend on what was imported. :data:`FIT_EFFECTS` is the library
with these; :func:`effect_class`, :func:`build_effect` and :func:`facts_for` read it.

Every class declares its diagnosis facts (:class:`quadsim.effects.facts.EffectFacts`); a
fit form inherits its library effect's.

Example::

    >>> build_effect("canted_rotor", {"rotor": 1.0, "tilt_x": 0.02})   # a CantedRotorFit
    >>> facts_for("nominal_refit").fitted                                # ('thrust', 'drag')

Plausible magnitudes and words
------------------------------

What the effects' declared facts imply for a reading: plausible magnitudes of fitted
effects, with sources (what ranks collinear explanations), and each reading in words.

When two candidates explain the same forces (an added mass and a uniform loss of thrust per
Omega^2 are the same in the force balance up to drag), the data cannot choose; physics can
say which magnitude is believable. Each prior is a range of the *relative* or absolute size
that real vehicles show; a fit outside it is flagged ``implausible``: it keeps its evidence,
and as lead it is named only with a caveat and tentative (:func:`quadsim.gap.judge.lead_caveat`).

Each range is declared by its effect beside its parameters, with its source
(``facts.ranges``, :class:`quadsim.effects.facts.PlausibleRange`); :data:`PRIORS` is a
read-only view of them, and ``docs/effects.md`` ("Diagnosis facts") tabulates them with their
reasoning.

:func:`plausibility` returns (score, plausible, text): score = |value| / bound on its side
(<= 1 plausible; the smaller, the more plausible).

Collinear explanations in words
-------------------------------
Each candidate's physical magnitude (:func:`describe`), what the torque and yaw channels
say, and what separates them (:func:`separation`).

Readings the data cannot choose between are all listed in ``verdict.alternatives``
(:mod:`quadsim.gap.diagnose`, from the held-out posterior of :mod:`quadsim.gap.diagnose`),
each with

* ``magnitude``: the fitted parameters as a physical statement with units ("+4.0 ± 0.2 g
  (+10.8 % of the vehicle mass)", "-9.7 ± 0.5 % thrust per Omega^2 on all 4 rotors");
* ``torque_yaw``: the held-out RMS of Mx, My, Mz (N m) that the candidate leaves, so a
  reader sees whether the torque channels prefer one (a thrust-per-Omega^2 change from the
  air also scales the yaw drag torque; an added mass at the CoM leaves torques alone);
* ``separate_by``: the measurement or manoeuvre that would tell them apart;
* ``plausible`` / ``plausibility``: the prior check of :mod:`quadsim.gap.fitting` (score
  <= 1 plausible). An implausible candidate is flagged; as lead it is named only with a
  caveat, tentative.

Least squares of candidate effects
----------------------------------

Equation-error fitting of candidate effects (the "which" of the gap diagnosis).

For a candidate effect with values theta, every sample of every flight gives a residual
(measured Newton–Euler wrench minus model wrench, :mod:`quadsim.gap.residual`, plus a rotor-speed
channel when the log has commands), divided per channel by the noise scale ``sigma``. The
effect's fittable parameters, their typical sizes and fit windows are what the effect declares
(``facts``, :mod:`quadsim.effects.facts`; :data:`FIT_SPEC` is a read-only view) and are found
with bounded ``scipy.optimize.least_squares``; confidence intervals come from the Jacobian at
the solution, widened by the residuals' correlation time (the smoothed samples are not
independent).

A *candidate* is a tuple of (effect name, fixed values, fitted parameter names). Some effects
need a companion to be seen at all (``facts.companions``): ``wind`` acts only through drag, so
the ``wind`` candidate fits the mean wind together with the rotor-drag coefficient. The
diagnosis' own effects and fit forms are declared in :mod:`quadsim.gap.fitting`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from functools import lru_cache
from types import MappingProxyType

import numpy as np
from scipy.optimize import least_squares

from ..core.errors import ModelError
from ..core.frames import cross, quat_to_rotmat
from ..effects import EFFECTS, make_effect
from ..effects.base import EffectBase, EffectLoads, EffectParameter
from ..effects.body_drag import BodyDrag
from ..effects.cable_payload import CablePayload
from ..effects.canted_rotor import CantedRotor
from ..effects.facts import (
    ALL,
    EffectFacts,
    ParameterFacts,
    PlausibleRange,
    Scale,
    Words,
    arm_length,
    parameter_facts,
    plus_minus,
)
from ..effects.rate_damping import momentum_rate_damping
from ..effects.thrust_curve import (  # re-exported
    CURVE_QUADRATIC_SD,
    ThrustCurve,
    curve_quadratic_bounds,
    curve_quadratic_sd,
    hover_thrust_per_speed,
)
from ..effects.translational_lift import momentum_translational_lift
from ..effects.wind import WIND_SD_MS
from ..vehicle.params import VehicleParams
from .residual import (  # re-exported: the diagnosis' public fitting names
    FlightStates,
    command_of_speed,
    command_speed,
    effects_plan,
    fit_motor_map,
    fit_set_map,
    flight_memo,
    kept,
    measured_wrench,
    memoised,
    min_time_constant,
    model_wrench,
    rotor_residual,
    speed_of_command,
)

__all__ = ["FITTED", "LENGTH_PRIOR_M", "MASS_PRIOR", "START_PRIOR", "START_SWING", "CableSwing",
           "Restart",
           "prior", "start_state", "swing", "FIT_EFFECTS", "FIT_FORMS", "LOCAL_EFFECTS",
           "PSEUDO_EFFECTS", "SPEED_GAIN_PART", "CantedRotorFit", "DragLaw", "NominalRefit",
           "SpeedGain", "build_effect", "effect_class", "facts_for", "parameter_facts_for",
           "CURVE_QUADRATIC_SD", "DETERMINED", "PRIORS", "SEPARATE", "WIND_SD_MS",
           "candidate_plausibility", "curve_quadratic_bounds", "curve_quadratic_sd",
           "curve_slope_sd", "describe", "hover_thrust_per_speed", "momentum_rate_damping",
           "momentum_translational_lift", "plausibility", "separation", "torque_text", "unit_of",
           "BASELINE", "FIT_SPEC", "NOISE_FLOOR", "NO_OFF_VALUE", "UPSTREAM_OF_SPEED", "Candidate",
           "Fit", "arm_length", "candidates_for", "command_of_speed", "command_speed",
           "correlation_time", "curve_bound", "drag_refit_iv", "fit_candidate", "fit_motor_map",
           "fit_set_map",
           "flight_memo", "noise_floor", "noise_scale", "parameter_bounds", "plane_step",
           "residuals",
           "speed_of_command", "stack_states", "typical_scales"]


#: prior of the payload mass, in units of the vehicle's mass: centre and spread (module doc).
MASS_PRIOR = (0.3, 0.15)
#: prior of the cable length (m): centre and spread (module doc).
LENGTH_PRIOR_M = (0.55, 0.225)


#: prior spreads of the swing at the first sample: lean (rad, 10 deg) and rate (rad/s).
START_PRIOR = (0.17, 0.5)
#: the parameters of the swing at the first sample (rad, rad/s; nuisance): one flight's own,
#: never another's (held out each flight is read at its own, and each stacked training
#: flight fitted at its own, :mod:`quadsim.gap.diagnose`)
START_SWING = ("lean_x", "lean_y", "rate_x", "rate_y")
#: the fitted parameters: the payload, and the swing at the first sample (nuisance).
FITTED = ("mass", "length", *START_SWING, "swing_damping")
#: prior of the swing's damping rate (1/s): centre and spread (module doc)
DAMPING_PRIOR = (0.5, 0.5)


def prior(params: VehicleParams) -> tuple[list[float], list[float]]:
    """(means, spreads) of :data:`FITTED` (kg, m, rad, rad, rad/s, rad/s; module doc)."""
    lean, rate = START_PRIOR
    return ([MASS_PRIOR[0] * params.mass, LENGTH_PRIOR_M[0], 0.0, 0.0, 0.0, 0.0,
             DAMPING_PRIOR[0]],
            [MASS_PRIOR[1] * params.mass, LENGTH_PRIOR_M[1], lean, lean, rate, rate,
             DAMPING_PRIOR[1]])


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
def _rate(q, w, a, constants):
    """(dq/dt, dw/dt) of the cable (module doc): direction ``q``, angular velocity ``w``
    (rad/s) and the attachment's acceleration ``a`` (world, m/s^2), each a 3-tuple;
    ``constants`` = (gravity m/s^2, length m, swing damping rate 1/s). Returns a 6-tuple."""
    qx, qy, qz = q
    wx, wy, wz = w
    ax, ay, az = a
    gravity, length, damping = constants
    ex, ey, ez = -ax, -ay, -gravity - az
    return (wy * qz - wz * qy, wz * qx - wx * qz, wx * qy - wy * qx,
            (qy * ez - qz * ey) / length - damping * wx,
            (qz * ex - qx * ez) / length - damping * wy,
            (qx * ey - qy * ex) / length - damping * wz)


@_compiled
def _swing_kernel(t, accel, starts, at, constants, out):
    """RK4 of the cable's direction q and angular velocity w along the samples (module doc);
    ``accel`` (N, 3) the attachment's acceleration (world); ``starts`` (S, 2, 3) the rows
    q0, w0 of each start, taken at the sample indices ``at`` (S,; rising, ``at[0]`` = 0: a
    stacked flight's first sample); ``constants`` as :func:`_rate`'s; any other time jump
    restarts hanging still. Fills ``out`` (2, N, 3): q, then w."""
    n = t.shape[0]
    dt0 = t[1] - t[0] if n > 1 else 1.0
    j = 0
    for k in range(n):
        if j < at.shape[0] and k == at[j]:      # a start of its own
            for i in range(3):
                out[0, k, i], out[1, k, i] = starts[j, 0, i], starts[j, 1, i]
            j += 1
            continue
        if abs((t[k] - t[k - 1]) - dt0) > 0.5 * dt0:      # a time jump: a new flight
            out[0, k, 0], out[0, k, 1], out[0, k, 2] = 0.0, 0.0, -1.0
            out[1, k, 0], out[1, k, 1], out[1, k, 2] = 0.0, 0.0, 0.0
            continue
        h = t[k] - t[k - 1]
        qx, qy, qz = out[0, k - 1, 0], out[0, k - 1, 1], out[0, k - 1, 2]
        wx, wy, wz = out[1, k - 1, 0], out[1, k - 1, 1], out[1, k - 1, 2]
        a0 = (accel[k - 1, 0], accel[k - 1, 1], accel[k - 1, 2])
        a1 = (accel[k, 0], accel[k, 1], accel[k, 2])
        am = (0.5 * (a0[0] + a1[0]), 0.5 * (a0[1] + a1[1]), 0.5 * (a0[2] + a1[2]))
        k1 = _rate((qx, qy, qz), (wx, wy, wz), a0, constants)
        c = 0.5 * h
        k2 = _rate((qx + c * k1[0], qy + c * k1[1], qz + c * k1[2]),
                   (wx + c * k1[3], wy + c * k1[4], wz + c * k1[5]), am, constants)
        k3 = _rate((qx + c * k2[0], qy + c * k2[1], qz + c * k2[2]),
                   (wx + c * k2[3], wy + c * k2[4], wz + c * k2[5]), am, constants)
        k4 = _rate((qx + h * k3[0], qy + h * k3[1], qz + h * k3[2]),
                   (wx + h * k3[3], wy + h * k3[4], wz + h * k3[5]), a1, constants)
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
        out[0, k, 0], out[0, k, 1], out[0, k, 2] = qx, qy, qz
        out[1, k, 0], out[1, k, 1], out[1, k, 2] = wx - along * qx, wy - along * qy, wz - along * qz


def _swing_floats(t: list, accel: list, starts: dict, constants: tuple
                  ) -> tuple[list, list]:
    """:func:`_swing_kernel`'s steps on Python floats (``t`` a list, ``accel`` a list of
    3-lists, ``starts`` sample index -> (q0, w0) as 3-lists, index 0 among them,
    ``constants`` as :func:`_rate`'s), for when it is not compiled: the same operations in
    the same order (the same numbers), without the per-element indexing of numpy arrays that
    dominates the uncompiled kernel. Returns the lists of q and w rows."""
    rate = getattr(_rate, "py_func", _rate)
    n = len(t)
    dt0 = t[1] - t[0] if n > 1 else 1.0
    out_q, out_w = [None] * n, [None] * n
    for k in range(n):
        if k in starts:                                   # a start of its own
            out_q[k], out_w[k] = ([float(v) for v in starts[k][0]],
                                  [float(v) for v in starts[k][1]])
            continue
        if abs((t[k] - t[k - 1]) - dt0) > 0.5 * dt0:      # a time jump: a new flight
            out_q[k], out_w[k] = [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]
            continue
        h = t[k] - t[k - 1]
        qx, qy, qz = out_q[k - 1]
        wx, wy, wz = out_w[k - 1]
        a0 = tuple(accel[k - 1])
        a1 = tuple(accel[k])
        am = (0.5 * (a0[0] + a1[0]), 0.5 * (a0[1] + a1[1]), 0.5 * (a0[2] + a1[2]))
        k1 = rate((qx, qy, qz), (wx, wy, wz), a0, constants)
        c = 0.5 * h
        k2 = rate((qx + c * k1[0], qy + c * k1[1], qz + c * k1[2]),
                  (wx + c * k1[3], wy + c * k1[4], wz + c * k1[5]), am, constants)
        k3 = rate((qx + c * k2[0], qy + c * k2[1], qz + c * k2[2]),
                  (wx + c * k2[3], wy + c * k2[4], wz + c * k2[5]), am, constants)
        k4 = rate((qx + h * k3[0], qy + h * k3[1], qz + h * k3[2]),
                  (wx + h * k3[3], wy + h * k3[4], wz + h * k3[5]), a1, constants)
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
    return q0 / np.linalg.norm(q0), cross(q0, dq)


@dataclass(frozen=True)
class Restart:
    """A stacked flight's own swing at its first sample (:data:`START_SWING`): ``at`` the
    index of that sample in the stacked states (> 0), ``lean`` (rad) and ``rate`` (rad/s)
    along world x and y (:func:`start_state`). Without one, a stacked flight starts hanging
    still (the kernel's restart at a time jump)."""

    at: int
    lean: tuple
    rate: tuple


def swing(t: np.ndarray, accel: np.ndarray, length: float, gravity: float,
          start: tuple | None = None, damping: float = 0.0, *,
          restarts: tuple = ()) -> tuple[np.ndarray, np.ndarray]:
    """Cable direction q (N, 3) and angular velocity w (N, 3, rad/s) along a flight whose
    attachment point accelerates by ``accel`` (N, 3, world m/s^2) at times ``t`` (s), from
    ``start`` = (q0, w0) (default: hanging still, :func:`start_state`), the swing damped at
    the rate ``damping`` (1/s: dw/dt gains -damping w; module doc); ``restarts``
    (:class:`Restart`): stacked flights that start at a swing of their own (one whose
    ``at`` is not a later sample of ``t`` is not one of them)."""
    t = np.ascontiguousarray(t, dtype=float)
    accel = np.ascontiguousarray(accel, dtype=float)
    q0, w0 = start_state() if start is None else start
    rows = [(0, np.asarray(q0, float), np.asarray(w0, float))]
    rows += [(r.at, *start_state(r.lean, r.rate))
             for r in sorted(restarts, key=lambda r: r.at) if 0 < r.at < len(t)]
    out = np.empty((2, *accel.shape))
    q, w = out[0], out[1]
    constants = (float(gravity), float(length), float(damping))
    if len(t) and hasattr(_swing_kernel, "py_func"):         # compiled (numba)
        _swing_kernel(t, accel, np.array([[r[1], r[2]] for r in rows]),
                      np.array([r[0] for r in rows], dtype=np.int64), constants, out)
    elif len(t):
        rows_q, rows_w = _swing_floats(t.tolist(), accel.tolist(),
                                       {r[0]: (r[1].tolist(), r[2].tolist()) for r in rows},
                                       constants)
        q[:], w[:] = rows_q, rows_w
    return q, w


#: window (s) of the Savitzky-Golay derivative that turns the logged velocity into the
#: attachment's acceleration: its response falls off above ~4 Hz (slung-load swings are
#: 0.5-1.6 Hz for 0.1-1 m cables); the difference of a 100 Hz velocity log is noise-dominated
#: (CHANGELOG.md: Docstrings as contracts).
ACCEL_WINDOW_S = 0.25


def _derivative(t: np.ndarray, x: np.ndarray, deriv: int = 1) -> np.ndarray:
    """d x / d t (N, 3), Savitzky-Golay (cubic, :data:`ACCEL_WINDOW_S`) per stretch of
    uniform samples (a time jump starts a new one): :func:`quadsim.logs.savgol.savgol`,
    scipy's ``savgol_filter`` to round-off with the ends' fits built once per window (a
    payload's mount height moves the attachment, and each height differentiates anew).
    ``deriv`` 0: the same filter's smoothed ``x`` (an acceleration logged as such, given the
    response a differentiated velocity has)."""
    from ..logs.savgol import savgol

    if len(t) < 3:
        return np.zeros_like(x) if deriv else np.array(x, dtype=float)
    dt = np.diff(t)
    cut = np.nonzero(np.abs(dt - dt[0]) > 0.5 * dt[0])[0] + 1
    out = np.zeros_like(x)
    for piece in np.split(np.arange(len(t)), cut):
        if len(piece) < 3:
            continue
        step = float(t[piece[1]] - t[piece[0]])
        window = min(len(piece) - (1 - len(piece) % 2), 2 * int(ACCEL_WINDOW_S / (2 * step)) + 1)
        if window >= 5:
            out[piece] = savgol(x[piece], window, 3, deriv=deriv, delta=step)
        elif deriv:
            out[piece] = np.gradient(x[piece], t[piece], axis=0)
        else:
            out[piece] = x[piece]
    return out


class CableSwing(CablePayload):
    """``cable_payload`` without an internal state: the swing integrated from the logged
    motion (module doc). Fitted: ``mass`` and ``length``, the swing at the first sample and
    its damping rate ``swing_damping`` (1/s; not the engine's ``damping``, the axial spring's
    coefficient); the attachment ``x, y`` (body, m) held at the engine's default, ``z``
    fitted by the reading with a mount (:data:`quadsim.gap.explanations.CABLE_MOUNT`)."""

    parameters = tuple(
        EffectParameter("length", "m", 0.5, 0.05, 5.0, "cable length") if p.name == "length"
        else p for p in CablePayload.parameters) + (
        EffectParameter("lean_x", "rad", 0.0, -1.0, 1.0,
                        "cable's lean from the vertical towards world +x at the first sample"),
        EffectParameter("lean_y", "rad", 0.0, -1.0, 1.0,
                        "cable's lean from the vertical towards world +y at the first sample"),
        EffectParameter("rate_x", "rad/s", 0.0, -5.0, 5.0, "swing rate along x at the start"),
        EffectParameter("rate_y", "rad/s", 0.0, -5.0, 5.0, "swing rate along y at the start"),
        EffectParameter("swing_damping", "1/s", 0.0, 0.0, 5.0,
                        "swing damping rate (air drag on the payload and cable)"))

    #: the swing at the first sample, its damping and the attachment's height are fitted
    #: with the payload, never part of an answer (the JSON's params keep them)
    facts = dataclasses.replace(CablePayload.facts,
                                nuisance=(*START_SWING, "swing_damping", "z"))

    #: (context fields, vehicle attributes) ``loads`` reads
    #: (:attr:`quadsim.effects.base.EffectBase.loads_reads`): the logged motion only (kept
    #: per flight motion by the caller) and the vehicle's CoM and gravity; not the rotor
    #: speeds, so a rotor-delay shift reuses the pull
    loads_reads = ((), ("com", "gravity"))

    def __init__(self, *, restarts: tuple = (), **values: float):
        """``values``: the parameters; ``restarts``: the stacked flights that start at a
        swing of their own (:class:`Restart`; the stacked fit's, :mod:`quadsim.gap.diagnose`:
        not parameters of the effect, whose start swing is its first flight's)."""
        super().__init__(**values)
        self.restarts = tuple(restarts)

    def state_size(self) -> int:
        return 0

    def pull(self, t, position, velocity, quat, body_rate, params: VehicleParams, *,
             rotation: np.ndarray | None = None, memo: dict | None = None,
             accel_world: np.ndarray | None = None):
        """Cable pull on the vehicle: force (N, 3, world N), torque about the CoM (N, 3, body
        N m) and the swing angle from the vertical (N,, rad). ``rotation``: ``quat``'s
        matrices when the caller has them; ``memo``: a dict kept across calls on the same
        logged motion (the attachment's acceleration is kept there per attachment point).
        The attachment's acceleration is d/dt (v + R (w x r_a)), ``velocity`` differentiated;
        ``accel_world`` (N, 3, m/s^2): the vehicle's acceleration where no velocity is
        logged (:attr:`quadsim.effects.base.EffectContext.accel_world`: R f - g e_z, R the
        logged attitude or the gyro's own frame, :func:`quadsim.gap.logcheck.posefree_states`;
        the pull in the body frame is the same for any R' = C R, C constant), then
        a + d/dt R (w x r_a), ``accel_world`` through the same filter."""
        rot = quat_to_rotmat(quat) if rotation is None else rotation
        arm = np.array([self.x, self.y, self.z])
        key = ("cable_accel", self.x, self.y, self.z)
        accel = None if memo is None else memo.get(key)
        if accel is None:
            turning = np.einsum("bij,bj->bi", rot, cross(body_rate, arm))
            accel = _derivative(t, velocity + turning) if accel_world is None else \
                _derivative(t, turning) + _derivative(t, accel_world, deriv=0)
            if memo is not None:
                memo[key] = accel
        q, w = self._swing(t, accel, params.gravity, memo)
        e = -accel
        e[:, 2] -= params.gravity
        tension = self.mass * (np.einsum("bi,bi->b", q, e)
                               + self.length * np.einsum("bi,bi->b", w, w))
        force = np.maximum(tension, 0.0)[:, None] * q
        torque = cross(arm - params.com, np.einsum("bji,bj->bi", rot, force))
        return force, torque, np.arccos(np.clip(-q[:, 2], -1.0, 1.0))

    #: swings kept per flight (:meth:`_swing`): a fit's Jacobian and its next step
    KEPT_SWINGS = 16

    def _swing(self, t, accel, gravity: float, memo: dict | None):
        """:func:`swing` of this cable; with a ``memo`` (one flight's logged motion) the
        last :data:`KEPT_SWINGS` are kept by their inputs: the swing does not depend on the
        payload's mass (it only scales the pull) nor on the rotor speeds (a rotor-delay
        shift), so those evaluations reuse it."""
        key = (self.length, self.lean_x, self.lean_y, self.rate_x, self.rate_y,
               self.x, self.y, self.z, float(gravity), self.swing_damping, self.restarts)
        kept = None if memo is None else memo.setdefault("cable_swings", {})
        if kept is not None and key in kept:
            return kept[key]
        value = swing(t, accel, self.length, gravity,
                      start_state((self.lean_x, self.lean_y), (self.rate_x, self.rate_y)),
                      damping=self.swing_damping, restarts=self.restarts)
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
                                     memo=ctx.flight_memo, accel_world=ctx.accel_world)
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.force_world, loads.torque_body = force, torque
        return loads


class CantedRotorFit(CantedRotor):
    """``canted_rotor`` as the diagnosis fits it: the tilted axis' horizontal components
    ``tilt_x``, ``tilt_y`` (rad, small angles: the axis leans by them towards body +x, +y)
    instead of angle and azimuth, which are singular at angle 0 (every azimuth gives the
    same untilted rotor, so a fit starting there cannot move). ``angle = hypot(tilt_x,
    tilt_y)``, ``azimuth = atan2(tilt_x, -tilt_y)`` (then Rodrigues tilts z by angle about
    (cos azimuth, sin azimuth, 0) towards (sin azimuth, -cos azimuth) = (tilt_x, tilt_y) /
    angle). The rotor index is fixed per candidate: one candidate per rotor
    (``facts.one_per_rotor``), the one that fits the training flights best is kept."""

    parameters = CantedRotor.parameters + CantedRotor.facts.fit_parameters

    def apply_to_params(self, params):
        angle = float(np.hypot(self.tilt_x, self.tilt_y))
        if angle == 0.0:
            return CantedRotor(rotor=self.rotor, angle=self.angle,
                               azimuth=self.azimuth).apply_to_params(params)
        return CantedRotor(rotor=self.rotor, angle=angle,
                           azimuth=float(np.arctan2(self.tilt_x, -self.tilt_y))
                           ).apply_to_params(params)


def _refit_phrase(parameter, value, ci, params) -> str:
    if parameter == "thrust":
        return (f"{plus_minus(value, ci, 100)} % thrust per Ω² on all {params.rotor_count} "
                "rotors")
    return f"{plus_minus(value, ci, 100)} % drag torque per Ω²"


class NominalRefit(EffectBase):
    """Baseline: the parameter set's thrust and drag factors b and d refitted (relative
    changes); the reference model's shared group and the held-out reading "b and d are off"
    (:data:`quadsim.gap.fitting.BASELINE`)."""

    name = "nominal_refit"
    parameters = (
        EffectParameter("thrust", "1", 0.0, -0.9, 3.0, "relative change of b"),
        EffectParameter("drag", "1", 0.0, -0.9, 3.0, "relative change of d"),
    )
    facts = EffectFacts(
        fitted=("thrust", "drag"),
        # d from the yaw torque on measured speeds is regression-diluted to -1 near hover
        instrumented=("drag",),
        scales={"thrust": Scale(lambda p: 0.05, "5 %: as a propeller change (thrust_factor)"),
                "drag": Scale(lambda p: 0.2, "20 %: d is known less well than b")},
        ranges={"thrust": PlausibleRange(-0.15, 0.05, "relative", "as thrust_factor.change")},
        separate_from={
            "mass_offset": "weigh the vehicle, or measure b on a thrust stand",
            "thrust_factor": "the same effect (b refitted); a thrust stand tells b and d apart",
            "thrust_curve": "fly over a wider range of rotor speeds"},
        words={"thrust": Words("thrust per Omega^2 on every rotor", "%", 100.0, _refit_phrase),
               "drag": Words("drag torque per Omega^2", "%", 100.0, _refit_phrase)},
    )

    def apply_to_params(self, params):
        return params.replace(thrust_factor=params.thrust_factor * (1 + self.thrust),
                              drag_factor=params.drag_factor * (1 + self.drag))


def _speed_gain_phrase(parameter, value, ci, params) -> str:
    return f"the rotors spin {plus_minus(value, ci, 1e2)} % faster per command (steady speed)"


class SpeedGain(EffectBase):
    """The motor map's gain: the steady rotor speed per command scaled by (1 + gain), as a
    pseudo-effect the reference model shares (:mod:`.calibrate`) when commands are logged and
    no battery voltage is.

    Why. The static command -> speed map (:func:`quadsim.gap.fitting.fit_motor_map`) is fitted
    once on all reference flights pooled; a single flight's mean speed per command still differs
    from it, and by how it was flown: where the rotor dynamics are not first order at one
    time constant, the mean speed a varying command gives depends on how much it varies
    (CHANGELOG.md: Docstrings as contracts). Without a shared
    parameter for it, that offset had no place in the reference model's uncertainty, and a
    nominal flight's own offset was read as ``thrust_factor`` (whose propeller coupling moves
    the speed per command) or ``battery_sag``. With a battery-voltage log the shared
    ``battery_sag.full_voltage`` (speed per command ~ vbat / V_full) already is this gain.

    Physics: ``Omega_ss = (1 + gain) Omega_map(command)`` (:meth:`SpeedGain.speed_factor`,
    upstream of the measured speed like a battery: the thrust at a measured speed is unchanged).
    Typical size (fit step unit) 1 %; bounds -50 % to +100 %: the references' own gain stays
    within a few per cent (a map off by more is refused by the motor map's own checks), but a
    flight's reading of another motor or ESC
    (:func:`quadsim.gap.explanations.explanations_for`, ``MOTOR_CHANGE``) takes the gain of its
    own, tens of per cent (CHANGELOG.md: Docstrings as contracts).

    Example::

        >>> SpeedGain(gain=0.01).speed_factor(np.zeros(3))     # array([1.01, 1.01, 1.01])
    """

    name = "speed_gain"
    parameters = (
        EffectParameter("gain", "1", 0.0, -0.5, 1.0,
                        "relative change of the steady rotor speed per command"),
    )
    facts = EffectFacts(
        fitted=("gain",),
        upstream_of_speed=True,
        scales={"gain": Scale(lambda p: 0.01, "1 %: the references' own gain stays within a few "
                                             "per cent (class doc)")},
        words={"gain": Words("steady speed per command", "%", 100.0, _speed_gain_phrase)},
    )

    def speed_factor(self, t, vbat=None):
        if self.gain == 0.0:
            return None
        return np.full(len(np.atleast_1d(t)), 1.0 + self.gain)


#: the shared-candidate part (name, fixed, fitted) of the motor map's gain
SPEED_GAIN_PART = ("speed_gain", {}, ("gain",))


class DragLaw(BodyDrag):
    """The references' horizontal drag under a quadratic law, held fixed in every reading
    of a flight (:mod:`quadsim.gap.evidence`): :class:`quadsim.effects.body_drag.BodyDrag`
    under its own name, so that a reading's own body drag stays apart from it. Never fitted
    (its C_d A is the references' equivalent)."""

    name = "drag_law"
    facts = EffectFacts()


#: library effect -> the class the diagnosis fits in its place (module doc)
FIT_FORMS = MappingProxyType({cls.name: cls for cls in (CantedRotorFit, CableSwing)})
#: the diagnosis' own effects, not in the library (module doc)
PSEUDO_EFFECTS = MappingProxyType({cls.name: cls for cls in (NominalRefit, SpeedGain, DragLaw)})
#: every class the diagnosis fits in place of a name that is not the library's own
LOCAL_EFFECTS = MappingProxyType({**FIT_FORMS, **PSEUDO_EFFECTS})
#: name -> the class the diagnosis builds for it (the library, with :data:`LOCAL_EFFECTS`)
FIT_EFFECTS = MappingProxyType({**EFFECTS, **LOCAL_EFFECTS})


def effect_class(name: str) -> type:
    """The class the diagnosis builds for effect ``name`` (KeyError for an unknown one)."""
    return FIT_EFFECTS[name]


def facts_for(name: str) -> EffectFacts:
    """The diagnosis facts of effect ``name`` (library or pseudo-effect)."""
    return FIT_EFFECTS[name].facts


def parameter_facts_for(parameter: str) -> ParameterFacts:
    """The facts of ``effect.parameter`` (``"speed_gain.gain"``) of any effect the diagnosis
    fits, library or its own: unit, meaning, typical scale, plausible range, words
    (:class:`quadsim.effects.facts.ParameterFacts`; :func:`quadsim.effects.facts_of` for
    the library alone). KeyError for an unknown effect or parameter."""
    name, _, key = parameter.partition(".")
    return parameter_facts(FIT_EFFECTS[name], key)


def build_effect(name: str, values: dict):
    """Effect ``name`` with parameter ``values``: a :data:`LOCAL_EFFECTS` class built directly,
    a library effect through :func:`quadsim.effects.make_effect` (its bounds checked)."""
    if name in LOCAL_EFFECTS:
        return LOCAL_EFFECTS[name](**values)
    return make_effect(name, **values)


def _priors() -> dict:
    out = {}
    for name, cls in FIT_EFFECTS.items():
        for key, plausible in cls.facts.ranges.items():
            out[name if key == ALL else f"{name}.{key}"] = (
                plausible.lower, plausible.upper, plausible.kind, plausible.source)
    return out


#: parameter (``effect.parameter``, or ``effect`` for all its parameters) -> (lower, upper,
#: kind, source): the effects' declared plausible ranges (a read-only view). kind
#: "relative": fraction of 1; "mass": of the vehicle mass; "arm": of the arm length;
#: "absolute": in the parameter's unit; "hover", "momentum", "lift": see
#: :class:`quadsim.effects.facts.PlausibleRange`.
PRIORS = MappingProxyType(_priors())

#: score given to a parameter without a prior (ranks between well inside and at the edge).
NO_PRIOR_SCORE = 0.5


def _key(parameter: str) -> str | None:
    if parameter in PRIORS:
        return parameter
    head = parameter.split(".")[0]
    return head if head in PRIORS else None


def plausibility(parameter: str, value: float, params: VehicleParams):
    """(score, plausible, prior text) of a fitted ``value``; (0, True, "") without a prior."""
    key = _key(parameter)
    if key is None:
        return NO_PRIOR_SCORE, True, ""
    lower, upper, kind, source = PRIORS[key]
    if kind == "mass":
        value = value / params.mass
    elif kind == "hover":  # linear thrust term as a fraction of the hover thrust
        value = value / hover_thrust_per_speed(params)
    elif kind == "arm":
        value = value / arm_length(params)
    elif kind == "momentum":
        value = value / momentum_rate_damping(params)
    elif kind == "lift":
        value = value / momentum_translational_lift(params)
    bound = upper if value >= 0 else lower
    score = abs(value) / abs(bound) if bound != 0 else (0.0 if value == 0 else float("inf"))
    scale = {"relative": 100, "mass": 100, "arm": 100, "hover": 100, "absolute": 1,
             "momentum": 1, "lift": 1}[kind]
    unit = {"relative": " %", "mass": " % of the vehicle mass", "arm": " % of the arm",
            "hover": " % of the hover thrust", "absolute": "",
            "momentum": (f" x the momentum-theory damping "
                         f"{momentum_rate_damping(params):.2g} N m s/rad"),
            "lift": (f" x the momentum-theory lift "
                     f"{momentum_translational_lift(params):.2g} kg/m")}[kind]
    text = f"plausible {lower * scale:g} .. {upper * scale:g}{unit} ({source})"
    return float(score), bool(score <= 1.0), text


#: a parameter is determined when its posterior spread is below this fraction of its prior's
#: (the rule a value is printed by, and a shared thrust-curve slope kept by)
DETERMINED = 0.5


def curve_slope_sd(params: VehicleParams) -> float:
    """Prior spread (N s/rad) of a thrust curve's linear term: half the plausible range of
    :data:`PRIORS` ``thrust_curve.linear`` (a fraction of the hover thrust per rad/s), in
    SI for ``params``."""
    return ThrustCurve.facts.spread_of("linear", params)


def plausible_values(ev, params: VehicleParams) -> dict:
    """The values of reading ``ev`` (an Evidence: ``values``, ``determined``, ``post_sd``,
    ``explanation.loose``) that its plausibility for ``params`` is judged on: its determined
    ones, less a loose one (:attr:`quadsim.gap.explanations.Explanation.loose`) whose 95 % interval
    ``value +- 1.96 post_sd`` reaches its plausible range (:func:`plausibility` at the
    interval's ends, its middle and its quarter points). Why: what a reading carries beside
    its effect (a wind's flapping moment) is fitted on every flight, where little air speed
    fixes it near zero but not in sign; flagged at a value its interval does not place
    outside, the reading was "outside its plausible range" by noise."""
    loose = set(getattr(getattr(ev, "explanation", None), "loose", ()) or ())
    post = getattr(ev, "post_sd", None) or {}
    out = {}
    for q, v in ev.values.items():
        if not ev.determined.get(q):
            continue
        if q in loose and q in post:
            half = 1.96 * float(post[q])
            if any(
                    plausibility(q, v + k * half, params)[1] for k in (-1, -0.5, 0, 0.5, 1)):
                continue
        out[q] = v
    return out


def candidate_plausibility(values: dict, params: VehicleParams):
    """(score, plausible, text) of a whole fitted candidate: its least plausible parameter
    (the text led by that parameter's name where the values span several effects and it
    lies outside its range).

    A per-rotor effect's values are split into their mean (judged as the uniform parameter
    its facts name, ``uniform_as``: a mismatch's as a thrust-per-Omega^2 change,
    ``thrust_factor.change``) and each rotor's deviation from that mean (judged as the
    per-rotor effect): four rotors all 16 % weak are a uniform loss, not four damaged props."""
    values = dict(values)
    for name, cls in FIT_EFFECTS.items():
        facts = cls.facts
        if not (facts.per_rotor and facts.uniform_as):
            continue
        prefix = f"{name}.{facts.per_rotor.partition('{}')[0]}"
        rotors = {k: v for k, v in values.items() if k.startswith(prefix)}
        if len(rotors) > 1:
            mean = sum(rotors.values()) / len(rotors)
            for k, v in rotors.items():
                values[k] = v - mean
            values[facts.uniform_as] = mean
    scores = [(plausibility(k, v, params), k) for k, v in values.items()]
    if not scores:
        return NO_PRIOR_SCORE, True, ""
    (score, ok, text), key = max(scores, key=lambda s: s[0][0])
    # a reading of several effects (a wind with its drag and flapping moment) says which
    # parameter lies outside, the prior text being that parameter's
    if not ok and len({k.split(".")[0] for k in values}) > 1:
        text = f"{key}: {text}"
    return score, ok, text


# --- collinear explanations in words (module doc) ---------------------------------------------


def _separate() -> dict:
    out: dict = {}
    for name, cls in FIT_EFFECTS.items():
        for other, text in cls.facts.separate_from.items():
            pair = frozenset({name, other})
            if out.get(pair, text) != text:
                raise ValueError(f"{name} and {other}: two texts on what separates them")
            out[pair] = text
    return out


#: known collinear pairs and what data would separate them: a read-only view of the effects'
#: declared ``facts.separate_from`` (each pair declared by one of the two)
SEPARATE = MappingProxyType(_separate())


def separation(best: str, others: list[str]) -> dict:
    """What tells reading ``best`` from each of ``others`` (:data:`SEPARATE`; a generic
    advice for a pair without one)."""
    return {other: SEPARATE.get(frozenset({best.split("+")[0], other.split("+")[0]}),
                                "more varied flights (speeds, heights, attitudes)")
            for other in others}


def unit_of(parameter: str) -> str:
    """Unit of ``effect.parameter`` (from the effect's declaration)."""
    name, _, p = parameter.partition(".")
    try:
        specs = {s.name: s for s in effect_class(name).parameters}
    except KeyError:
        return ""
    if p in specs:
        return specs[p].unit
    return "1" if p.startswith("rotor_") else ""


def describe(name: str, values: dict, ci: dict, params: VehicleParams,
             fixed: dict | None = None) -> str:
    """Physical statement (with units) of a fitted candidate (``values``, ``ci``: the fitted
    ``effect.parameter`` values and 95 % half-widths; ``fixed``: the values held fixed in
    the fit, e.g. ``canted_rotor.rotor``): each effect's declared wording
    (:class:`quadsim.effects.facts.Words`, ``phrase``; parameters worded together first,
    ``facts.together``), its nuisance parameters left out, a parameter without a phrase
    stated with its declared meaning and unit (:func:`_worded`); ``name`` where nothing is
    left."""
    fixed = fixed or {}
    parts, together = [], set()
    for effect in dict.fromkeys(key.partition(".")[0] for key in values):
        facts = _facts(effect)
        if facts is None or facts.together is None:
            continue
        keys = [f"{effect}.{p}" for p in facts.together.parameters]
        together |= set(keys)
        if all(k in values for k in keys):
            own = _own(effect, values)
            parts.append(facts.together.phrase(own, _own(effect, ci), params,
                                               _own(effect, fixed)))
    for key, value in values.items():
        effect, _, p = key.partition(".")
        facts = _facts(effect)
        if key in together or (facts is not None and p in facts.nuisance):
            continue
        words = facts.words_of(p) if facts is not None else None
        c = ci.get(key)
        if words is not None and words.phrase is not None:
            parts.append(words.phrase(p, value, c, params))
        else:
            parts.append(_worded(key, value, c, params))
    return ", ".join(parts) if parts else name


def _facts(effect: str):
    cls = FIT_EFFECTS.get(effect)
    return None if cls is None else cls.facts


def _own(effect: str, table: dict) -> dict:
    """``table``'s entries of ``effect``, keyed by its parameter names."""
    prefix = effect + "."
    return {k[len(prefix):]: v for k, v in table.items() if k.startswith(prefix)}


def _worded(key: str, value: float, c: float | None, params: VehicleParams) -> str:
    """A parameter without a declared phrase, stated with its declared meaning and unit
    (never as a bare ``effect.parameter = value``)."""
    name, _, p = key.partition(".")
    try:
        spec = {s.name: s for s in effect_class(name).parameters}[p]
        text, unit = spec.doc, spec.unit
    except KeyError:
        text, unit = p.replace("_", " "), unit_of(key)
    return f"{name.replace('_', ' ')}: {text} {plus_minus(value, c, 1.0, '.4g')} {unit}".rstrip()


def torque_text(entry: dict) -> str:
    rms = entry.get("heldout_rms_after") or {}
    have = [(k, rms[k]) for k in ("Mx", "My", "Mz") if k in rms]
    return ", ".join(f"{k} {v:.2g} N m" for k, v in have)


#: parameters whose "off" value does not switch their effect off (with a voltage log the sag
#: (V / V_full)^2 acts for every V_full), so "significantly away from off" does not apply:
#: each effect's ``facts.no_off_value`` (a read-only view)
NO_OFF_VALUE = frozenset(f"{name}.{p}" for name, cls in EFFECTS.items()
                         for p in cls.facts.no_off_value)

#: a fitted value within this fraction of its typical size from a bound is "at the bound".
AT_BOUND = 1e-3
#: a standard error below this fraction of the parameter's typical size is not credible.
ABSURD_CI = 1e-6

#: library effects acting upstream of the measured rotor speed (command -> speed channel
#: only): each effect's ``facts.upstream_of_speed`` (a read-only view)
UPSTREAM_OF_SPEED = frozenset(name for name, cls in EFFECTS.items()
                              if cls.facts.upstream_of_speed)

#: the step unit of a fitted parameter whose effect declares no typical scale for it
DEFAULT_SCALE = 1.0


@dataclass(frozen=True)
class Candidate:
    """Effects to fit together: ``parts`` = ((effect name, fixed values, fitted names), ...);
    ``base``: effects already in the model (a diagnosed model as the starting point, e.g.
    ``python -m quadsim.gap --effects-file``), applied first and never fitted."""

    name: str
    parts: tuple[tuple[str, dict, tuple[str, ...]], ...]
    base: tuple = ()

    @property
    def parameter_names(self) -> list[str]:
        return [f"{name}.{p}" for name, _, fitted in self.parts for p in fitted]

    @property
    def fixed_values(self) -> dict[str, float]:
        """The values held fixed, ``effect.parameter`` -> value (e.g. a canted rotor's index)."""
        return {f"{name}.{p}": float(v) for name, fixed, _ in self.parts for p, v in fixed.items()}

    def effects(self, theta: np.ndarray) -> list:
        """The base effects, then each part built with its fixed values and its fitted ones
        from ``theta`` (in :attr:`parameter_names` order). An effect is its class and its
        values, set once: a part whose values a step of ``theta`` did not move is the same
        object as before (:func:`_built`)."""
        return list(self.base) + built_parts(self.parts, theta)

    def combine(self, other: Candidate) -> Candidate:
        return Candidate(f"{self.name}+{other.name}", self.parts + other.parts, self.base)


def built_parts(parts: tuple, theta: np.ndarray) -> list:
    """The effects of ``parts`` ((name, fixed values, fitted parameter names), ...), each
    built with its fixed values and its fitted ones from ``theta`` (SI, in the parts'
    order). An effect is its class and its values, set once: a part whose values are those
    of an earlier build is that same object (:func:`_built`; a fixed value that is not
    hashable: built anew)."""
    out, k = [], 0
    for name, fixed, fitted in parts:
        values = dict(fixed)
        for p in fitted:
            values[p] = float(theta[k])
            k += 1
        try:
            out.append(_built(name, tuple(values.items())))
        except TypeError:
            out.append(build_effect(name, values))
    return out


@lru_cache(maxsize=4096)
def _built(name: str, values: tuple) -> object:
    """:func:`build_effect` of ``name`` with ``values`` ((parameter, value), ...), kept: a
    fit builds the same effect for every step that moves another part."""
    return build_effect(name, dict(values))


@dataclass
class Fit:
    """A fitted candidate: parameter values, standard errors, 95 % CI half-widths, cost."""

    candidate: Candidate
    theta: np.ndarray
    stderr: np.ndarray
    correlation: np.ndarray
    cost: float
    identifiable: list[bool] = field(default_factory=list)
    significant: list[bool] = field(default_factory=list)

    def params(self) -> dict[str, float]:
        return dict(zip(self.candidate.parameter_names, map(float, self.theta)))

    def ci(self) -> dict[str, float]:
        return dict(zip(self.candidate.parameter_names, map(float, 1.96 * self.stderr)))

    def effects(self) -> list:
        return self.candidate.effects(self.theta)


def _fit_spec_entry(cls: type) -> tuple:
    facts = cls.facts
    fitted = None if facts.per_rotor else tuple(facts.fitted)

    def typical(params: VehicleParams, facts=facts) -> list[float]:
        return [facts.scale_of(p).size(params) for p in facts.fitted_for(params.rotor_count)]

    return fitted, dict(facts.fixed), typical


#: effect -> (parameters to fit, fixed values, typical magnitude of each fitted parameter
#: as a function of the vehicle), for every effect the diagnosis fits: a read-only view of
#: the effects' ``facts`` (:mod:`quadsim.effects.facts`; None: one per rotor). Unlisted
#: parameters stay at their ``off`` value.
FIT_SPEC = MappingProxyType({name: _fit_spec_entry(cls) for name, cls in FIT_EFFECTS.items()
                             if cls.facts.fitted or cls.facts.per_rotor})


def candidates_for(params: VehicleParams, has_commands: bool,
                   has_vbat: bool = False) -> list[Candidate]:
    """The candidate list for a vehicle: every effect of the library that the data can show,
    in name order, as each declares it (``facts``).

    An effect upstream of the measured rotor speed (``facts.upstream_of_speed``: a motor
    lag, a battery) needs commands: it is fitted on the command -> speed channel only (with
    measured rotor speeds it does not change the wrench); one with companions is fitted with
    them (wind with the rotor drag: wind alone exerts no force); one with a discrete index
    (``facts.one_per_rotor``: a canted rotor) is one candidate per rotor (the diagnosis keeps
    the one that fits the training flights best); with a voltage log an effect fits its
    ``facts.with_voltage_log`` parameters instead."""
    out = []
    for name in sorted(EFFECTS):
        facts = EFFECTS[name].facts
        fitted = facts.fitted_for(params.rotor_count)
        if not fitted or (facts.upstream_of_speed and not has_commands):
            continue
        if facts.one_per_rotor:      # a discrete index: one candidate per rotor
            out += [Candidate(name, ((name, {facts.one_per_rotor: float(k + 1)}, fitted),))
                    for k in range(params.rotor_count)]
            continue
        if has_vbat and facts.with_voltage_log:
            fitted = tuple(facts.with_voltage_log)
        known = {p.name for p in EFFECTS[name].parameters}
        fitted = tuple(p for p in fitted if p in known)
        if fitted:
            companions = tuple((c.effect, {}, tuple(c.fitted)) for c in facts.companions)
            out.append(Candidate(name, ((name, dict(facts.fixed), fitted),) + companions))
    return out


def typical_scales(candidate: Candidate, params: VehicleParams) -> np.ndarray:
    """The typical size of each fitted parameter of ``candidate`` for ``params`` (its unit):
    the effect's declared scale (``facts.scales``), else :data:`DEFAULT_SCALE`."""
    scales = []
    for name, _, fitted in candidate.parts:
        facts = facts_for(name)
        for p in fitted:
            scale = facts.scale_of(p)
            scales.append(DEFAULT_SCALE if scale is None else scale.size(params))
    return np.asarray(scales, dtype=float)


def curve_bound(params: VehicleParams) -> float:
    """The largest thrust-curve slope a fit takes (N s/rad): the hover thrust per rad/s of
    hover speed, ``b Omega_h``, a linear term carrying the whole hover thrust (fs's stand
    curve, 0.785 + 9.16 a + 18.0 a^2 N, needs 0.81 of it about its hover speed; the effect's
    own range is +-1 N s/rad, for any vehicle)."""
    return hover_thrust_per_speed(params)


def parameter_bounds(candidate: Candidate, params: VehicleParams
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of each fitted parameter of ``candidate``: its declared bounds, within
    the effect's fit window for this vehicle where it declares one (``facts.windows``)."""
    lower, upper = [], []
    for name, _, fitted in candidate.parts:
        cls = effect_class(name)
        specs = {p.name: p for p in cls.parameters}
        for p in fitted:
            lo, hi = specs[p].lower, specs[p].upper
            window = cls.facts.window_of(p)
            if window is not None:
                lo, hi = max(lo, window.low(params)), min(hi, window.high(params))
            lower.append(lo)
            upper.append(hi)
    return np.asarray(lower), np.asarray(upper)


def start_off(candidate: Candidate) -> np.ndarray:
    """The "off" value of each fitted parameter of ``candidate`` (P,): the value that leaves
    its effect out (each effect's parameter spec), in the parameter's unit."""
    off = []
    for name, _, fitted in candidate.parts:
        specs = {p.name: p for p in effect_class(name).parameters}
        off += [specs[p].off for p in fitted]
    return np.asarray(off, dtype=float)


def _start(candidate: Candidate, lower: np.ndarray, upper: np.ndarray,
           typical: np.ndarray) -> np.ndarray:
    x0 = start_off(candidate)
    # Start strictly inside the bounds (least_squares' trust region needs it); an effect
    # whose "off" value sits on a bound starts a tenth of its typical size away from it.
    x0 = np.where(x0 <= lower, lower + 0.1 * typical, x0)
    x0 = np.where(x0 >= upper, upper - 0.1 * typical, x0)
    return np.clip(x0, lower + 1e-12 * typical, upper - 1e-12 * typical)


def stack_states(flights: list[FlightStates]) -> FlightStates:
    """Several flights as one sample set (each keeps its own time axis; the rotor channel
    skips the boundaries)."""
    if len(flights) == 1:
        return flights[0]

    def cat(name):
        values = [getattr(f, name) for f in flights]
        return None if any(v is None for v in values) else np.concatenate(values)

    first = flights[0]
    return FlightStates(*(cat(n) for n in ("t", "position", "velocity", "accel_world", "quat",
                                           "body_rate", "body_accel", "specific_force",
                                           "rotor_speed", "rotor_accel", "command", "vbat")),
                        first.accel_source, first.window_s, first.polyorder, "stacked",
                        all(f.pose for f in flights), all(f.attitude for f in flights),
                        all(f.synthesised for f in flights))


def residuals(states: FlightStates, params: VehicleParams, effects: list, *,
              rotor_channel: bool, memo: dict | None = None) -> np.ndarray:
    """Unscaled residual (N, C): Fx Fy Fz Mx My Mz (N, N m) [+ rotor_1..R (rad/s)].

    The force channels are compared as specific force times the *nominal* mass
    (``(F_meas - F_model) * m / m_vehicle``): an unmodelled force that the log carries
    (drag a candidate does not model) then weighs the same for every candidate. In newtons
    of the candidate's own vehicle, a candidate that adds mass would also scale every
    unexplained force by m'/m and lose against an equivalent thrust scale (CHANGELOG.md:
    Docstrings as contracts).

    The torque channels likewise are angular acceleration times the *nominal* inertia,
    ``I (I_v^-1 (M_meas - M_model))`` = ``I (w_dot_meas - w_dot_model)`` with ``I_v`` the
    candidate vehicle's inertia: the measured angular acceleration (a differentiated, noisy
    gyro) then enters every candidate's residual with weight one. In newtons-metres of the
    candidate's own inertia the gyro noise would be scaled by ``I_v``, and least squares
    would shrink ``I_v`` to shrink the noise (errors in variables; CHANGELOG.md: Docstrings
    as contracts)."""
    upstream = upstream_speeds(states, effects)
    if memo is None:
        force, torque, vehicle = model_wrench(states, params, effects, rotor_speed=upstream)
        meas_force, meas_torque = measured_wrench(states, vehicle)
        inertia_map = _vehicle_facts(vehicle, params)[1]
    else:
        rotation, motion = flight_memo(memo, states)
        plan = effects_plan(effects)
        if upstream is None:
            force, torque, vehicle = memoised(
                memo, ("wrench", id(states), id(params), plan.wrench), states,
                lambda: model_wrench(states, params, plan.effects, rotation=rotation,
                                     flight_memo=motion))
        else:   # speeds of this evaluation's own: its wrench is not one to keep
            force, torque, vehicle = model_wrench(states, params, plan.effects,
                                                  rotor_speed=upstream, rotation=rotation,
                                                  flight_memo=motion)
        values, inertia_map = kept(motion, "vehicle_facts", (id(vehicle), id(params)),
                                   (vehicle, params), lambda: _vehicle_facts(vehicle, params))
        # what the motion implies: the same for every rotor timing of one flight
        arrays = (states.body_rate, states.body_accel, states.specific_force)
        meas_force, meas_torque = memoised(
            memo, ("measured", id(arrays[0]), id(arrays[1]), id(arrays[2])) + values, arrays,
            lambda: measured_wrench(states, vehicle))
    torque_residual = meas_torque - torque
    if inertia_map is not None:
        torque_residual = torque_residual @ inertia_map
    force_residual = (meas_force - force) * (params.mass / vehicle.mass)
    if not rotor_channel:
        return np.concatenate((force_residual, torque_residual), axis=1)
    if memo is None:
        rotor = rotor_residual(states, params, effects)
    else:
        rotors = params.rotor_count if states.command is None else states.command.shape[1]
        rotor = memoised(memo, ("rotor", id(states), id(params), plan.rotor(rotors)), states,
                         lambda: rotor_residual(states, params, plan.effects, memo=memo))
    return np.concatenate((force_residual, torque_residual, rotor), axis=1)


def upstream_speeds(states: FlightStates, effects) -> np.ndarray | None:
    """The rotor speeds (N, R) rad/s of synthesised ``states`` (speeds made from the log's
    commands, :attr:`FlightStates.synthesised`) under the effects upstream of the speed
    (``facts.upstream_of_speed``: a battery's sag; not the motor map's gain
    :class:`SpeedGain`, the references' own, which the synthesis read), each one's time law
    ``speed_factor(t - t_0)`` (the log's voltage is not read: the speeds were synthesised
    through the references' map at it, :mod:`quadsim.gap.logcheck`) times the synthesised
    speeds; None for measured speeds or where no such effect acts (the speeds as logged).

    Why only there: a measured rotor speed already carries what acts upstream of it
    (:mod:`quadsim.effects.battery_sag`); a speed synthesised from a command is the model's
    speed for that command, which such an effect changes."""
    if not getattr(states, "synthesised", False) or states.rotor_speed is None:
        return None
    factor = None
    for effect in getattr(effects, "effects", effects) or ():
        facts = getattr(type(effect), "facts", None)
        # the motor map's gain is the references' map's, which the synthesis read already
        # (its command model is fitted on the references' speeds): never applied twice
        if facts is None or not facts.upstream_of_speed or isinstance(effect, SpeedGain):
            continue
        one = effect.speed_factor(states.t - states.t[0])
        if one is not None:
            factor = one if factor is None else factor * one
    return None if factor is None else states.rotor_speed * np.asarray(factor)[:, None]


def _vehicle_facts(vehicle: VehicleParams, params: VehicleParams) -> tuple:
    """What :func:`residuals` reads of the model's vehicle ``vehicle`` against the nominal
    ``params``: (its mass, CoM and inertia as the key of its measured wrench (kg, float64
    bytes), ``I_v^-1 I`` (:func:`_inertia_map`) or None where the inertias are equal)."""
    key = (vehicle.mass, vehicle.com.tobytes(), vehicle.inertia.tobytes())
    if vehicle.inertia is params.inertia or np.array_equal(vehicle.inertia, params.inertia):
        return key, None
    return key, _inertia_map(np.asarray(vehicle.inertia, dtype=float).tobytes(),
                             np.asarray(params.inertia, dtype=float).tobytes())


@lru_cache(maxsize=256)
def _inertia_map(vehicle_inertia: bytes, nominal_inertia: bytes) -> np.ndarray:
    """``I_v^-1 I`` (3, 3) of two inertia matrices given as their float64 bytes (kept: a fit
    evaluates many models with the same inertia); read-only."""
    out = np.linalg.solve(np.frombuffer(vehicle_inertia).reshape(3, 3),
                          np.frombuffer(nominal_inertia).reshape(3, 3))
    out.flags.writeable = False
    return out


#: the noise scale of a channel is at least this fraction of its operating point (weight,
#: weight x arm, hover speed): on noiseless (simulated) logs "noise" would otherwise be
#: round-off and any integration difference would count as a gap.
NOISE_FLOOR = 1e-3


def noise_floor(params: VehicleParams, rotor_channel: bool) -> np.ndarray:
    """Smallest noise scale per channel (see :data:`NOISE_FLOOR`)."""
    hover = np.sqrt(params.weight / (params.rotor_count * params.thrust_factor))
    floors = [params.weight] * 3 + [params.weight * arm_length(params)] * 3
    if rotor_channel:
        floors += [hover] * params.rotor_count
    return NOISE_FLOOR * np.asarray(floors)


def noise_scale(residual: np.ndarray, dt: float, window_s: float = 0.5,
                floor: np.ndarray | None = None) -> np.ndarray:
    """Per-channel noise scale: robust spread of the residual after removing its slow part
    (moving average over ``window_s``), so that a slowly acting effect does not inflate it;
    at least ``floor`` (:func:`noise_floor`)."""
    n = max(3, int(round(window_s / dt)) | 1)
    kernel = np.ones(n) / n
    slow = np.stack([np.convolve(c, kernel, mode="same") for c in residual.T], -1)
    fast = residual - slow
    mad = np.median(np.abs(fast - np.median(fast, axis=0)), axis=0) * 1.4826
    tiny = 1e-9 * (np.abs(residual).max(axis=0) + 1e-12)
    return np.maximum(mad, tiny if floor is None else np.maximum(tiny, floor))


def correlation_time(e: np.ndarray, max_lag: int = 200) -> float:
    """Integrated autocorrelation time (samples) of the scaled residual, for CI widening."""
    x = e - e.mean(axis=0)
    var = np.sum(x * x)
    if var <= 0:
        return 1.0
    tau = 1.0
    for lag in range(1, min(max_lag, len(x) - 1)):
        rho = np.sum(x[lag:] * x[:-lag]) / var
        if rho < 0.05:
            break
        tau += 2 * rho
    return float(tau)


def drag_refit_iv(states: FlightStates, params: VehicleParams, candidate: Candidate,
                  theta: np.ndarray, k: int) -> tuple[float, float]:
    """Relative change of the drag-torque factor d (``nominal_refit.drag``) by instrumental
    variables, and its standard error.

    The yaw torque is linear in d: Mz = (1 + delta) x + o, with x = d sum_i s_i Omega_i^2 (N m,
    s_i the rotor's spin sign) and o the rest of the model's yaw torque. Least squares on
    *measured* rotor speeds is an errors-in-variables regression: noise e on Omega_i enters x
    as d sum_i 2 s_i Omega_i e_i, and the slope is attenuated by var(x) / (var(x) + var(e_x))
    (regression dilution). Near hover with little yaw the true x hardly varies, so the
    attenuation is almost total and the least-squares refit goes to delta = -1 (measured:
    Crazyflie hover flown closed loop by ``quadsim.fly`` with rotor-speed noise 0.5 % of hover
    gave -0.9 at the bound, docs/gap.md). The instrument z is the same regressor computed from
    the *commanded* speeds (the motor map of the commands): correlated with the true speeds,
    not with their measurement noise, so
    ``1 + delta = sum z (Mz_meas - o) / sum z x`` is consistent (Wald/IV estimator; motor lag
    between command and speed does not bias it, it only weakens the instrument).
    Standard error: ``s_u sqrt(sum z^2) / |sum z x|`` (s_u the RMS of Mz_meas - o - (1+delta) x),
    widened by the residual's correlation time. A weak instrument (no yaw commanded) gives a
    wide interval, so d is then reported as not identified instead of a confident -90 %.
    Returns (nan, nan) when the rotor speeds or commands are missing."""
    if states.command is None or states.rotor_speed is None:
        return float("nan"), float("nan")
    effects = candidate.effects(theta)
    plus = theta.copy()
    plus[k] += 1.0
    effects_plus = candidate.effects(plus)
    _, torque, vehicle = model_wrench(states, params, effects)
    _, torque_plus, _ = model_wrench(states, params, effects_plus)
    cmd = command_speed(states, params)
    _, zt, _ = model_wrench(states, params, effects, rotor_speed=cmd)
    _, zt_plus, _ = model_wrench(states, params, effects_plus, rotor_speed=cmd)
    x = torque_plus[:, 2] - torque[:, 2]          # d sum s_i Omega_i^2 (N m per unit delta)
    z = zt_plus[:, 2] - zt[:, 2]                  # the same from the commanded speeds
    _, measured = measured_wrench(states, vehicle)
    y = measured[:, 2] - (torque[:, 2] - (1.0 + theta[k]) * x)   # Mz_meas - o
    zx = float(z @ x)
    if not np.isfinite(zx) or abs(zx) <= 0.0:
        return float("nan"), float("nan")
    gain = float(z @ y) / zx
    u = y - gain * x
    tau = correlation_time(u[:, None])
    se = float(np.sqrt(np.mean(u * u) * float(z @ z) * tau) / abs(zx))
    return gain - 1.0, se


def flagged(candidate: Candidate, flag: str) -> list[int]:
    """Indices of ``candidate``'s fitted parameters that their effect lists in its facts'
    ``flag`` (:class:`quadsim.effects.facts.EffectFacts`: ``rotor_time_constants``,
    ``starts_at_logged_voltage``, ``instrumented``)."""
    out, k = [], 0
    for name, _, fitted in candidate.parts:
        listed = getattr(facts_for(name), flag)
        out += [k + i for i, p in enumerate(fitted) if p in listed]
        k += len(fitted)
    return out


#: the candidate fit's relative finite-difference step (scipy's ``diff_step``), in units of
#: each parameter's typical size (:func:`fit_candidate`)
FIT_STEP = 1e-4


@dataclass
class _Walled:
    """:func:`fit_candidate`'s residual in units of each parameter's typical size:
    ``stacked(z)`` the residual over sigma (flattened) of ``candidate`` at ``x0 + z
    typical`` on ``states``; 1e3 per entry where the values make no vehicle (ModelError,
    e.g. an inertia breaking the triangle inequality: a wall, not a crash), counted in
    ``walls``; ``z_lo``, ``z_hi``: the bounds in z. The fields
    :func:`quadsim.gap.evidence.wall_jacobian` reads."""

    candidate: Candidate
    states: FlightStates
    params: VehicleParams
    sigma: np.ndarray
    _: dataclasses.KW_ONLY
    rotor_channel: bool
    x0: np.ndarray
    typical: np.ndarray
    z_lo: np.ndarray
    z_hi: np.ndarray
    walls: int = 0
    #: the residual parts one parameter does not move (:func:`residuals`)
    memo: dict = field(default_factory=dict)

    def stacked(self, z: np.ndarray) -> np.ndarray:
        """The residual over sigma at ``z`` (class doc)."""
        try:
            effects = self.candidate.effects(self.x0 + z * self.typical)
            return (residuals(self.states, self.params, effects,
                              rotor_channel=self.rotor_channel, memo=self.memo)
                    / self.sigma).ravel()
        except ModelError:
            self.walls += 1
            return np.full(len(self.states.t) * len(self.sigma), 1e3)


def fit_candidate(candidate: Candidate, flights: list[FlightStates], params: VehicleParams,
                  sigma: np.ndarray, *, rotor_channel: bool, start: np.ndarray | None = None,
                  max_nfev: int = 60, compact: bool = False) -> Fit:
    """Bounded least squares of ``candidate`` on ``flights`` (already decimated).
    ``compact``: solved through the residual's R factor (:func:`quadsim.gap.lsq.
    compact_least_squares`: scipy's iterates up to rounding, each SVD on P+1 rows)."""
    typical = typical_scales(candidate, params)
    lower, upper = parameter_bounds(candidate, params)
    # a rotor time constant is at least one sub-step of the rotor channel (min_time_constant)
    step = min_time_constant(float(flights[0].t[1] - flights[0].t[0])) \
        if len(flights[0].t) > 1 else 0.0
    for k in flagged(candidate, "rotor_time_constants"):
        lower[k] = max(lower[k], step)
    x0 = _start(candidate, lower, upper, typical) if start is None else np.clip(
        start, lower + 1e-12 * typical, upper - 1e-12 * typical)
    for k in flagged(candidate, "starts_at_logged_voltage") if start is None else ():
        # Start where the sag is neutral on average: the full voltage at the highest logged.
        x0[k] = np.clip(max(float(np.nanmax(s.vbat)) for s in flights), lower[k], upper[k])

    walled = _Walled(candidate, stack_states(flights), params, sigma,
                     rotor_channel=rotor_channel, x0=x0, typical=typical,
                     z_lo=(lower - x0) / typical, z_hi=(upper - x0) / typical)
    fun, z_lower, z_upper = walled.stacked, walled.z_lo, walled.z_hi
    if compact:
        from .lsq import compact_least_squares

        result = compact_least_squares(fun, np.zeros_like(x0), bounds=(z_lower, z_upper),
                                       diff_step=FIT_STEP, max_nfev=max_nfev)
    else:
        result = least_squares(fun, np.zeros_like(x0), bounds=(z_lower, z_upper),
                               diff_step=FIT_STEP, max_nfev=max_nfev, method="trf", x_scale=1.0)
    theta = x0 + result.x * typical
    jac, res = result.jac / typical, result.fun
    if walled.walls:
        # the fit met a wall of values that make no vehicle: the solver's last Jacobian
        # may hold a difference across it, a column ~1e3 / step whose direction the
        # pseudo-inverse keeps alone (every other spread 0); taken again without one
        from .lsq import wall_jacobian

        _, again, _ = wall_jacobian(walled, result.x, FIT_STEP, prior=False)
        if again is not None:
            jac = again / typical
    stacked = walled.states
    dof = max(1, res.size - len(x0))
    s2 = float(res @ res) / dof
    inflation = correlation_time(res.reshape(-1, len(sigma)))
    cov = np.linalg.pinv(jac.T @ jac) * s2 * inflation
    stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
    for k in flagged(candidate, "instrumented") if stacked.command is not None else ():
        value, se = drag_refit_iv(stacked, params, candidate, theta, k)
        if np.isfinite(value) and np.isfinite(se):
            theta[k] = float(np.clip(value, lower[k], upper[k]))
            cov[k, :] = cov[:, k] = 0.0
            cov[k, k] = se ** 2
            stderr[k] = se
    denom = np.outer(stderr, stderr)
    corr = np.divide(cov, denom, out=np.zeros_like(cov), where=denom > 0)
    column = np.linalg.norm(jac, axis=0) * typical
    # A parameter is identified when the data move the residual and its CI is narrower
    # than half the plausible range.
    span = upper - lower
    # Never identified: a value at a bound (the optimum lies beyond it, its CI means
    # nothing) or an absurdly narrow interval (a flat or degenerate Jacobian direction, e.g.
    # "wind.vy = 29.99 +- 4e-21 m/s").
    at_bound = (theta - lower <= AT_BOUND * typical) | (upper - theta <= AT_BOUND * typical)
    absurd = stderr < ABSURD_CI * typical
    identifiable = [bool(c > 1e-6 * np.sqrt(res.size) and 1.96 * se < 0.5 * sp
                         and not b and not a)
                    for c, se, sp, b, a in zip(column, stderr, span, at_bound, absurd)]
    off = start_off(candidate)
    significant = [bool(abs(th - o) > 1.96 * se) or name in NO_OFF_VALUE
                   for th, o, se, name in zip(theta, off, stderr, candidate.parameter_names)]
    return Fit(candidate, theta, stderr, corr, float(result.cost), identifiable, significant)


#: the nominal refit's candidate (:class:`quadsim.gap.fitting.NominalRefit`): the
#: parameter set's b and d re-identified; a shared group of the reference model
#: (:mod:`.calibrate`) and the held-out reading "b and d are off"
BASELINE = Candidate("nominal_refit", (("nominal_refit", {}, ("thrust", "drag")),))


def plane_step(r: np.ndarray, qb: np.ndarray, c: np.ndarray, h: float, *,
               bounds: tuple) -> np.ndarray | None:
    """The minimum of the quadratic ``|qb + r x|^2`` on the plane ``c . x = h``: the linear
    model's step held on one linear wall (:func:`quadsim.gap.evidence.linear_step`, the
    inertia's triangle inequality).

    ``r`` (P, P): the upper-triangular factor of the linear model's stacked Jacobian
    (``rᵀr`` its Gauss-Newton precision, positive definite: it holds the prior's identity
    rows); ``qb`` (P,): Qᵀ of its residual; ``c`` (P,), ``h``: the plane. Closed form with one
    active equality (Lagrange): with x_u = -r^-1 qb the unconstrained minimum, y = r^-ᵀ c,

        x = x_u - r^-1 y (c . x_u - h) / |y|^2

    Returned only where it lies inside the box ``bounds`` (lower, upper; each (P,)); None
    where it does not (a box value and the wall active together: no closed form, the
    caller keeps its step) or ``c`` is zero."""
    from scipy.linalg import solve_triangular

    lower, upper = bounds
    if not np.any(c):
        return None
    xu = -solve_triangular(r, qb)
    y = solve_triangular(r, c, trans="T")
    x = xu - solve_triangular(r, y) * (float(c @ xu) - h) / float(y @ y)
    return x if np.all((x >= lower) & (x <= upper)) else None
