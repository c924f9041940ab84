"""The per-flight evaluation's shortcuts against the slow paths they replace, on a generated
flight (docs/gap.md, Speed): the residual with its per-flight memo (rotations, the cable's
attachment acceleration, measured wrench, rotor channel) against the residual computed from
scratch; the calibration's Jacobian against forward differences without a memo; the rotor
drag summed through rotor-speed sums against the per-rotor forces; the gyroscopic torque
against its einsum form; the inertia check's diagonal path against an eigenvalue check; the
last residual an explanation keeps against a fresh evaluation. Tolerances: 1e-12 of each
quantity's scale (round-off: the shortcuts reorder sums at most)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import ModelError, QuadsimWarning
from quadsim.core.frames import euler_to_quat, rotate, rotate_inverse
from quadsim.effects import make_effect
from quadsim.effects.base import EffectContext
from quadsim.effects.gyroscopic import gyroscopic_torque
from quadsim.effects.rotor_drag import rotor_drag_forces
from quadsim.gap.calibrate import Reference, jacobian, shared_candidate, weighted_residual
from quadsim.gap.diagnose import prepare
from quadsim.gap.evidence import Problem, explanations_for
from quadsim.gap.fitting import CableSwing, effect_class, residuals, typical_scales
from quadsim.vehicle.params import inertia_problems, load_params

from _helpers import shared_effects


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def states(cf):
    log = synthetic_flight(cf, shared_effects(), duration=4.0, seed=90, speed=1.2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return prepare([log], cf)[0].fit


def _close(got, want, rel=1e-12):
    want = np.asarray(want, dtype=float)
    np.testing.assert_allclose(got, want, rtol=0, atol=rel * max(np.abs(want).max(), 1e-300))


def _models(cf):
    """Four models that move every memoised part: rotations and the cable's acceleration
    (shared), the vehicle (inertia, CoM), the rotor channel (lag), a canted rotor; the last
    differs from the first by the lag alone (the model wrench is reused)."""
    for k, (lag, inertia, tilt, mass) in enumerate([(0.008, 0.0, 0.0, 0.006),
                                                    (0.012, 0.2, 0.05, 0.004),
                                                    (0.008, -0.1, 0.0, 0.009),
                                                    (0.02, 0.0, 0.0, 0.006)]):
        k = k % 3
        yield [make_effect("motor_lag", time_constant=lag),
               make_effect("rotor_drag", coefficient=2e-7, axial_coefficient=1e-7),
               make_effect("inertia_error", xx=inertia, yy=inertia, zz=0.5 * inertia),
               make_effect("gyroscopic", rotor_inertia=5e-8),
               make_effect("wind", vx=0.3, vy=-0.2),
               make_effect("body_drag", cd_area=1e-3),
               make_effect("com_offset", x=0.001 * k),
               effect_class("canted_rotor")(rotor=2.0, tilt_x=tilt),
               CableSwing(mass=mass, length=0.45, lean_x=0.05, rate_y=0.2)]


def test_the_residual_with_its_flight_memo_is_the_residual_from_scratch(cf, states):
    memo: dict = {}
    for effects in list(_models(cf)) * 2:          # the second round reads the memo only
        fast = residuals(states, cf, effects, rotor_channel=True, memo=memo)
        slow = residuals(states, cf, effects, rotor_channel=True)
        for c in range(slow.shape[1]):
            _close(fast[:, c], slow[:, c])
    assert any(k[0] == "motion" for k in memo)
    assert sum(isinstance(k, tuple) and k[0] == "wrench" for k in memo) == 3
    motion = next(v for k, v in memo.items() if k[0] == "motion")[1][1]
    assert any(k[0] == "cable_accel" for k in motion if isinstance(k, tuple))
    assert len(motion["cable_swings"]) == 1     # the same cable: only the mass changed


def test_a_jacobian_column_recomputes_only_the_effect_it_moves(cf, states):
    """The kept per-effect loads (quadsim.gap.residual.kept): moving rotor drag adds one entry,
    and the residual stays the one from scratch; moving the wind moves the air velocity,
    and every effect that reads it is computed anew (still equal to scratch)."""
    memo: dict = {}
    base = list(next(iter(_models(cf))))
    residuals(states, cf, base, rotor_channel=True, memo=memo)
    motion = next(v for k, v in memo.items() if k[0] == "motion")[1][1]
    before = len(motion["loads"])

    def swap(effects, new):
        return [new if e.name == new.name else e for e in effects]

    moved = swap(base, make_effect("rotor_drag", coefficient=3e-7, axial_coefficient=1e-7))
    windy = swap(base, make_effect("wind", vx=0.5, vy=-0.2))
    fast = residuals(states, cf, moved, rotor_channel=True, memo=memo)
    assert len(motion["loads"]) == before + 1
    _close(fast, residuals(states, cf, moved, rotor_channel=True))
    fast = residuals(states, cf, windy, rotor_channel=True, memo=memo)
    assert len(motion["air"]) == 2
    _close(fast, residuals(states, cf, windy, rotor_channel=True))


def _reference(cf, states):
    cand = shared_candidate(rotor=True)
    values = {"nominal_refit.thrust": 0.01, "nominal_refit.drag": -0.02,
              "rotor_drag.coefficient": 2e-7, "inertia_error.xx": 0.1,
              "inertia_error.yy": 0.1, "inertia_error.zz": 0.05, "rate_damping.x": 1e-6,
              "rate_damping.y": 1e-6, "rate_damping.z": 1e-6,
              "gyroscopic.rotor_inertia": 5e-8, "wind.vx": 0.1, "wind.vy": -0.1,
              "motor_lag.time_constant": 0.008, "thrust_curve.linear": 0.0,
              "thrust_curve.quadratic": 1e-10}
    theta = np.array([values[n] for n in cand.parameter_names])
    r = residuals(states, cf, cand.effects(theta), rotor_channel=True)
    sigma = np.sqrt(np.mean(r ** 2, axis=0))
    return Reference(cf, True, cand, theta, 0.1 * np.abs(theta), np.zeros_like(theta), sigma,
                     np.full(len(sigma), 3.0), np.zeros(len(sigma)), 1.0, 1, {}, [], {})


def test_the_jacobian_with_a_memo_is_forward_differences_from_scratch(cf, states):
    ref = _reference(cf, states)
    columns = list(range(len(ref.theta)))
    fast, base = jacobian(states, ref, columns, ref.candidate.effects, with_base=True)
    typical = typical_scales(ref.candidate, ref.params)
    slow_base = weighted_residual(states, ref, ref.effects()).ravel()
    _close(base, slow_base)
    for k in columns:
        theta = ref.theta.copy()
        theta[k] += 1e-3 * typical[k]
        moved = weighted_residual(states, ref, ref.candidate.effects(theta)).ravel()
        _close(fast[:, k], (moved - slow_base) / (1e-3 * typical[k]), rel=1e-9)


def test_an_explanations_kept_residual_is_a_fresh_evaluation(cf, states):
    ref = _reference(cf, states)
    jac = jacobian(states, ref, list(range(len(ref.theta))), ref.candidate.effects)
    expl = next(e for e in explanations_for(ref, states) if e.name == "cable_payload")
    memo: dict = {}
    kept = Problem(states, ref, expl, jac, ref.s_ref, memo)
    fresh = Problem(states, ref, expl, jac, ref.s_ref)
    z1, z2 = np.full(len(kept.mean), 0.1), np.full(len(kept.mean), -0.2)
    first = kept.residual(z1)
    kept.residual(z2)
    z1_again = z1.copy()
    assert kept.residual(z1_again) is not first       # another point came in between
    again = kept.residual(z1_again)
    assert again is kept.residual(z1_again)           # kept: the same array
    _close(again, fresh.residual(z1))
    _close(first, fresh.residual(z1))


def _context(cf, n=50, seed=3):
    rng = np.random.default_rng(seed)
    quat = euler_to_quat(rng.uniform(-0.6, 0.6, (n, 3)))
    vehicle = cf.replace(com=np.array([0.002, -0.001, 0.003]))
    vehicle = effect_class("canted_rotor")(rotor=3.0, tilt_x=0.1,
                                           tilt_y=-0.05).apply_to_params(vehicle)
    speed = rng.uniform(1500.0, 2800.0, (n, 4))
    return EffectContext(np.arange(n) * 0.01, rng.normal(size=(n, 3)),
                         rng.normal(size=(n, 3)), quat, rng.normal(size=(n, 3)),
                         rng.normal(size=(n, 3)) * 2.0, speed,
                         rng.normal(size=(n, 4)) * 1e3, vehicle)


def test_the_rotor_drag_sums_are_the_per_rotor_forces(cf):
    ctx = _context(cf)
    drag = make_effect("rotor_drag", coefficient=3e-7, axial_coefficient=1e-7)
    loads = drag.loads(ctx)
    params = ctx.params
    arms = params.rotor_positions - params.com
    forces = rotor_drag_forces(rotate_inverse(ctx.quat, ctx.air_velocity), ctx.rotor_speed,
                               params.rotor_axes, 3e-7, 1e-7, ctx.body_rate, arms)
    _close(loads.force_world, rotate(ctx.quat, forces.sum(axis=1)))
    _close(loads.torque_body, np.cross(arms[None], forces).sum(axis=1))


def test_the_context_rotations_are_the_frames_rotations(cf):
    ctx = _context(cf)
    v = np.random.default_rng(4).normal(size=(len(ctx.t), 3))
    _close(ctx.to_body(v), rotate_inverse(ctx.quat, v))
    _close(ctx.to_world(v), rotate(ctx.quat, v))


def test_the_gyroscopic_torque_is_its_einsum_form(cf):
    ctx = _context(cf)
    axes, spins = ctx.params.rotor_axes, ctx.params.rotor_spins
    h = np.einsum("br,r,rk->bk", ctx.rotor_speed, spins, axes)
    spin_up = np.einsum("br,r,rk->bk", ctx.rotor_accel, spins, axes)
    want = -5e-8 * (np.cross(ctx.body_rate, h) + spin_up)
    _close(gyroscopic_torque(5e-8, ctx.body_rate, ctx.rotor_speed, ctx.rotor_accel, axes,
                             spins), want)


def _physical(inertia):
    """An independent check: symmetric, positive principal moments, triangle inequality."""
    moments = np.sort(np.linalg.eigvalsh(inertia))
    return bool(np.allclose(inertia, inertia.T) and moments[0] > 0
                and moments[0] + moments[1] >= moments[2] * (1 - 1e-9))


def test_the_diagonal_inertia_check_is_the_eigenvalue_check(cf):
    rng = np.random.default_rng(5)
    cases = [np.diag(rng.uniform(-1e-5, 4e-5, 3)) for _ in range(300)]
    cases += [np.diag([1e-5, 1e-5, 2e-5]), np.diag([1e-5, 1e-5, 2.001e-5]),
              np.diag([0.0, 1e-5, 1e-5])]
    tilt = euler_to_quat(np.array([0.3, -0.2, 0.5]))
    from quadsim.core.frames import quat_to_rotmat
    rot = quat_to_rotmat(tilt)
    for k, inertia in enumerate(cases):
        assert (not inertia_problems(inertia)) == _physical(inertia), np.diag(inertia)
        if k < 300:     # the same body, not diagonal: the general path (off the boundaries)
            rotated = rot @ inertia @ rot.T
            assert (not inertia_problems(inertia)) == (not inertia_problems(rotated))
    assert sum(_physical(i) for i in cases) > 50 and sum(not _physical(i) for i in cases) > 50
    # a parameter change that moves the inertia is checked, one that does not is not redone
    with pytest.raises(ModelError):
        cf.replace(inertia=np.diag([1e-5, 1e-5, 3e-5]))
    assert cf.replace(mass=0.04).inertia is cf.inertia


def test_the_winds_gust_phases_drawn_on_first_use_are_the_seeds():
    from quadsim.effects.wind import GUST_COMPONENTS, LOWEST_FREQUENCY

    wind = make_effect("wind", vx=1.0, gust=0.5, bandwidth=3.0, seed=7)
    want = np.random.default_rng(7).uniform(0.0, 2.0 * np.pi, size=(3, GUST_COMPONENTS))
    np.testing.assert_array_equal(wind._phases, want)
    np.testing.assert_array_equal(wind._frequencies,
                                  np.geomspace(LOWEST_FREQUENCY, 3.0, GUST_COMPONENTS))
    t = np.array([0.0, 0.37])
    angle = 2 * np.pi * wind._frequencies * t[:, None, None] + want
    gust = 0.5 * np.sqrt(2.0 / GUST_COMPONENTS) * np.cos(angle).sum(axis=-1)
    _close(wind.air_velocity(t, np.zeros((2, 3))), gust + np.array([1.0, 0.0, 0.0]))


def test_the_screens_step_is_the_qr_and_bounded_solve_it_replaces(cf, states):
    """evidence.linear_step (its factor from the Gram matrix of [A b]; lsq_linear's own
    unconstrained first step where it lies inside the bounds) against Q R of the stacked
    Jacobian A formed here and ``lsq_linear``, inside and at the bounds; its precision AᵀA."""
    from scipy.optimize import lsq_linear

    from quadsim.gap.evidence import Columns, FitInputs, jacobian_columns, linear_step

    ref = _reference(cf, states)
    names = list(ref.candidate.parameter_names)
    jac = jacobian(states, ref, list(range(len(names))), ref.candidate.effects)
    memo: dict = {}
    expl = next(e for e in explanations_for(ref, states) if e.name == "cable_payload")
    prob = Problem(states, ref, expl, jac, ref.s_ref, memo)
    cols = Columns(FitInputs(states, ref, jac, ref.s_ref, memo))
    start = prob.start(0.0)
    base = prob.residual(start)
    columns = jacobian_columns(prob, cols, start, base, np.ones(len(start)))
    for squeeze in (None, 1e-3):          # the bounds as they are; then tight around start
        if squeeze is not None:
            prob.z_lo, prob.z_hi = start - squeeze, start + squeeze
        z1, predicted, h, active = linear_step(prob, start, base, columns)
        aug0, du0 = prob.marg.profile(base)
        b = np.concatenate([aug0, du0, start])
        aug, du = prob.marg.profile(columns)     # the stacked Jacobian A, formed here
        a = np.vstack([aug, du, np.eye(len(start))])
        _close(h, a.T @ a, rel=1e-9)
        q, r = np.linalg.qr(a)
        qb = q.T @ b
        want = lsq_linear(r, -qb, bounds=(prob.z_lo - start, prob.z_hi - start),
                          method="bvls")
        _close(z1 - start, want.x, rel=1e-9)
        cost = float(b @ b - qb @ qb) + float(np.sum((qb + r @ want.x) ** 2))
        assert predicted == pytest.approx(cost, rel=1e-9)
        assert active == int(np.count_nonzero(want.active_mask))
        assert (active > 0) == (squeeze is not None)


def test_the_uncompiled_swing_on_floats_is_the_kernels_steps():
    """cable._swing_floats (the swing without numba) against cable._swing_kernel stepped on
    arrays (compiled where numba is installed, else as plain Python), with two time jumps:
    a stacked flight at its own start (a Restart) and one hanging still; and
    cable.swing, which passes the restarts to whichever runs."""
    from quadsim.gap import fitting as cable

    rng = np.random.default_rng(1)
    t = np.arange(0.0, 6.4, 0.01)
    t[300:] += 0.5                                   # stacked flights: a restart
    t[500:] += 0.5                                   # and another, hanging still
    accel = rng.normal(size=(len(t), 3))
    q0, w0 = cable.start_state((0.1, -0.05), (0.3, 0.2))
    q1, w1 = cable.start_state((-0.2, 0.1), (0.0, -0.4))
    want = np.empty((2, *accel.shape))
    want_q, want_w = want
    constants = (9.81, 0.45, 0.3)                    # gravity, length, damped 0.3/s
    cable._swing_kernel(t, accel, np.array([[q0, w0], [q1, w1]]), np.array([0, 300]),
                        constants, want)
    rows_q, rows_w = cable._swing_floats(t.tolist(), accel.tolist(),
                                         {0: (q0.tolist(), w0.tolist()),
                                          300: (q1.tolist(), w1.tolist())}, constants)
    _close(np.array(rows_q), want_q, rel=1e-12)
    _close(np.array(rows_w), want_w, rel=1e-12)
    np.testing.assert_array_equal(np.array(rows_q)[300], q1)
    np.testing.assert_array_equal(np.array(rows_q)[500], [0.0, 0.0, -1.0])
    q, w = cable.swing(t, accel, 0.45, 9.81, (q0, w0), damping=0.3,
                       restarts=(cable.Restart(300, (-0.2, 0.1), (0.0, -0.4)),))
    _close(q, want_q, rel=1e-12)
    _close(w, want_w, rel=1e-12)


def test_the_jacobian_steps_back_from_a_wall_of_the_physical_set(cf, states):
    """A shared value half a step inside the triangle inequality (Izz <= Ixx + Iyy): the
    forward probe leaves the physical set (ModelError), so the column is the backward
    difference (1e-9 of its scale against one computed from scratch). Before, the calibration
    failed there and judged nothing (the multirotor source's 5.5 kg quadrotor, Izz 1.87
    Ixx)."""
    ref = _reference(cf, states)
    names = ref.candidate.parameter_names
    k = names.index("inertia_error.zz")
    i = np.diag(cf.inertia)
    xx, yy = ref.theta[names.index("inertia_error.xx")], ref.theta[names.index("inertia_error.yy")]
    wall = (i[0] * (1 + xx) + i[1] * (1 + yy)) / i[2] - 1.0
    h = 1e-3 * typical_scales(ref.candidate, ref.params)[k]
    ref.theta[k] = wall - 0.5 * h
    beyond = ref.theta.copy()
    beyond[k] += h
    with pytest.raises(ModelError):
        weighted_residual(states, ref, ref.candidate.effects(beyond))
    jac = jacobian(states, ref, [k], ref.candidate.effects)
    back = ref.theta.copy()
    back[k] -= h
    slow = (weighted_residual(states, ref, ref.candidate.effects(back)).ravel()
            - weighted_residual(states, ref, ref.effects()).ravel()) / -h
    _close(jac[:, 0], slow, rel=1e-9)


def test_the_rotor_drags_kept_geometry_gives_the_loads_from_scratch(cf):
    """rotor_drag keeps what it reads of the motion, the air and the vehicle per flight
    (RotorDrag._geometry): at other rotor speeds, and on a vehicle of another mass (the
    same rotors and CoM: shared) or another CoM (its own entry), the loads are the ones
    computed without a memo, to the bit (the same operations on the same numbers)."""
    import dataclasses

    ctx = _context(cf)
    memo: dict = {}
    drag = make_effect("rotor_drag", coefficient=3e-7, axial_coefficient=1e-7)
    heavier = ctx.params.replace(mass=ctx.params.mass + 0.004)
    moved = ctx.params.replace(com=ctx.params.com + np.array([0.001, 0.0, 0.0]))
    for params, speed in [(ctx.params, ctx.rotor_speed), (ctx.params, ctx.rotor_speed * 1.1),
                          (heavier, ctx.rotor_speed), (moved, ctx.rotor_speed * 0.9)]:
        plain = dataclasses.replace(ctx, params=params, rotor_speed=speed)
        kept = dataclasses.replace(plain, flight_memo=memo)
        fast, slow = drag.loads(kept), drag.loads(plain)
        assert np.array_equal(fast.force_world, slow.force_world)
        assert np.array_equal(fast.torque_body, slow.torque_body)
    assert len(memo["rotor_drag.geometry"]) == 2       # the heavier vehicle shared the first


def test_the_rotor_channels_kept_model_gives_the_channel_from_scratch(cf, states):
    """The rotor channel's command side (quadsim.gap.residual.rotor_model) is kept per
    command model: read at several rotor delays (the evidence's shifted states share the
    commands), the channel is the one computed without a memo, to the bit; one model per
    motor lag, not one per delay."""
    from quadsim.gap.reference import shifted
    from quadsim.gap.residual import rotor_residual

    memo: dict = {}
    for lag in (0.008, 0.012):
        effects = [make_effect("motor_lag", time_constant=lag),
                   make_effect("battery_sag", full_voltage=4.1)]
        for delay in (0.0, 0.002, -0.003):
            view = shifted(states, delay)
            fast = rotor_residual(view, cf, effects, memo=memo)
            assert np.array_equal(fast, rotor_residual(view, cf, effects))
    assert sum(isinstance(k, tuple) and k[0] == "rotor_model" for k in memo) == 2


def test_cable_attachment_derivative_is_scipys_savgol_filter():
    """The cable's attachment acceleration (:func:`quadsim.gap.fitting._derivative`, through
    :func:`quadsim.logs.savgol.savgol`) against ``scipy.signal.savgol_filter(..., deriv=1)``
    itself, per uniform stretch of a time base with a jump (a stacked flight): 1e-12 of the
    derivative's scale (the ends' fits are the same polynomial, taken as a fixed matrix)."""
    from scipy.signal import savgol_filter

    from quadsim.gap.fitting import ACCEL_WINDOW_S, _derivative

    rng = np.random.default_rng(5)
    step = 0.01
    t = np.concatenate([np.arange(300) * step, 10.0 + np.arange(200) * step])
    x = np.cumsum(rng.normal(size=(500, 3)), axis=0) * 0.01
    got = _derivative(t, x)
    window = 2 * int(ACCEL_WINDOW_S / (2 * step)) + 1
    for piece in (slice(0, 300), slice(300, 500)):
        want = savgol_filter(x[piece], window, 3, deriv=1, delta=step, axis=0)
        np.testing.assert_allclose(got[piece], want, rtol=0,
                                   atol=1e-12 * float(np.max(np.abs(want))))


def test_window_means_kept_for_the_same_arrays(cf, states):
    """:func:`quadsim.gap.residual._window_means` gives its last answer again while the
    flights hold the same arrays (the same objects back, equal to a fresh computation) and
    computes anew for other arrays, even of the same values (a copy)."""
    import dataclasses

    from quadsim.gap import residual as res

    fresh = res._computed_window_means([states])
    first = res._window_means([states])
    assert res._window_means([states]) is first
    for got, want in zip(first, fresh):
        np.testing.assert_array_equal(got, want)
    copy = dataclasses.replace(states, command=states.command.copy())
    other = res._window_means([copy])
    assert other is not first
    for got, want in zip(other, fresh):
        np.testing.assert_array_equal(got, want)


def test_the_line_sum_of_squares_is_polyfits():
    """:func:`quadsim.gap.residual.line_rss` (the timing search's line, :func:`map_lag`) is
    the summed residual sum of squares of ``np.polyfit(x, y, 1)`` per column, to 1e-12 of
    it: a noisy line at a rotor's scale (commands ~0.5, speeds ~2000 rad/s), an exact line
    (0 to round-off of the speeds' scale) and a column whose x does not vary (y's own sum of
    squares about its mean)."""
    from quadsim.gap.residual import line_rss

    rng = np.random.default_rng(7)
    x = rng.uniform(0.3, 0.7, (500, 3))
    y = 300.0 + 2500.0 * x + rng.normal(0.0, 15.0, x.shape)
    want = sum(float(np.sum((y[:, i] - np.polyval(np.polyfit(x[:, i], y[:, i], 1),
                                                   x[:, i])) ** 2)) for i in range(3))
    assert line_rss(x, y) == pytest.approx(want, rel=1e-12)
    exact = 300.0 + 2500.0 * x
    assert line_rss(x, exact) < 1e-18 * float(np.sum(exact ** 2))
    flat = np.full((500, 1), 0.5)
    assert line_rss(flat, y[:, :1]) == pytest.approx(float(np.sum((y[:, 0] - y[:, 0].mean())
                                                                  ** 2)), rel=1e-12)
