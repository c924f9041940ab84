"""The numba kernel of :mod:`quadsim.sim.compiled` (imported only when numba is installed).

:func:`run` (``run(functions, addr, commands, omega, k0, substeps, dt, period, rotor_arm,
rotor_axis, rotor_spin, rotor_position, rows, extra, lag, active, out, status)``) calls
MuJoCo's C functions by address (no ctypes objects inside, so numba can cache it on disk); the
formulas are those of :mod:`quadsim.sim.mujoco_engine` (``_effect_step``,
``_effect_state_step``) and of each effect's module, written per simulation and per rotor;
``extra`` (B, 6) carries cable_payload's payload position and velocity (world) between calls.
:func:`analytic_rhs` is the analytic engine's right-hand side with the same load functions.
No allocation inside the time-step loop (scratch arrays are made once per call). Units SI.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from ..analytic import STATE_BOUND
from .layout import OFFSET as offset

MIN_SCALE = 0.5          # quadsim.effects.battery_sag.MIN_SCALE
MAX_TERM = 0.5           # quadsim.effects.ground_effect.MAX_TERM


@intrinsic
def _as_pointer(typingctx, address):
    signature = types.CPointer(types.float64)(types.int64)

    def codegen(context, builder, sig, args):
        return builder.inttoptr(args[0], context.get_value_type(types.CPointer(types.float64)))

    return signature, codegen


@intrinsic
def _call(typingctx, function, model, data, state, spec):
    """Call a C function ``void f(void*, void*[, void*, int])`` at address ``function``
    (int64; ``state``/``spec`` ignored when both are 0 for the two-argument form)."""
    signature = types.void(types.int64, types.int64, types.int64, types.int64, types.int64)

    def codegen(context, builder, sig, args):
        pointer = ir.IntType(8).as_pointer()
        kind = ir.FunctionType(ir.VoidType(), [pointer, pointer, pointer, ir.IntType(32)])
        target = builder.inttoptr(args[0], kind.as_pointer())
        builder.call(target, [builder.inttoptr(args[1], pointer),
                              builder.inttoptr(args[2], pointer),
                              builder.inttoptr(args[3], pointer),
                              builder.trunc(args[4], ir.IntType(32))])
        return context.get_dummy_value()

    return signature, codegen


O_UP, O_DOWN, O_MIS = offset["tau_up"], offset["tau_down"], offset["mismatch"]
O_BAT, O_GG, O_GH = offset["battery_rate"], offset["ground_gain"], offset["ground_height"]
O_SG, O_RSG = offset["speed_gain"], offset["rotor_speed_gain"]
O_GR, O_CL, O_CO = offset["ground_radius"], offset["curve_linear"], offset["curve_offset"]
O_RD, O_RA, O_BD = offset["rotor_drag"], offset["rotor_drag_axial"], offset["body_drag"]
O_BA, O_CQ = offset["body_drag_axes"], offset["curve_quadratic"]
O_RHO, O_JR, O_WM = offset["air_density"], offset["rotor_inertia"], offset["wind_mean"]
O_GA, O_GF, O_GP = offset["gust_amplitude"], offset["gust_frequency"], offset["gust_phase"]
GUST = offset["gust_phase"] - offset["gust_frequency"]
O_TG, O_RDX = offset["thrust_gain"], offset["rate_damping"]
O_BF = offset["blade_flapping"]
O_TL = offset["translational_lift"]
O_PM, O_PL, O_PA = offset["payload_mass"], offset["payload_length"], offset["payload_attach"]
O_PC, O_PK, O_PD = offset["payload_arm"], offset["payload_stiffness"], offset["payload_damping"]
O_G, O_COM = offset["gravity"], offset["com"]
BOUND = STATE_BOUND
TWO_PI = 2.0 * np.pi


@numba.njit(inline="always", cache=True)
def speed_factor(bat, gain, t):
    """The speed factors' product: battery_sag's sqrt(max(MIN_SCALE, 1 - rate t)) (1 when
    off) times a constant ``gain`` (thrust_factor's (1 + change)^-alpha; 1 when off)."""
    return gain * (np.sqrt(max(MIN_SCALE, 1.0 - bat * t)) if bat != 0.0 else 1.0)


@numba.njit(inline="always", cache=True)
def rate(c, w, up, down, f):
    """dOmega/dt of quadsim.effects.base.EffectSet.rotor_speed_rate: the command scaled by
    the battery's speed factor f (battery_sag; 1 without it), then the first-order lag
    (motor_lag, or SPEED_RESPONSE_S when only the battery acts)."""
    c = c * f
    return (c - w) / (up if c >= w else down)


@numba.njit(inline="always", cache=True)
def rk4(c, w0, h, up, down, f0, f1, f2):
    """One RK4 step of h; f0, f1, f2 the speed factors at its start, middle and end."""
    k1 = rate(c, w0, up, down, f0)
    k2 = rate(c, w0 + h / 2 * k1, up, down, f1)
    k3 = rate(c, w0 + h / 2 * k2, up, down, f1)
    k4 = rate(c, w0 + h * k3, up, down, f2)
    return w0 + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


@numba.njit(inline="always", cache=True)
def predict(qpos, qvel, qacc, h, normalize, pos, vel, rate_b, rot):
    """Body state h ahead predicted from (qpos, qvel, qacc) (mujoco_engine._midpoint_state);
    the quaternion is normalised when ``normalize`` (the analytic right-hand side uses its
    state as is, like quadsim.sim.analytic)."""
    for i in range(3):
        pos[i] = qpos[i] + qvel[i] * h + 0.5 * qacc[i] * h * h
        vel[i] = qvel[i] + qacc[i] * h
        rate_b[i] = qvel[3 + i] + qacc[3 + i] * h
    w0 = qvel[3] + qacc[3] * h / 2
    w1 = qvel[4] + qacc[4] * h / 2
    w2 = qvel[5] + qacc[5] * h / 2
    q0, q1, q2, q3 = qpos[3], qpos[4], qpos[5], qpos[6]
    d0 = 0.5 * (-q1 * w0 - q2 * w1 - q3 * w2)
    d1 = 0.5 * (q0 * w0 + q2 * w2 - q3 * w1)
    d2 = 0.5 * (q0 * w1 - q1 * w2 + q3 * w0)
    d3 = 0.5 * (q0 * w2 + q1 * w1 - q2 * w0)
    q0, q1, q2, q3 = q0 + d0 * h, q1 + d1 * h, q2 + d2 * h, q3 + d3 * h
    n = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3) if normalize else 1.0
    w, x, y, z = q0 / n, q1 / n, q2 / n, q3 / n
    rot[0, 0], rot[0, 1], rot[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), \
        2 * (x * z + w * y)
    rot[1, 0], rot[1, 1], rot[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), \
        2 * (y * z - w * x)
    rot[2, 0], rot[2, 1], rot[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), \
        1 - 2 * (x * x + y * y)


@numba.njit(inline="always", cache=True)
def tension(row, pos, vel, rate_b, rot, st, pull):
    """Cable pull T u on the vehicle (world, N) into ``pull`` (quadsim.effects.cable_payload):
    payload state st = (p, v) world, attachment r_a body frame."""
    ax, ay, az = row[O_PA], row[O_PA + 1], row[O_PA + 2]
    cx = rate_b[1] * az - rate_b[2] * ay
    cy = rate_b[2] * ax - rate_b[0] * az
    cz = rate_b[0] * ay - rate_b[1] * ax
    d0 = st[0] - (pos[0] + (rot[0, 0] * ax + rot[0, 1] * ay + rot[0, 2] * az))
    d1 = st[1] - (pos[1] + (rot[1, 0] * ax + rot[1, 1] * ay + rot[1, 2] * az))
    d2 = st[2] - (pos[2] + (rot[2, 0] * ax + rot[2, 1] * ay + rot[2, 2] * az))
    r0 = st[3] - (vel[0] + (rot[0, 0] * cx + rot[0, 1] * cy + rot[0, 2] * cz))
    r1 = st[4] - (vel[1] + (rot[1, 0] * cx + rot[1, 1] * cy + rot[1, 2] * cz))
    r2 = st[5] - (vel[2] + (rot[2, 0] * cx + rot[2, 1] * cy + rot[2, 2] * cz))
    length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    u0, u1, u2 = d0 / length, d1 / length, d2 / length
    stretch = u0 * r0 + u1 * r1 + u2 * r2
    t = max(0.0, row[O_PK] * (length - row[O_PL]) + row[O_PD] * stretch)
    pull[0], pull[1], pull[2] = t * u0, t * u1, t * u2


@numba.njit(inline="always", cache=True)
def payload_rate(row, pos, vel, rate_b, rot, st, pull, out):
    """d/dt of the payload state (6,) into ``out``."""
    tension(row, pos, vel, rate_b, rot, st, pull)
    for i in range(3):
        out[i] = st[3 + i]
        out[3 + i] = -pull[i] / row[O_PM]
    out[5] -= row[O_G]


@numba.njit(cache=True)
def loads(b, t, dt, qpos, qvel, qacc, mid, acc, rows, arm, axis, spin, hub, st, wrench, scale,
          rot, normalize, work):
    """Effect loads of simulation b at the mid-step state predicted from (qpos, qvel, qacc)
    over dt / 2 (dt = 0: at that state): body-frame force and torque about the CoM and the
    world-frame force at the CoM into ``wrench`` (9,), per-rotor thrust scale into ``scale``,
    the rotation matrix into ``rot``; ``st`` the payload state (cable_payload) at that time;
    ``work`` (11, 3) scratch (no allocation per step)."""
    rotors = mid.shape[0]
    h = dt / 2
    pos, vel, rate_b, air, air_body = work[0], work[1], work[2], work[3], work[4]
    force_body, torque, momentum, spin_up = work[5], work[6], work[7], work[8]
    f, pull = work[9], work[10]
    for i in range(3):
        air_body[i] = force_body[i] = torque[i] = momentum[i] = spin_up[i] = 0.0
    predict(qpos, qvel, qacc, h, normalize, pos, vel, rate_b, rot)
    tm = t + dt / 2
    row = rows[b]
    for j in range(3):
        wind = row[O_WM + j]
        if row[O_GA] > 0.0:
            total = 0.0
            for g in range(GUST):
                total += np.cos(TWO_PI * row[O_GF + g] * tm + row[O_GP + j * GUST + g])
            wind += row[O_GA] * total
        air[j] = vel[j] - wind
    for i in range(3):
        for j in range(3):
            air_body[i] += rot[j, i] * air[j]
    # force_body: body frame, rotor drag + body drag + thrust offsets; torque: about the CoM
    c, ca = row[O_RD], row[O_RA]
    for r in range(rotors):
        a = axis[b, r]
        s = row[O_MIS + r] * row[O_TG]
        gain = row[O_GG]
        if gain != 0.0:
            hub_z = pos[2] + rot[2, 0] * hub[b, r, 0] + rot[2, 1] * hub[b, r, 1] \
                + rot[2, 2] * hub[b, r, 2]
            height = max(hub_z - row[O_GH], 1e-9)
            term = min(gain * (row[O_GR] / (4.0 * height)) ** 2, MAX_TERM)
            s *= 1.0 / (1.0 - term)
        scale[r] = s
        # rotor drag at the hub's air velocity u = v + w x (r_i - c) (effects.rotor_drag)
        p = arm[b, r]
        u0 = air_body[0] + rate_b[1] * p[2] - rate_b[2] * p[1]
        u1 = air_body[1] + rate_b[2] * p[0] - rate_b[0] * p[2]
        u2 = air_body[2] + rate_b[0] * p[1] - rate_b[1] * p[0]
        axial = u0 * a[0] + u1 * a[1] + u2 * a[2]
        # scales with the propeller
        extra = s * ((row[O_CQ] * mid[r] + row[O_CL]) * mid[r] + row[O_CO])
        # translational_lift: + k_h |v - (v . a) a|^2 along the axis (air velocity, no rotation)
        va = air_body[0] * a[0] + air_body[1] * a[1] + air_body[2] * a[2]
        extra += row[O_TL] * (air_body[0] ** 2 + air_body[1] ** 2 + air_body[2] ** 2 - va * va)
        for i in range(3):
            along = axial * a[i]
            u = u0 if i == 0 else (u1 if i == 1 else u2)
            f[i] = -mid[r] * (c * (u - along) + ca * along) + extra * a[i]
            force_body[i] += f[i]
            momentum[i] += spin[r] * mid[r] * a[i]
            spin_up[i] += spin[r] * acc[r] * a[i]
        # blade_flapping: -diag(k) Omega (a x v_perp) = -diag(k) Omega (a x v), k per body axis
        torque[0] -= row[O_BF] * mid[r] * (a[1] * air_body[2] - a[2] * air_body[1])
        torque[1] -= row[O_BF + 1] * mid[r] * (a[2] * air_body[0] - a[0] * air_body[2])
        torque[2] -= row[O_BF + 2] * mid[r] * (a[0] * air_body[1] - a[1] * air_body[0])
        torque[0] += p[1] * f[2] - p[2] * f[1]
        torque[1] += p[2] * f[0] - p[0] * f[2]
        torque[2] += p[0] * f[1] - p[1] * f[0]
    speed = np.sqrt(air_body[0] ** 2 + air_body[1] ** 2 + air_body[2] ** 2)
    per_axis = row[O_BA] >= 0.5          # body_drag.per_axis: |v_i| v_i on each body axis
    for i in range(3):
        own = abs(air_body[i]) if per_axis else speed
        force_body[i] += -0.5 * row[O_RHO] * own * row[O_BD + i] * air_body[i]
    jr = row[O_JR]
    if jr != 0.0:
        torque[0] += -jr * (rate_b[1] * momentum[2] - rate_b[2] * momentum[1] + spin_up[0])
        torque[1] += -jr * (rate_b[2] * momentum[0] - rate_b[0] * momentum[2] + spin_up[1])
        torque[2] += -jr * (rate_b[0] * momentum[1] - rate_b[1] * momentum[0] + spin_up[2])
    for i in range(3):
        torque[i] -= row[O_RDX + i] * rate_b[i]
        wrench[i] = force_body[i]
        wrench[3 + i] = torque[i]
        wrench[6 + i] = 0.0
    if row[O_PM] > 0.0:
        tension(row, pos, vel, rate_b, rot, st, pull)
        ax, ay, az = row[O_PC], row[O_PC + 1], row[O_PC + 2]
        f0 = rot[0, 0] * pull[0] + rot[1, 0] * pull[1] + rot[2, 0] * pull[2]
        f1 = rot[0, 1] * pull[0] + rot[1, 1] * pull[1] + rot[2, 1] * pull[2]
        f2 = rot[0, 2] * pull[0] + rot[1, 2] * pull[1] + rot[2, 2] * pull[2]
        wrench[3] += ay * f2 - az * f1
        wrench[4] += az * f0 - ax * f2
        wrench[5] += ax * f1 - ay * f0
        for i in range(3):
            wrench[6 + i] = pull[i]


@numba.njit(inline="always", cache=True)
def joint_load(wrench, rot, com, qfrc):
    """The free joint's generalised force of the effect wrench (mujoco_engine.joint_load):
    world force F = R f_body + f_world; body-frame torque about the body origin
    tau_body + com x R^T F."""
    fb0 = wrench[0] + rot[0, 0] * wrench[6] + rot[1, 0] * wrench[7] + rot[2, 0] * wrench[8]
    fb1 = wrench[1] + rot[0, 1] * wrench[6] + rot[1, 1] * wrench[7] + rot[2, 1] * wrench[8]
    fb2 = wrench[2] + rot[0, 2] * wrench[6] + rot[1, 2] * wrench[7] + rot[2, 2] * wrench[8]
    for i in range(3):
        qfrc[i] = rot[i, 0] * wrench[0] + rot[i, 1] * wrench[1] + rot[i, 2] * wrench[2] \
            + wrench[6 + i]
    qfrc[3] = wrench[3] + com[1] * fb2 - com[2] * fb1
    qfrc[4] = wrench[4] + com[2] * fb0 - com[0] * fb2
    qfrc[5] = wrench[5] + com[0] * fb1 - com[1] * fb0


@numba.njit(inline="always", cache=True)
def payload_step(b, qpos, qvel, qacc, dt, row, st, half, scratch, rot):
    """The payload state over one timestep (mujoco_engine._effect_state_step): two RK4 half
    steps along the body state predicted from the last accelerations; ``st`` (6,) is
    advanced to the end of the step, its mid-step value written to ``half``."""
    pos, vel, rate_b, pull = scratch[0, 0:3], scratch[0, 3:6], scratch[0, 6:9], scratch[0, 9:12]
    y0, y, k1, k2, k3, k4 = scratch[1], scratch[2], scratch[3], scratch[4], scratch[5], \
        scratch[6]
    hh = dt / 2
    for part in range(2):
        t0 = 0.0 if part == 0 else dt / 2
        for i in range(6):
            y0[i] = st[i]
        predict(qpos, qvel, qacc, t0, True, pos, vel, rate_b, rot)
        payload_rate(row, pos, vel, rate_b, rot, y0, pull, k1)
        for i in range(6):
            y[i] = y0[i] + hh / 2 * k1[i]
        predict(qpos, qvel, qacc, t0 + hh / 2, True, pos, vel, rate_b, rot)
        payload_rate(row, pos, vel, rate_b, rot, y, pull, k2)
        for i in range(6):
            y[i] = y0[i] + hh / 2 * k2[i]
        payload_rate(row, pos, vel, rate_b, rot, y, pull, k3)
        for i in range(6):
            y[i] = y0[i] + hh * k3[i]
        predict(qpos, qvel, qacc, t0 + hh, True, pos, vel, rate_b, rot)
        payload_rate(row, pos, vel, rate_b, rot, y, pull, k4)
        for i in range(6):
            st[i] = y0[i] + hh / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i])
            if part == 0:
                half[i] = st[i]


@numba.njit(cache=True)
def run_one(b, functions, addr, commands, omega, k0, substeps, dt, period, arm, axis, spin, hub,
            rows, extra, lag, active, out, status):
    """Simulation b of :func:`run`."""
    periods, rotors = commands.shape[1], commands.shape[2]
    if status[b] != 0:
        return
    qpos = numba.carray(_as_pointer(addr[b, 2]), 7)
    qvel = numba.carray(_as_pointer(addr[b, 3]), 6)
    qacc = numba.carray(_as_pointer(addr[b, 4]), 6)
    ctrl = numba.carray(_as_pointer(addr[b, 5]), rotors)
    qfrc = numba.carray(_as_pointer(addr[b, 6]), 6)     # the free joint's qfrc_applied
    mid = np.empty(rotors)
    end = np.empty(rotors)
    msq = np.empty(rotors)
    acc = np.zeros(rotors)
    scale = np.ones(rotors)
    clock = np.empty(1)
    wrench = np.empty(9)
    rot = np.empty((3, 3))
    half = np.zeros(6)
    scratch = np.empty((7, 12))
    work = np.empty((11, 3))
    st = extra[b]
    row = rows[b]
    up, down, bat, sg = row[O_UP], row[O_DOWN], row[O_BAT], row[O_SG]
    carried = row[O_PM] > 0.0
    hh = dt / 2
    fa = fb = fc = fd = fe = 1.0
    for k in range(periods):
        cmd = commands[b, k]
        for j in range(substeps):
            t = (k0 + k) * period + j * dt
            if lag:     # speed factors at the stage times of the two RK4 half steps
                fa, fb, fc = speed_factor(bat, sg, t), speed_factor(bat, sg, t + hh / 2), \
                    speed_factor(bat, sg, t + hh)
                fd, fe = (speed_factor(bat, sg, (t + hh) + hh / 2),
                          speed_factor(bat, sg, (t + hh) + hh))
            for r in range(rotors):
                if lag:
                    w0 = omega[b, r]
                    g = row[O_RSG + r]       # this rotor's own speed factor (1: none)
                    m_ = rk4(cmd[r], w0, hh, up, down, fa * g, fb * g, fc * g)
                    e_ = rk4(cmd[r], m_, hh, up, down, fc * g, fd * g, fe * g)
                    mid[r], end[r] = m_, e_
                    msq[r] = (w0 * w0 + 4 * m_ * m_ + e_ * e_) / 6
                    acc[r] = rate(cmd[r], m_, up, down, fc * g)
                else:
                    mid[r] = end[r] = cmd[r]
                    msq[r] = cmd[r] * cmd[r]
            if carried:
                payload_step(b, qpos, qvel, qacc, dt, row, st, half, scratch, rot)
            if active:
                loads(b, t, dt, qpos, qvel, qacc, mid, acc, rows, arm, axis, spin,
                      hub, half, wrench, scale, rot, True, work)
                joint_load(wrench, rot, row[O_COM:O_COM + 3], qfrc)
            for r in range(rotors):
                ctrl[r] = scale[r] * msq[r]
                omega[b, r] = end[r]
            _call(functions[0], addr[b, 0], addr[b, 1], 0, 0)
        _call(functions[1], addr[b, 0], addr[b, 1], clock.ctypes.data, 1)
        bad = abs(clock[0] - (k0 + k + 1) * period) > 1e-6
        for i in range(7):
            if not np.isfinite(qpos[i]) or (i < 3 and abs(qpos[i]) > BOUND):
                bad = True
        for i in range(6):
            if not np.isfinite(qvel[i]) or abs(qvel[i]) > BOUND:
                bad = True
        if bad:
            status[b] = k0 + k + 1
            out[b, k:] = np.nan
            break
        out[b, k, 0:3] = qpos[0:3]
        out[b, k, 3:6] = qvel[0:3]
        out[b, k, 6:10] = qpos[3:7]
        out[b, k, 10:13] = qvel[3:6]
        out[b, k, 13:] = omega[b]


@numba.njit(cache=True, nogil=True)
def run(functions, addr, commands, omega, k0, substeps, dt, period, arm, axis, spin,
        hub, rows, extra, lag, active, out, status):
    """functions: addresses of mj_step and mj_getState; runs without the GIL, so the caller
    may run chunks of a batch in threads (numba's prange compiled several times slower)."""
    for b in range(commands.shape[0]):
        run_one(b, functions, addr, commands, omega, k0, substeps, dt, period, arm, axis, spin,
                hub, rows, extra, lag, active, out, status)


@numba.njit(cache=True)
def analytic_rhs(t, y, command, lag, active, size, rows, arm, axis, spin, hub, allocation, mass,
                 com, inertia, inertia_inv, gravity, thrust_factor, drag_factor, out):
    """d/dt of the flat batched analytic state (quadsim.sim.analytic.state_derivative) into
    ``out``, with every effect evaluated in the kernel: Newton-Euler at the CoM, returned at
    the body origin; thrust scale s and offset o per rotor as in quadsim.sim.analytic."""
    batch, rotors = command.shape
    base = 13 + rotors if lag else 13
    width = base + size
    omega = np.empty(rotors)
    accel_r = np.zeros(rotors)
    wrench = np.zeros(9)
    pos = np.empty(3)
    vel = np.empty(3)
    pull = np.empty(3)
    scale = np.ones(rotors)
    rot = np.empty((3, 3))
    zeros = np.zeros(6)
    work = np.empty((11, 3))
    for b in range(batch):
        s = y[b * width:(b + 1) * width]
        d = out[b * width:(b + 1) * width]
        up, down, bat, sg = rows[b, O_UP], rows[b, O_DOWN], rows[b, O_BAT], rows[b, O_SG]
        for i in range(size):
            d[base + i] = 0.0
        for r in range(rotors):
            if lag:
                omega[r] = s[13 + r]
                accel_r[r] = rate(command[b, r], omega[r], up, down,
                                  speed_factor(bat, sg, t) * rows[b, O_RSG + r])
                d[13 + r] = accel_r[r]
            else:
                omega[r] = command[b, r]
        qpos = np.empty(7)
        qvel = np.empty(6)
        qpos[0:3] = s[0:3]
        qpos[3:7] = s[6:10]
        qvel[0:3] = s[3:6]
        qvel[3:6] = s[10:13]
        w0, w1, w2, w3 = s[6], s[7], s[8], s[9]
        x_, y_, z_ = w1, w2, w3
        rot[0, 0], rot[0, 1], rot[0, 2] = 1 - 2 * (y_ * y_ + z_ * z_), 2 * (x_ * y_ - w0 * z_), \
            2 * (x_ * z_ + w0 * y_)
        rot[1, 0], rot[1, 1], rot[1, 2] = 2 * (x_ * y_ + w0 * z_), 1 - 2 * (x_ * x_ + z_ * z_), \
            2 * (y_ * z_ - w0 * x_)
        rot[2, 0], rot[2, 1], rot[2, 2] = 2 * (x_ * z_ - w0 * y_), 2 * (y_ * z_ + w0 * x_), \
            1 - 2 * (x_ * x_ + y_ * y_)
        for i in range(9):
            wrench[i] = 0.0
        st = s[base:base + 6] if rows[b, O_PM] > 0.0 else zeros
        if active:
            loads(b, t, 0.0, qpos, qvel, zeros, omega, accel_r, rows, arm, axis,
                  spin, hub, st, wrench, scale, rot, False, work)
        if rows[b, O_PM] > 0.0:
            for i in range(3):
                pos[i] = s[i]
                vel[i] = s[3 + i]
            payload_rate(rows[b], pos, vel, s[10:13], rot, st, pull, d[base:base + 6])
        force = np.zeros(3)
        torque = np.zeros(3)
        for i in range(3):
            force[i] = wrench[i]
            torque[i] = wrench[3 + i]
        for r in range(rotors):
            sq = omega[r] * omega[r]
            for i in range(3):
                force[i] += allocation[b, i, r] * sq
                torque[i] += allocation[b, 3 + i, r] * sq
            if active:
                thrust = (scale[r] - 1.0) * thrust_factor[b] * sq
                drag = (scale[r] - 1.0) * drag_factor[b] * sq
                a = axis[b, r]
                p = arm[b, r]
                f0, f1, f2 = thrust * a[0], thrust * a[1], thrust * a[2]
                force[0] += f0
                force[1] += f1
                force[2] += f2
                torque[0] += p[1] * f2 - p[2] * f1 - drag * spin[r] * a[0]
                torque[1] += p[2] * f0 - p[0] * f2 - drag * spin[r] * a[1]
                torque[2] += p[0] * f1 - p[1] * f0 - drag * spin[r] * a[2]
        om = s[10:13]
        momentum = np.zeros(3)
        for i in range(3):
            for j in range(3):
                momentum[i] += inertia[b, i, j] * om[j]
        net = np.empty(3)
        net[0] = torque[0] - (om[1] * momentum[2] - om[2] * momentum[1])
        net[1] = torque[1] - (om[2] * momentum[0] - om[0] * momentum[2])
        net[2] = torque[2] - (om[0] * momentum[1] - om[1] * momentum[0])
        alpha = np.zeros(3)
        for i in range(3):
            for j in range(3):
                alpha[i] += inertia_inv[b, i, j] * net[j]
        c = com[b]
        wc = np.empty(3)
        wc[0] = om[1] * c[2] - om[2] * c[1]
        wc[1] = om[2] * c[0] - om[0] * c[2]
        wc[2] = om[0] * c[1] - om[1] * c[0]
        lever = np.empty(3)
        lever[0] = alpha[1] * c[2] - alpha[2] * c[1] + om[1] * wc[2] - om[2] * wc[1]
        lever[1] = alpha[2] * c[0] - alpha[0] * c[2] + om[2] * wc[0] - om[0] * wc[2]
        lever[2] = alpha[0] * c[1] - alpha[1] * c[0] + om[0] * wc[1] - om[1] * wc[0]
        for i in range(3):
            world = rot[i, 0] * force[0] + rot[i, 1] * force[1] + rot[i, 2] * force[2]
            world += wrench[6 + i]
            if i == 2:
                world -= gravity[b] * mass[b]
            d[i] = s[3 + i]
            d[3 + i] = world / mass[b] - (rot[i, 0] * lever[0] + rot[i, 1] * lever[1]
                                          + rot[i, 2] * lever[2])
            d[10 + i] = alpha[i]
        d[6] = 0.5 * (-w1 * om[0] - w2 * om[1] - w3 * om[2])
        d[7] = 0.5 * (w0 * om[0] + w2 * om[2] - w3 * om[1])
        d[8] = 0.5 * (w0 * om[1] - w1 * om[2] + w3 * om[0])
        d[9] = 0.5 * (w0 * om[2] + w1 * om[1] - w2 * om[0])
