"""The Drake flight source (benchmarks.drake_source, drake_cases): the parameter set against
closed forms of QuadrotorPlant()'s values, the frozen case list, and -- with Drake installed
(``pip install -e '.[drake]'``) -- the diagram's accelerations against Drake's own
QuadrotorPlant and against Newton-Euler closed forms (hover, a CoM off the centre, a weak
rotor, wind on the drag), the rotor lag's step response, Drake's integrator against the free
fall's closed form with linear drag, and one short flight's log against the source's force
law."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.drake_source import drake_available
from benchmarks.tests._helpers import check_case_table, check_drawn, quiet_flight

needs_drake = pytest.mark.skipif(not drake_available(), reason="Drake is not installed")

#: QuadrotorPlant() in drake 1.51.1 (the Skydio 2 values)
MASS, G, L, KM = 0.775, 9.81, 0.15, 0.0245
J = np.diag([0.0015, 0.0025, 0.0035])
#: 6.11e-8 N/RPM^2 in N s^2/rad^2
B = 6.11e-8 * (60 / (2 * np.pi)) ** 2
HOVER = np.sqrt(MASS * G / 4 / B)                  # rad/s


def _job(**changes):
    """A flight job (drake_source._job's fields) with the nominal values and ``changes``."""
    from benchmarks.drake_source import DRAG_RATE

    job = {"mass": MASS, "com": np.zeros(3), "J": J.copy(), "rotor_scale": np.ones(4),
           "motor_tau": 0.0, "drag": MASS * np.diag(DRAG_RATE), "wind": np.zeros(3),
           "rate_damping": np.zeros(3), "torque": np.zeros(3), "torque_hz": 0.0,
           "force": 0.0, "force_hz": 0.0}
    job.update(changes)
    return job


def _accel(job, speeds, rpy=(0.0, 0.0, 0.0), w_world=(0.0, 0.0, 0.0), v=(0.0, 0.0, 0.0)):
    """(angular acceleration world, origin acceleration world) of the diagram of ``job`` at
    rotor speed commands ``speeds`` (rad/s) and the given attitude, rates and velocity."""
    from pydrake.math import RigidTransform, RollPitchYaw
    from pydrake.multibody.math import SpatialVelocity

    from benchmarks.drake_source import build

    flight = build(job)
    flight.plant.SetFreeBodyPose(flight.plant_context, flight.body,
                                 RigidTransform(RollPitchYaw(*rpy), [0.0, 0.0, 1.0]))
    flight.plant.SetFreeBodySpatialVelocity(flight.plant_context, flight.body,
                                            SpatialVelocity(np.asarray(w_world, float),
                                                            np.asarray(v, float)))
    flight.diagram.get_input_port(0).FixValue(flight.context, np.asarray(speeds, float))
    vdot = flight.plant.get_generalized_acceleration_output_port().Eval(flight.plant_context)
    return vdot[0:3], vdot[3:6]


@needs_drake
def test_parameter_set_closed_form():
    """Drake's values as quadsim's set: m 0.775 kg, J diag(0.0015, 0.0025, 0.0035), rotors at
    (L, 0), (0, L), (-L, 0), (0, -L), spins -1, +1, -1, +1 (the 1st and 3rd rotors' moment is
    +kM per N: a clockwise rotor's reaction); b = 5.5717e-6 N s^2/rad^2, d = 0.0245 b; the
    hover speed sqrt(m g / 4 b) = 584.07 rad/s and the top speed sqrt(2.25) of it (1e-12)."""
    from benchmarks.drake_source import drake_params, hover_speed, max_speed, vehicle_params

    p = drake_params()
    assert (p["m"], p["g"], p["L"], p["kF"], p["kM"]) == (MASS, G, L, 1.0, KM)
    np.testing.assert_allclose(p["I"], J, rtol=1e-12)
    params = vehicle_params()
    assert params.thrust_factor == pytest.approx(5.571651888492154e-06, rel=1e-12)
    assert params.drag_factor == pytest.approx(KM * B, rel=1e-12)
    assert hover_speed() == pytest.approx(HOVER, rel=1e-12)
    assert HOVER == pytest.approx(584.068, abs=1e-3)
    assert max_speed() == pytest.approx(1.5 * HOVER, rel=1e-12)
    np.testing.assert_allclose(params.rotor_positions,
                               L * np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]]),
                               atol=1e-15)
    np.testing.assert_allclose(params.rotor_spins, [-1, 1, -1, 1])
    assert params.mass * params.gravity == pytest.approx(4 * params.thrust_factor * HOVER ** 2,
                                                         rel=1e-12)


def test_case_list_frozen_and_mapped_to_the_library():
    """The 28 frozen cases, the same on a second draw: 6 no-effect, 20 in-library, 2
    outside; seeds apart from the references'; each in-library truth (not a delay) a library
    effect named by its true difference on top of the shared drag; the draws within the
    module table."""
    if not drake_available():
        pytest.skip("Drake is not installed")
    from benchmarks import drake_cases
    from benchmarks.drake_source import DRAG_RATE

    cases = check_case_table(drake_cases, (6, 20, 2), ("rotor_drag",))
    check_drawn(cases, MASS, L, {"mass": (0.05, 0.2), "payload": ((0.04, 0.12), (0.01, 0.04)),
                                 "com": (0.03, 0.1), "motor_tau": (0.02, 0.06),
                                 "drag_scale": (1.5, 2.5), "wind": (1.0, 3.0)})
    [drag] = drake_cases.shared_effects()
    assert drag.coefficient == pytest.approx(MASS * DRAG_RATE[0] / (4 * HOVER), rel=1e-12)
    assert drag.axial_coefficient == pytest.approx(MASS * DRAG_RATE[2] / (4 * HOVER),
                                                   rel=1e-12)


@needs_drake
def test_hover_and_quadrotor_plant_agree():
    """At the hover speed, level and still: no acceleration (1e-12). At random attitudes,
    rates and rotor speeds (no drag, the body at rest in translation): the diagram's origin
    acceleration equals Drake's own QuadrotorPlant's with inputs b Omega^2 (1e-9), and its
    angular acceleration the Newton-Euler closed form J^-1 (tau - w x J w) with tau = (L b
    (O2^2 - O4^2), L b (O3^2 - O1^2), kM b (O1^2 - O2^2 + O3^2 - O4^2)) in body axes (1e-9)."""
    from pydrake.examples import QuadrotorPlant
    from pydrake.math import RollPitchYaw

    alpha, acc = _accel(_job(), np.full(4, HOVER))
    np.testing.assert_allclose(np.concatenate([alpha, acc]), 0.0, atol=1e-12)
    rng = np.random.default_rng(3)
    quad = QuadrotorPlant()
    for _ in range(5):
        rpy = rng.uniform(-0.5, 0.5, 3)
        w_world = rng.uniform(-2, 2, 3)
        speeds = HOVER * rng.uniform(0.7, 1.3, 4)
        alpha, acc = _accel(_job(drag=np.zeros((3, 3))), speeds, rpy, w_world)
        ctx = quad.CreateDefaultContext()
        rates = RollPitchYaw(rpy).CalcRpyDtFromAngularVelocityInParent(w_world)
        ctx.SetContinuousState(np.concatenate([[0, 0, 1.0], rpy, np.zeros(3), rates]))
        quad.get_input_port(0).FixValue(ctx, B * speeds ** 2)
        deriv = quad.EvalTimeDerivatives(ctx).CopyToVector()
        np.testing.assert_allclose(acc, deriv[6:9], atol=1e-9)
        rot = RollPitchYaw(rpy).ToRotationMatrix().matrix()
        w = rot.T @ w_world
        f = B * speeds ** 2
        tau = np.array([L * (f[1] - f[3]), L * (f[2] - f[0]), KM * (f[0] - f[1] + f[2] - f[3])])
        expect = np.linalg.solve(J, tau - np.cross(w, J @ w))
        np.testing.assert_allclose(rot.T @ alpha, expect, atol=1e-9)


@needs_drake
def test_case_handles_change_the_physics_by_the_stated_amount():
    """Level and still at the hover speed: a CoM at (cx, cy) gives the angular acceleration
    J^-1 (-cy m g, cx m g, 0) (1e-9); rotor 2 at -10 % gives a_z = -0.1 g / 4 and the body
    torques (-0.1 L, 0, +0.1 kM) m g / 4 (1e-9); a wind (2, 1) m/s on the linear drag gives
    the acceleration (0.3 x 2, 0.3 x 1, 0) m/s^2 and twice that at drag x 2 (1e-12); a mass
    +10 % gives a_z = -g 0.1 / 1.1 (1e-12)."""
    c = np.array([0.006, -0.004, 0.0])
    alpha, _ = _accel(_job(com=c), np.full(4, HOVER))
    np.testing.assert_allclose(alpha, np.linalg.solve(J, [-c[1] * MASS * G, c[0] * MASS * G,
                                                          0.0]), atol=1e-9)
    alpha, acc = _accel(_job(rotor_scale=np.array([1.0, 0.9, 1.0, 1.0])), np.full(4, HOVER))
    assert acc[2] == pytest.approx(-0.1 * G / 4, abs=1e-9)
    np.testing.assert_allclose(J @ alpha, np.array([-0.1 * L, 0.0, 0.1 * KM]) * MASS * G / 4,
                               atol=1e-9)
    from benchmarks.drake_source import DRAG_RATE

    _, acc = _accel(_job(wind=np.array([2.0, 1.0, 0.0])), np.full(4, HOVER))
    np.testing.assert_allclose(acc, [DRAG_RATE[0] * 2, DRAG_RATE[1] * 1, 0.0], atol=1e-12)
    _, acc = _accel(_job(wind=np.array([2.0, 1.0, 0.0]),
                         drag=2 * MASS * np.diag(DRAG_RATE)), np.full(4, HOVER))
    np.testing.assert_allclose(acc, [4 * DRAG_RATE[0], 2 * DRAG_RATE[1], 0.0], atol=1e-12)
    _, acc = _accel(_job(mass=1.1 * MASS), np.full(4, HOVER))
    assert acc[2] == pytest.approx(-G * 0.1 / 1.1, abs=1e-12)


@needs_drake
def test_rotor_lag_step_and_free_fall_through_drakes_integrator():
    """A rotor lag of 50 ms: a step of the command from the hover speed to 1.1 x it reaches
    hover (1 + 0.1 (1 - e^-1)) after 50 ms (1e-5 relative: Drake's RK3 at its accuracy).
    With the rotors stopped, from rest: z(t) = z0 - g/r (t - (1 - e^-rt)/r) under the
    axial drag rate r = 0.1 /s, after 0.5 s (1e-6 m)."""
    from benchmarks.drake_source import DRAG_RATE, build

    flight = build(_job(motor_tau=0.05))
    flight.rotor_context.SetContinuousState(np.full(4, HOVER))
    flight.diagram.get_input_port(0).FixValue(flight.context, np.full(4, 1.1 * HOVER))
    flight.simulator.AdvanceTo(0.05)
    speed = flight.rotor_context.get_continuous_state_vector().CopyToVector()
    np.testing.assert_allclose(speed, HOVER * (1 + 0.1 * (1 - np.exp(-1))), rtol=1e-5)
    flight = build(_job())
    flight.diagram.get_input_port(0).FixValue(flight.context, np.zeros(4))
    z0 = float(flight.plant.GetPositions(flight.plant_context)[6])
    flight.simulator.AdvanceTo(0.5)
    r, t = DRAG_RATE[2], 0.5
    z = float(flight.plant.GetPositions(flight.plant_context)[6])
    assert z == pytest.approx(z0 - G / r * (t - (1 - np.exp(-r * t)) / r), abs=1e-6)


@needs_drake
def test_short_flight_log_obeys_the_source_force_law():
    """A 1-s nominal flight with no sensor noise: per sample, the logged specific force times
    m equals the thrust b sum Omega^2 on z and the drag -m r v_body on every axis (1e-6 N:
    the log's specific force is the plant's own acceleration); the command is the speed over
    the top speed; the rotor speeds stay within 10 % of hover."""
    from benchmarks.drake_source import DRAG_RATE, drake_flights, max_speed

    log, v_body = quiet_flight(drake_flights, "drake")
    force = MASS * log.accel
    thrust = B * np.sum(log.rotor_speed ** 2, axis=1)
    drag = -MASS * np.asarray(DRAG_RATE) * v_body
    np.testing.assert_allclose(force[:, 0:2], drag[:, 0:2], atol=1e-6)
    np.testing.assert_allclose(force[:, 2], thrust + drag[:, 2], atol=1e-6)
    np.testing.assert_allclose(log.rotor_command * max_speed(), log.rotor_speed, rtol=1e-12)
    assert np.all(np.abs(log.rotor_speed / HOVER - 1) < 0.1)
