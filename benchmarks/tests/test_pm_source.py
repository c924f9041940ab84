"""The pymulticopter flight source (benchmarks.pm_source, pm_cases): the parameter set
against closed forms and pymulticopter's own effector, the frozen case list, and -- with
pymulticopter installed (``pip install --no-deps pymulticopter==0.0.1 pysimenv==0.0.22 h5py
pytictoc pyquaternion``) -- its plant's derivative against Newton-Euler closed forms (hover,
random states, a CoM off the centre, a weak motor, a bias, rate damping, a body torque),
pysimenv's RK4 against exact solutions, and short flights against quadsim's model."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.pm_source import pm_available
from benchmarks.tests._helpers import check_case_table, check_drawn

needs_pm = pytest.mark.skipif(not pm_available(), reason="pymulticopter is not installed")

#: its example vehicle and this project's rotor scale (pm_source's module doc)
MASS, G, D, C, B = 4.34, 9.805, 0.15, 0.0196, 1.2e-6
#: the gravity its plant applies: 9.805 times its float32 e3 (MulticopterDyn.e3 is float32)
G32 = float(np.float32(G))
J = np.diag([0.0820, 0.0845, 0.1377])
HOVER = np.sqrt(MASS * G / 4 / B)                     # rad/s
H = D / 2
#: rotor places in our FLU body frame (1 front right, 2 rear left, 3 front left, 4 rear right)
POS_FLU = np.array([[H, -H, 0], [-H, H, 0], [H, H, 0], [-H, -H, 0]])
SPINS = np.array([1.0, 1.0, -1.0, -1.0])
FLIP = np.diag([1.0, -1.0, -1.0])


def _job(**changes):
    """A flight job (pm_source.make_job's fields) with the nominal values and ``changes``."""
    job = {"mass": MASS, "com": np.zeros(3), "J": J.copy(), "alp": np.ones(4),
           "rho": np.zeros(4), "wind": np.zeros(3), "rate_damping": np.zeros(3),
           "torque": np.zeros(3), "torque_hz": 0.0, "force": 0.0, "force_hz": 0.0}
    job.update(changes)
    return job


def _derivative(job, thrusts, rot_flu=None, w_flu=(0.0, 0.0, 0.0), t=0.0):
    """(angular acceleration FLU, acceleration world z up) of pymulticopter's plant of ``job``
    (MulticopterDyn._deriv under pm_source.wrench) with the commanded rotor ``thrusts`` (N)
    through its ActuatorFault of the job's gain and bias, at the attitude ``rot_flu`` (body
    FLU -> world z up; None: level), body rates ``w_flu``, at rest, time ``t`` s."""
    from pymulticopter.model import ActuatorFault

    from benchmarks.pm_source import make_plant, wrench

    rot_flu = np.eye(3) if rot_flu is None else rot_flu
    _, _, dyn = make_plant(job, (0.0, 0.0, -1.0))
    actual = ActuatorFault([0.0], [job["alp"]], [job["rho"]])._forward(np.asarray(thrusts))
    f, tau = wrench(job, actual, t)
    d = dyn._deriv(np.zeros(3), np.zeros(3), FLIP @ rot_flu @ FLIP,
                   FLIP @ np.asarray(w_flu, float), f, tau)
    return FLIP @ d["omega"], FLIP @ d["v"]


def _newton_euler(thrusts, rot, w):
    """Closed form in FLU / world z up of the nominal rigid body: thrusts up along body z at
    POS_FLU, yaw reactions -spin c_tau_f f_i, gravity -G32 (its float32 e3: 9.805 becomes
    9.8050003, 3e-7 m/s^2, which a 1e-12 check finds); (angular acceleration, acceleration)."""
    f = np.asarray(thrusts, float)
    tau = np.sum(np.cross(POS_FLU, np.outer(f, [0, 0, 1.0])), axis=0)
    tau[2] += np.sum(-SPINS * C * f)
    alpha = np.linalg.solve(J, tau - np.cross(w, J @ w))
    return alpha, rot @ np.array([0, 0, f.sum()]) / MASS - np.array([0, 0, G32])


def test_parameter_set_closed_form():
    """The vehicle as quadsim's set: m 4.34 kg, J diag(0.0820, 0.0845, 0.1377), rotors (body x
    forward, y left) at (h, -h), (-h, h), (h, h), (-h, -h), h = 0.075 m, spins +1, +1, -1, -1;
    b 1.2e-6, d = c_tau_f b; the hover speed sqrt(m g / 4 b) = 2977.47 rad/s; with
    pymulticopter: quadsim's rotor model (r_i x b w^2 z - spin d w^2 z) reproduces its
    QuadXEffector's B (d_phi = d_theta = 0.15, c_tau_f = 0.0196) row by row (1e-15)."""
    if not pm_available():
        pytest.skip("pymulticopter is not installed")
    from pymulticopter.model import QuadXEffector

    from benchmarks.pm_source import effector_matrix, hover_speed, vehicle_params

    p = vehicle_params()
    assert (p.mass, p.gravity, p.thrust_factor) == (MASS, G, B)
    assert p.drag_factor == pytest.approx(C * B, rel=1e-15)
    np.testing.assert_allclose(p.inertia, J, rtol=1e-15)
    np.testing.assert_allclose(p.rotor_positions, POS_FLU, atol=1e-15)
    np.testing.assert_allclose(p.rotor_spins, SPINS)
    assert hover_speed() == pytest.approx(HOVER, rel=1e-12)
    assert HOVER == pytest.approx(2977.47, abs=0.01)
    theirs = QuadXEffector(D, D, C).B
    np.testing.assert_allclose(effector_matrix(), theirs, atol=1e-15)
    ours = np.zeros((4, 4))          # (f, tau) FRD per unit thrust of each rotor, from quadsim
    for i, (r, s) in enumerate(zip(p.rotor_positions, p.rotor_spins)):
        tau = np.cross(r, [0, 0, 1.0]) + np.array([0, 0, -s * p.drag_factor / B])
        ours[:, i] = np.concatenate([[1.0], FLIP @ tau])
    np.testing.assert_allclose(ours, theirs, atol=1e-15)


def test_case_list_frozen_and_mapped_to_the_library():
    """The 20 frozen cases, the same on a second draw: 6 no-effect, 12 in-library, 2
    outside; seeds apart from the references'; each in-library truth a library effect named
    by its true difference (no shared effects); the draws within the module table; the bias
    5-15 % of m g / 4 = 10.64 N on one motor."""
    if not pm_available():
        pytest.skip("pymulticopter is not installed")
    from benchmarks import pm_cases

    cases = check_case_table(pm_cases, (6, 12, 2), ())
    assert pm_cases.shared_effects() == []
    arm = np.hypot(H, H)
    assert pm_cases.rotor_distance() == pytest.approx(0.10607, abs=1e-5)
    check_drawn(cases, MASS, arm, {"mass": (0.05, 0.2), "payload": ((0.3, 0.8), (0.02, 0.06)),
                                   "com": (0.03, 0.1)})
    [bias] = [c["effects"]["bias"] for c in cases if "bias" in c["effects"]]
    assert bias[0] in (1, 2, 3, 4) and 0.05 <= abs(bias[1]) / (MASS * G / 4) <= 0.15


@needs_pm
def test_hover_and_random_states_obey_newton_euler():
    """At the hover thrust m g / 4 per rotor (its float32 g), level and still: no
    acceleration (1e-12). At
    random attitudes, body rates and thrusts: pymulticopter's plant under pm_source.wrench
    equals the Newton-Euler closed form in our frames (1e-9)."""
    from scipy.spatial.transform import Rotation

    alpha, acc = _derivative(_job(), np.full(4, MASS * G32 / 4))
    np.testing.assert_allclose(np.concatenate([alpha, acc]), 0.0, atol=1e-12)
    rng = np.random.default_rng(3)
    for _ in range(5):
        rot = Rotation.from_euler("xyz", rng.uniform(-0.5, 0.5, 3)).as_matrix()
        w = rng.uniform(-2, 2, 3)
        thrusts = MASS * G / 4 * rng.uniform(0.7, 1.3, 4)
        alpha, acc = _derivative(_job(), thrusts, rot, w)
        expect_alpha, expect_acc = _newton_euler(thrusts, rot, w)
        np.testing.assert_allclose(alpha, expect_alpha, atol=1e-9)
        np.testing.assert_allclose(acc, expect_acc, atol=1e-9)


@needs_pm
def test_case_handles_change_the_physics_by_the_stated_amount():
    """Level and still at the hover thrust, in our frames: a CoM at (cx, cy) gives J^-1 (-cy m
    g, cx m g, 0) (1e-9); motor 1 (front right) at gain 0.9 gives a_z = -0.1 g / 4 and the
    torques (h, h, c_tau_f) 0.1 m g / 4 (1e-9); a bias of +1 N on motor 3 (front left) gives
    a_z = 1 / m and J alpha = (h, -h, c_tau_f) x 1 N (1e-9); rate damping k at
    a roll rate of 1 rad/s gives -k / Ixx (1e-12); a body torque (0.01, -0.02, 0) N m at 1 Hz
    gives J^-1 of it a quarter period in (1e-12)."""
    hover = np.full(4, MASS * G / 4)
    c = np.array([0.006, -0.004, 0.0])
    alpha, _ = _derivative(_job(com=c), hover)
    np.testing.assert_allclose(alpha, np.linalg.solve(J, [-c[1] * MASS * G, c[0] * MASS * G,
                                                          0.0]), atol=1e-9)
    alpha, acc = _derivative(_job(alp=np.array([0.9, 1.0, 1.0, 1.0])), hover)
    assert acc[2] == pytest.approx(-0.1 * G / 4 + G - G32, abs=1e-9)
    np.testing.assert_allclose(J @ alpha, np.array([H, H, C]) * 0.1 * MASS * G / 4, atol=1e-9)
    alpha, acc = _derivative(_job(rho=np.array([0.0, 0.0, 1.0, 0.0])), hover)
    assert acc[2] == pytest.approx(1.0 / MASS + G - G32, abs=1e-9)
    np.testing.assert_allclose(J @ alpha, np.array([H, -H, C]), atol=1e-9)
    k = 0.02
    alpha, _ = _derivative(_job(rate_damping=np.array([k, k, k / 3])), hover,
                           w_flu=(1.0, 0.0, 0.0))
    np.testing.assert_allclose(alpha, [-k / J[0, 0], 0.0, 0.0], atol=1e-12)
    torque = np.array([0.01, -0.02, 0.0])
    alpha, _ = _derivative(_job(torque=torque, torque_hz=1.0), hover, t=0.25)
    np.testing.assert_allclose(alpha, np.linalg.solve(J, torque), atol=1e-12)


@needs_pm
def test_its_integrator_on_polynomial_motion():
    """pysimenv's "RK4" (make_plant's Simulator) with the thrusts held. Its third stage steps
    x0 + dt/2 k3 where RK4 has x0 + dt k3 (``StateVariable.rk4_update_3``), so a position
    under a constant acceleration a gains dt v + 5/12 a dt^2 a step (RK4: 1/2, exact): all
    four rotors off for 50 steps of 2 ms falls g dt^2 (N (N - 1) / 2 + 5 N / 12) = 0.0488616 m
    (1e-12; g t^2 / 2 = 0.049025 m: a lag of dt / 12 of the position behind the velocity,
    kept: the simulator's own); the velocity and body rates are exact;
    rotor 1, 2 (the counter-clockwise pair) at +1 N each over the hover share spins the
    vehicle up at 2 c_tau_f / Izz rad/s^2 about FLU -z (their reaction), 0.1 s: -0.0284677
    rad/s (1e-12), and lifts it at 2 / m m/s^2."""
    from benchmarks.pm_source import make_plant

    sim, _, dyn = make_plant(_job(), (0.0, 0.0, -1.0))
    for _ in range(50):
        sim.step(0.002, thrusts=np.zeros(4))
    n, dt = 50, 0.002
    fall = G32 * dt ** 2 * (n * (n - 1) / 2 + 5 * n / 12)
    assert dyn.state("p")[2] - (-1.0) == pytest.approx(fall, abs=1e-12)
    assert fall == pytest.approx(0.0488616, abs=1e-7)
    assert dyn.state("v")[2] == pytest.approx(G32 * n * dt, abs=1e-12)
    sim, _, dyn = make_plant(_job(), (0.0, 0.0, -1.0))
    thrusts = np.full(4, MASS * G / 4) + np.array([1.0, 1.0, 0.0, 0.0]) * 1.0
    torques = (np.array([-H, H, H, -H]) @ thrusts, np.array([H, -H, H, -H]) @ thrusts)
    assert torques == pytest.approx((0.0, 0.0), abs=1e-12)
    for _ in range(50):
        sim.step(0.002, thrusts=thrusts)
    w_z = -(FLIP @ dyn.state("omega"))[2]
    assert w_z == pytest.approx(2 * C / J[2, 2] * 0.1, abs=1e-12)
    assert w_z == pytest.approx(0.0284677, abs=1e-7)
    assert -(dyn.state("v")[2]) == pytest.approx((2.0 / MASS + G - G32) * 0.1, abs=1e-12)


@needs_pm
def test_flights_agree_with_quadsims_model():
    """A nominal flight (2.1 s logged, sensor noise on): quadsim's residual wrench of its log
    with no shared effects below 1.5 % of the weight (forces) and of weight x rotor distance
    (torques) RMS, unit quaternions near level, commands in 0..1 = speed / 5000. Without
    sensor noise (1 s, nominal and +0.3 kg): per sample the logged specific force times the
    flight's mass is b sum Omega^2 along body z (1e-6 N: no drag), the rotor speeds within
    15 % of hover. (Its position loop has no acceleration feed-forward: over 0.5 s the mean
    thrust is 0.90-1.08 of the weight, so the shared helper's 5 % mean check is not used.)"""
    from benchmarks.pm_cases import rotor_distance
    from benchmarks.pm_source import FlightSpec, pm_flights, vehicle_params
    from benchmarks.simlog import Sensors
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import residuals

    quiet = Sensors(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    specs = [FlightSpec(seed=5, speed=0.8, duration=2.1),
             FlightSpec(seed=4, duration=1.0, sensors=quiet),
             FlightSpec(seed=6, duration=1.0, sensors=quiet, effects={"mass": 0.3})]
    (log, truth), (bare, _), (heavy, _) = pm_flights(specs, workers=1)
    assert truth["effects"] == {} and truth["source"] == "pymulticopter"
    assert log.t[1] == pytest.approx(1.0 / 500) and np.all(log.quat[:, 0] > 0.9)
    np.testing.assert_allclose(np.linalg.norm(log.quat, axis=1), 1.0, atol=1e-9)
    assert np.all((log.rotor_command >= 0) & (log.rotor_command <= 1))
    params = vehicle_params()
    weight = params.mass * params.gravity
    r = residuals(prepare([log], params)[0].fit, params, [], rotor_channel=False)
    rms = np.sqrt(np.mean(r ** 2, axis=0))
    assert np.all(rms[:3] < 0.015 * weight), rms
    assert np.all(rms[3:6] < 0.015 * weight * rotor_distance()), rms
    for flight, mass in ((bare, MASS), (heavy, MASS + 0.3)):
        force = mass * flight.accel
        np.testing.assert_allclose(force[:, 0:2], 0.0, atol=1e-6)
        np.testing.assert_allclose(force[:, 2], B * np.sum(flight.rotor_speed ** 2, axis=1),
                                   atol=1e-6)
        assert np.all(np.abs(flight.rotor_speed / HOVER - 1) < 0.15)
        np.testing.assert_allclose(flight.rotor_command, flight.rotor_speed / 5000.0,
                                   rtol=1e-12)
