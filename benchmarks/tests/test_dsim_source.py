"""The drones-sim flight source (benchmarks.dsim_source, dsim_cases): the parameter set
against closed forms of QuadcopterConfig()'s defaults, the frozen case list, and -- with
drones-sim installed (``pip install --no-deps drones-sim==0.2.0``) -- its plant's
accelerations against Newton-Euler closed forms (hover, random states, a CoM off the centre,
a weak rotor, wind on the linear drag, a heavier vehicle, rate damping), its motor lag's
step response, and one short flight's log against the source's force law."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.dsim_source import dsim_available
from benchmarks.tests._helpers import check_case_table, check_drawn, quiet_flight

needs_dsim = pytest.mark.skipif(not dsim_available(), reason="drones-sim is not installed")

#: QuadcopterConfig() in drones-sim 0.2.0
MASS, G, L, KF, KM, DRAG, TAU = 1.0, 9.81, 0.2, 1e-6, 1e-7, 0.1, 0.04
J = np.diag([0.01, 0.01, 0.018])
HOVER = np.sqrt(MASS * G / 4 / KF)                 # rad/s
POS = L * np.array([[1.0, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]])
DIRS = np.array([1.0, -1.0, 1.0, -1.0])


def _job(**changes):
    """A flight job (dsim_source._job's fields) with the nominal values and ``changes``."""
    job = {"mass": MASS, "com": np.zeros(3), "J": J.copy(), "rotor_scale": np.ones(4),
           "motor_tau": TAU, "drag": np.full(3, DRAG), "wind": np.zeros(3),
           "rate_damping": np.zeros(3), "torque": np.zeros(3), "torque_hz": 0.0,
           "force": 0.0, "force_hz": 0.0}
    job.update(changes)
    return job


def _accel(job, speeds, rpy=(0.0, 0.0, 0.0), w_body=(0.0, 0.0, 0.0), v=(0.0, 0.0, 0.0)):
    """(angular acceleration body, CoM acceleration world) of drones-sim's plant of ``job``
    at rotor speeds ``speeds`` (rad/s), the given attitude, body rates and velocity."""
    from benchmarks.dsim_source import make_plant

    plant = make_plant(job)
    plant.reset(position=np.array([0.0, 0.0, 1.0]), attitude=np.asarray(rpy, float))
    plant.state[3:6] = v
    plant.state[10:13] = w_body
    d = plant._derivatives(plant.state, np.asarray(speeds, float), t=0.0)
    return d[10:13], d[3:6]


def _newton_euler(speeds, rot, w, v_body):
    """Closed form: (angular acceleration body, acceleration world) of the nominal rigid
    body with rotor forces KF O^2 along body z at POS, moments DIRS KM O^2, linear drag
    -DRAG v_body at the CoM, gravity; ``rot`` body -> world, ``w`` body rates."""
    f = KF * np.asarray(speeds) ** 2
    tau = np.sum(np.cross(POS, np.outer(f, [0, 0, 1.0])), axis=0)
    tau[2] += np.sum(DIRS * KM * np.asarray(speeds) ** 2)
    alpha = np.linalg.solve(J, tau - np.cross(w, J @ w))
    force = rot @ (np.array([0, 0, f.sum()]) - DRAG * v_body) + np.array([0, 0, -MASS * G])
    return alpha, force / MASS


def test_parameter_set_closed_form():
    """drones-sim's defaults as quadsim's set: m 1.0 kg, J diag(0.01, 0.01, 0.018), rotors at
    (L, 0), (0, L), (-L, 0), (0, -L), spins -1, +1, -1, +1 (directions +1, -1, +1, -1: a
    moment +k_m along +z is a clockwise rotor's reaction); b 1e-6, d 1e-7; the hover speed
    sqrt(m g / 4 b) = 1566.05 rad/s (1e-12)."""
    if not dsim_available():
        pytest.skip("drones-sim is not installed")
    from benchmarks.dsim_source import dsim_params, hover_speed, vehicle_params

    p = dsim_params()
    assert (p["m"], p["g"], p["L"], p["kf"], p["km"], p["tau"]) == (MASS, G, L, KF, KM, TAU)
    np.testing.assert_allclose(p["I"], J, rtol=1e-12)
    np.testing.assert_allclose(p["drag"], DRAG, rtol=1e-12)
    params = vehicle_params()
    assert (params.thrust_factor, params.drag_factor, params.max_speed) == (KF, KM, 4000.0)
    assert hover_speed() == pytest.approx(HOVER, rel=1e-12)
    assert HOVER == pytest.approx(1566.046, abs=1e-3)
    np.testing.assert_allclose(params.rotor_positions, POS, atol=1e-15)
    np.testing.assert_allclose(params.rotor_spins, [-1, 1, -1, 1])
    assert params.mass * params.gravity == pytest.approx(4 * KF * HOVER ** 2, rel=1e-12)


def test_case_list_frozen_and_mapped_to_the_library():
    """The 28 frozen cases, the same on a second draw: 6 no-effect, 20 in-library, 2
    outside; seeds apart from the references'; each in-library truth (not a delay) a library
    effect named by its true difference on top of the shared motor lag and drag; the draws
    within the module table; the shared effects' closed forms (k = D / 4 Omega_hover)."""
    if not dsim_available():
        pytest.skip("drones-sim is not installed")
    from benchmarks import dsim_cases

    cases = check_case_table(dsim_cases, (6, 20, 2), ("motor_lag", "rotor_drag"))
    check_drawn(cases, MASS, L, {"mass": (0.05, 0.2), "payload": ((0.05, 0.15), (0.015, 0.05)),
                                 "com": (0.03, 0.1), "motor_slow": (1.5, 2.5),
                                 "drag_scale": (1.5, 2.5), "wind": (1.0, 3.0)})
    lag, drag = dsim_cases.shared_effects()
    assert lag.time_constant == pytest.approx(TAU, rel=1e-12)
    assert drag.coefficient == pytest.approx(DRAG / (4 * HOVER), rel=1e-12)
    assert drag.axial_coefficient == pytest.approx(DRAG / (4 * HOVER), rel=1e-12)


@needs_dsim
def test_hover_and_random_states_obey_newton_euler():
    """At the hover speed, level and still: no acceleration (1e-12). At random attitudes,
    body rates, velocities and rotor speeds: drones-sim's plant equals the Newton-Euler
    closed form (:func:`_newton_euler`, 1e-9)."""
    from drones_sim.math_utils import quat_from_euler, quat_to_rotation_matrix

    alpha, acc = _accel(_job(), np.full(4, HOVER))
    np.testing.assert_allclose(np.concatenate([alpha, acc]), 0.0, atol=1e-12)
    rng = np.random.default_rng(3)
    for _ in range(5):
        rpy = rng.uniform(-0.5, 0.5, 3)
        w = rng.uniform(-2, 2, 3)
        v = rng.uniform(-2, 2, 3)
        speeds = HOVER * rng.uniform(0.7, 1.3, 4)
        alpha, acc = _accel(_job(), speeds, rpy, w, v)
        rot = quat_to_rotation_matrix(quat_from_euler(*rpy))
        expect_alpha, expect_acc = _newton_euler(speeds, rot, w, rot.T @ v)
        np.testing.assert_allclose(alpha, expect_alpha, atol=1e-9)
        np.testing.assert_allclose(acc, expect_acc, atol=1e-9)


@needs_dsim
def test_case_handles_change_the_physics_by_the_stated_amount():
    """Level and still at the hover speed: a CoM at (cx, cy) gives the angular acceleration
    J^-1 (-cy m g, cx m g, 0) (1e-9); rotor 2 at -10 % gives a_z = -0.1 g / 4 and the body
    torques (-0.1 L, 0, +0.1 k_m / k_f) m g / 4 (1e-9); a wind (2, 1) m/s on the linear drag
    gives the acceleration (0.1 x 2, 0.1 x 1, 0) m/s^2 and twice that at drag x 2 (1e-12); a
    mass +10 % gives a_z = -g 0.1 / 1.1 (1e-12); rate damping k at rates w gives the
    angular acceleration J^-1 (-k w - w x J w) (1e-12)."""
    c = np.array([0.006, -0.004, 0.0])
    alpha, _ = _accel(_job(com=c), np.full(4, HOVER))
    np.testing.assert_allclose(alpha, np.linalg.solve(J, [-c[1] * MASS * G, c[0] * MASS * G,
                                                          0.0]), atol=1e-9)
    alpha, acc = _accel(_job(rotor_scale=np.array([1.0, 0.9, 1.0, 1.0])), np.full(4, HOVER))
    assert acc[2] == pytest.approx(-0.1 * G / 4, abs=1e-9)
    np.testing.assert_allclose(J @ alpha, np.array([-0.1 * L, 0.0, 0.1 * KM / KF]) * MASS * G
                               / 4, atol=1e-9)
    _, acc = _accel(_job(wind=np.array([2.0, 1.0, 0.0])), np.full(4, HOVER))
    np.testing.assert_allclose(acc, [DRAG * 2, DRAG * 1, 0.0], atol=1e-12)
    _, acc = _accel(_job(wind=np.array([2.0, 1.0, 0.0]), drag=np.full(3, 2 * DRAG)),
                    np.full(4, HOVER))
    np.testing.assert_allclose(acc, [4 * DRAG, 2 * DRAG, 0.0], atol=1e-12)
    _, acc = _accel(_job(mass=1.1 * MASS), np.full(4, HOVER))
    assert acc[2] == pytest.approx(-G * 0.1 / 1.1, abs=1e-12)
    k, w = np.array([0.03, 0.03, 0.01]), np.array([1.0, -2.0, 0.5])
    alpha, _ = _accel(_job(rate_damping=k), np.full(4, HOVER), w_body=w)
    np.testing.assert_allclose(alpha, np.linalg.solve(J, -k * w - np.cross(w, J @ w)),
                               atol=1e-12)


@needs_dsim
def test_motor_lag_step_response():
    """The 40 ms motor lag, x 2 by ``motor_slow``: a step of the command from the hover
    speed to 1.1 x it reaches hover (1 + 0.1 (1 - e^-1)) after one time constant (exact
    update: 1e-12 relative at 25 steps of 3.2 ms)."""
    from benchmarks.dsim_source import make_plant

    plant = make_plant(_job(motor_tau=2 * TAU))
    plant.reset(position=np.array([0.0, 0.0, 1.0]))
    plant.motor_states = np.full(4, HOVER)
    for _ in range(25):
        plant.update(2 * TAU / 25, np.full(4, 1.1 * HOVER))
    np.testing.assert_allclose(plant.get_motor_speeds(), HOVER * (1 + 0.1 * (1 - np.exp(-1))),
                               rtol=1e-12)


@needs_dsim
def test_short_flight_log_obeys_the_source_force_law():
    """A 1-s nominal flight with no sensor noise: per sample, the logged specific force times
    m equals the thrust k_f sum Omega^2 on z and the drag -D v_body on every axis (1e-9 N: the
    log's specific force is the plant's own acceleration); the rotor speeds stay within 15 %
    of hover and follow the command through the exact lag (1e-9 relative)."""
    from benchmarks.dsim_source import CONTROL_HZ, dsim_flights

    log, v_body = quiet_flight(dsim_flights, "drones-sim")
    force = MASS * log.accel
    thrust = KF * np.sum(log.rotor_speed ** 2, axis=1)
    np.testing.assert_allclose(force[:, 0:2], -DRAG * v_body[:, 0:2], atol=1e-9)
    np.testing.assert_allclose(force[:, 2], thrust - DRAG * v_body[:, 2], atol=1e-9)
    assert np.all(np.abs(log.rotor_speed / HOVER - 1) < 0.15)
    a = 1 - np.exp(-1 / CONTROL_HZ / TAU)
    cmd = log.rotor_command * 4000.0
    np.testing.assert_allclose(log.rotor_speed[1:], log.rotor_speed[:-1]
                               + a * (cmd[1:] - log.rotor_speed[:-1]), rtol=1e-9)
