"""The quad_sim_python flight source (benchmarks.qsp_source, qsp_cases): the parameter set
against closed forms of its ``quad_params``, the frozen case list, and -- with
quad_sim_python installed (``pip install --no-deps quad_sim_python==0.0.2``) -- its plant's
accelerations against Newton-Euler closed forms (hover, random states, a CoM off the centre,
a weak rotor, wind and a drag scale on its quadratic drag, a heavier vehicle), its motor
dynamics' step response, and one short flight's log against the source's force law and
our frames."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.qsp_source import qsp_available
from benchmarks.tests._helpers import check_case_table, check_drawn, quiet_flight

needs_qsp = pytest.mark.skipif(not qsp_available(), reason="quad_sim_python is not installed")

#: quad_params of quad_sim_python 0.0.2
MASS, G, D, KTH, KTO, CD, TAU = 1.2, 9.81, 0.16, 1.076e-5, 1.632e-7, 0.1, 0.015
J = np.diag([0.0123, 0.0123, 0.0224])
HOVER = np.sqrt(MASS * G / 4 / KTH)                 # rad/s
#: rotor places in its FRD body frame (1 front left, then clockwise from above)
POS_FRD = D * np.array([[1.0, -1, 0], [1, 1, 0], [-1, 1, 0], [-1, -1, 0]])
#: its yaw row in NED: tau_z = -kTo (w1^2 - w2^2 + w3^2 - w4^2)
YAW_FRD = -np.array([1.0, -1.0, 1.0, -1.0])
FLIP = np.diag([1.0, -1.0, -1.0])


def _job(**changes):
    """A flight job (qsp_source._job's fields) with the nominal values and ``changes``."""
    job = {"mass": MASS, "com": np.zeros(3), "J": J.copy(), "rotor_scale": np.ones(4),
           "tau": TAU, "Cd": CD, "wind": np.zeros(3), "rate_damping": np.zeros(3),
           "torque": np.zeros(3), "torque_hz": 0.0, "force": 0.0, "force_hz": 0.0}
    job.update(changes)
    return job


def _quat(rpy):
    """Scalar-first quaternion of roll, pitch, yaw (x, y, z extrinsic; its init_state)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("xyz", rpy).as_quat()[[3, 0, 1, 2]]


def _derivative(job, speeds, rpy=(0.0, 0.0, 0.0), w_frd=(0.0, 0.0, 0.0),
                v_ned=(0.0, 0.0, 0.0)):
    """(angular acceleration FRD, acceleration NED) of quad_sim_python's plant of ``job``
    (its state_dot) at rotor speeds ``speeds`` (rad/s, held: the commands equal them and the
    speed rates are 0), the attitude ``rpy`` (its init_state's Euler angles), body rates and
    velocity."""
    from benchmarks.qsp_source import _wind_input, make_plant

    plant = make_plant(job, (0.0, 0.0, -1.0))
    state = plant.state.copy()
    state[3:7] = _quat(rpy)
    state[7:10], state[10:13] = v_ned, w_frd
    state[[13, 15, 17, 19]] = speeds
    state[[14, 16, 18, 20]] = 0.0
    d = plant.state_dot(0.0, state, np.asarray(speeds, float), _wind_input(job["wind"]))
    return d[10:13], d[7:10]


def _newton_euler(speeds, rot, w, v):
    """Closed form in NED/FRD: (angular acceleration body, acceleration world) of the nominal
    rigid body with thrusts KTH O^2 along body -z at POS_FRD, yaw moments YAW_FRD KTO O^2,
    drag -CD |v_i| v_i per world axis, gravity +G along NED z; ``rot`` body -> world. Euler's
    equations as ITS state_dot writes them: its yaw row's gyroscopic term is (Ixx - Izz) p q
    where Euler's is (Ixx - Iyy) p q (= 0 for its Ixx = Iyy): kept, the simulator's own."""
    f = KTH * np.asarray(speeds) ** 2
    tau = np.sum(np.cross(POS_FRD, np.outer(f, [0, 0, -1.0])), axis=0)
    tau[2] += np.sum(YAW_FRD * KTO * np.asarray(speeds) ** 2)
    alpha = np.linalg.solve(J, tau - np.cross(w, J @ w))
    alpha[2] += (J[0, 0] - J[2, 2]) * w[0] * w[1] / J[2, 2]
    force = rot @ np.array([0, 0, -f.sum()]) - CD * np.abs(v) * np.asarray(v)
    return alpha, force / MASS + np.array([0, 0, G])


def test_parameter_set_closed_form():
    """quad_params as quadsim's set: m 1.2 kg, J diag(0.0123, 0.0123, 0.0224), rotors (body x
    forward, y left) at (d, d), (d, -d), (-d, -d), (-d, d), d = 0.16 m, spins -1, +1, -1, +1
    (its yaw row: rotors 1, 3 push +kTo w^2 about world up, the reaction of a clockwise
    rotor); b 1.076e-5, d 1.632e-7; the hover speed sqrt(m g / 4 kTh) = 522.985 rad/s, where
    the four thrusts equal the weight (1e-12), its own init_cmd's w_hover."""
    if not qsp_available():
        pytest.skip("quad_sim_python is not installed")
    from benchmarks.qsp_source import (
        hover_speed,
        make_plant,
        nominal_job,
        qsp_params,
        vehicle_params,
    )

    p = qsp_params()
    assert (p["mB"], p["g"], p["dxm"], p["dym"], p["kTh"], p["kTo"], p["Cd"], p["tau"]) == (
        MASS, G, D, D, KTH, KTO, CD, TAU)
    np.testing.assert_allclose(p["IB"], J, rtol=1e-12)
    params = vehicle_params()
    assert (params.thrust_factor, params.drag_factor, params.max_speed) == (KTH, KTO, 925.0)
    assert hover_speed() == pytest.approx(HOVER, rel=1e-12)
    assert HOVER == pytest.approx(522.985, abs=1e-3)
    assert make_plant(nominal_job()).params["w_hover"] == pytest.approx(HOVER, rel=1e-12)
    np.testing.assert_allclose(params.rotor_positions, POS_FRD @ FLIP, atol=1e-15)
    np.testing.assert_allclose(params.rotor_spins, [-1, 1, -1, 1])
    assert params.mass * params.gravity == pytest.approx(4 * KTH * HOVER ** 2, rel=1e-12)


def test_case_list_frozen_and_mapped_to_the_library():
    """The 24 frozen cases, the same on a second draw: 6 no-effect, 16 in-library, 2
    outside; seeds apart from the references'; each in-library truth a library effect named
    by its true difference on top of the shared motor lag and body drag; the draws within
    the module table; the shared effects' closed forms (2 tau = 30 ms; C_d A = 2 Cd / rho =
    0.1633 m^2 per axis)."""
    if not qsp_available():
        pytest.skip("quad_sim_python is not installed")
    from benchmarks import qsp_cases

    cases = check_case_table(qsp_cases, (6, 16, 2), ("motor_lag", "body_drag"))
    arm = np.hypot(D, D)
    check_drawn(cases, MASS, arm, {"mass": (0.05, 0.2), "payload": ((0.1, 0.3), (0.02, 0.06)),
                                   "com": (0.03, 0.1), "motor_slow": (1.5, 2.5),
                                   "drag_scale": (1.5, 2.5), "wind": (2.0, 5.0)})
    lag, drag = qsp_cases.shared_effects()
    assert lag.time_constant == pytest.approx(2 * TAU, rel=1e-12)
    assert drag.cd_area == pytest.approx(2 * CD / 1.225, rel=1e-12)
    assert drag.cd_area_vertical == pytest.approx(2 * CD / 1.225, rel=1e-12)
    assert drag.per_axis == 1.0


@needs_qsp
def test_hover_and_random_states_obey_newton_euler():
    """At the hover speed, level and still: no acceleration (1e-12). At random attitudes,
    body rates, velocities and rotor speeds: quad_sim_python's plant equals the Newton-Euler
    closed form (:func:`_newton_euler`, 1e-9; with its yaw row's (Ixx - Izz) p q term, which
    a check against Euler's (Ixx - Iyy) p q = 0 finds: 0.24 rad/s^2 at one of these states)."""
    from scipy.spatial.transform import Rotation

    alpha, acc = _derivative(_job(), np.full(4, HOVER))
    np.testing.assert_allclose(np.concatenate([alpha, acc]), 0.0, atol=1e-12)
    rng = np.random.default_rng(3)
    for _ in range(5):
        rpy = rng.uniform(-0.5, 0.5, 3)
        w = rng.uniform(-2, 2, 3)
        v = rng.uniform(-2, 2, 3)
        speeds = HOVER * rng.uniform(0.7, 1.3, 4)
        alpha, acc = _derivative(_job(), speeds, rpy, w, v)
        rot = Rotation.from_euler("xyz", rpy).as_matrix()
        expect_alpha, expect_acc = _newton_euler(speeds, rot, w, v)
        np.testing.assert_allclose(alpha, expect_alpha, atol=1e-9)
        np.testing.assert_allclose(acc, expect_acc, atol=1e-9)


@needs_qsp
def test_case_handles_change_the_physics_by_the_stated_amount():
    """Level and still at the hover speed, in our frames (x forward, y left, z up): a CoM at
    (cx, cy) gives the angular acceleration J^-1 (-cy m g, cx m g, 0) (1e-9); rotor 2 (front
    right) with kTh, kTo -10 % gives a_z = -0.1 g / 4 and the body torques (0.1 d, 0.1 d,
    0.1 kTo / kTh) m g / 4 (1e-9); a wind (2, 1) m/s on its quadratic drag gives (Cd 4, Cd 1,
    0) / m and 1.5 times that at Cd x 1.5 (1e-12); a mass +10 % gives a_z = -g 0.1 / 1.1
    (1e-12); a body torque (0.01, -0.02, 0) N m at 1 Hz gives J^-1 of it a quarter period
    in (1e-12)."""
    from benchmarks.qsp_source import make_plant

    c = np.array([0.006, -0.004, 0.0])
    alpha, _ = _derivative(_job(com=c), np.full(4, HOVER))
    np.testing.assert_allclose(FLIP @ alpha, np.linalg.solve(
        J, [-c[1] * MASS * G, c[0] * MASS * G, 0.0]), atol=1e-9)
    alpha, acc = _derivative(_job(rotor_scale=np.array([1.0, 0.9, 1.0, 1.0])),
                             np.full(4, HOVER))
    assert -acc[2] == pytest.approx(-0.1 * G / 4, abs=1e-9)
    np.testing.assert_allclose(J @ (FLIP @ alpha), np.array([0.1 * D, 0.1 * D, 0.1 * KTO / KTH])
                               * MASS * G / 4, atol=1e-9)
    for scale in (1.0, 1.5):
        _, acc = _derivative(_job(wind=np.array([2.0, 1.0, 0.0]), Cd=scale * CD),
                             np.full(4, HOVER))
        np.testing.assert_allclose(FLIP @ acc, scale * CD * np.array([4.0, 1.0, 0.0]) / MASS,
                                   atol=1e-12)
    _, acc = _derivative(_job(mass=1.1 * MASS), np.full(4, HOVER))
    assert -acc[2] == pytest.approx(-G * 0.1 / 1.1, abs=1e-12)
    torque = np.array([0.01, -0.02, 0.0])
    plant = make_plant(_job(torque=torque, torque_hz=1.0), (0.0, 0.0, -1.0))
    d = plant.state_dot(0.25, plant.state, np.full(4, HOVER), [0.0, 0.0, 0.0])
    np.testing.assert_allclose(FLIP @ d[10:13], np.linalg.solve(J, torque), atol=1e-12)


@needs_qsp
def test_motor_step_response():
    """Its critically damped second-order motor (tau 15 ms, x 2 by ``motor_slow``): a step of
    the command from rest at the hover speed to 1.1 x it reaches hover (1 + 0.1 (1 - 2/e))
    after one time constant (dopri5 at its rtol 1e-5: 1e-5 relative)."""
    from benchmarks.qsp_source import make_plant

    plant = make_plant(_job(tau=2 * TAU), (0.0, 0.0, -100.0))
    steps = 10
    for k in range(steps):
        plant.update((k + 1) * 2 * TAU / steps, 2 * TAU / steps, np.full(4, 1.1 * HOVER),
                     [0.0, 0.0, 0.0])
    np.testing.assert_allclose(plant.wMotor, HOVER * (1 + 0.1 * (1 - 2 / np.e)), rtol=1e-5)


@needs_qsp
def test_short_flight_log_obeys_the_source_force_law():
    """A 1-s nominal flight with no sensor noise, in our frames: per sample, the logged
    specific force times m equals the thrust kTh sum Omega^2 on body z plus its world-axis
    drag -Cd |v_i| v_i rotated into the body (1e-6 N: the log's specific force is its own
    state derivative; its quaternion's norm drifts by < 1e-7 under dopri5); the rotor speeds
    stay within 15 % of hover, the commands are speeds / 925; the vehicle flies the loop
    1.2-1.8 m above the ground (the loop 1.25-1.75 m) (z up)."""
    from benchmarks.qsp_source import qsp_flights
    from quadsim.core.frames import quat_to_rotmat

    log, _ = quiet_flight(qsp_flights, "quad-sim-python")
    rot = quat_to_rotmat(log.quat)
    v = log.velocity
    drag_body = np.einsum("nji,nj->ni", rot, -CD * np.abs(v) * v)
    force = MASS * log.accel - drag_body
    thrust = KTH * np.sum(log.rotor_speed ** 2, axis=1)
    np.testing.assert_allclose(force[:, 0:2], 0.0, atol=1e-6)
    np.testing.assert_allclose(force[:, 2], thrust, atol=1e-6)
    assert np.all(np.abs(log.rotor_speed / HOVER - 1) < 0.15)
    assert np.all((log.rotor_command > 0.3) & (log.rotor_command < 0.8))
    assert np.all((log.position[:, 2] > 1.2) & (log.position[:, 2] < 1.8))
