"""The Robotics Toolbox flight source (benchmarks.rtb_source, rtb_cases): the frame
conversion at the boundary (NED/FRD, ZYX Euler angles -> world z up, body FLU, quaternion w
first) against closed forms, and -- with roboticstoolbox-python installed (``pip install -e
'.[rtb]'``) -- the parameter set and hover thrust = M g from the toolbox's model dict, its
``MultiRotor`` block's flapping drag, wind and case handles against closed forms, the frozen
case list, and one short flight's log against the source's force law and motor lag."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.rtb_source import FLIP, flu_state, rtb_available
from benchmarks.tests._helpers import check_case_table, check_drawn, quiet_flight
from quadsim.core.frames import quat_to_rotmat

needs_rtb = pytest.mark.skipif(not rtb_available(), reason="roboticstoolbox is not installed")

#: roboticstoolbox-python 1.5.0 blocks/quad_model.py
M, G, D, H, R, RHO, CT = 4.0, 9.81, 0.315, -0.007, 0.165, 1.184, 0.0048
B = CT * RHO * np.pi * R ** 2 * R ** 2                       # N s^2/rad^2
K = CT * np.sqrt(CT / 2) * RHO * np.pi * R ** 2 * R ** 3      # N m s^2/rad^2
J = np.diag([0.082, 0.082, 0.149])
HOVER = np.sqrt(M * G / 4 / B)                                # rad/s
#: the flapping force per rotor speed per air speed, b (8/3 theta0 + 2 theta1) / r
FLAP = B * (8 / 3 * np.radians(14.6) + 2 * np.radians(6.8 - 14.6)) / R


def _rot(yaw, pitch, roll):
    """Rz(yaw) Ry(pitch) Rx(roll), written out."""
    cz, sz, cy, sy, cx, sx = (np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch),
                              np.cos(roll), np.sin(roll))
    return (np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1.0]])
            @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
            @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]]))


def test_frame_conversion_closed_form():
    """NED position (1, 2, -3) is (1, -2, 3) z up; NED velocity and FRD rates flip y and z;
    the FLU attitude of NED (yaw, pitch, roll) is FLIP Rz Ry Rx FLIP (1e-12), a unit
    quaternion with w first; a nose turned 0.3 rad toward +y NED (east) is a yaw of -0.3 z
    up."""
    rng = np.random.default_rng(5)
    for _ in range(5):
        x = np.zeros(12)
        x[0:3] = (1.0, 2.0, -3.0)
        x[3:6] = rng.uniform(-0.6, 0.6, 3)
        x[6:9] = rng.uniform(-2, 2, 3)
        x[9:12] = rng.uniform(-2, 2, 3)
        pos, vel, quat, rate = flu_state(x)
        np.testing.assert_allclose(pos, [1.0, -2.0, 3.0], atol=1e-15)
        np.testing.assert_allclose(vel, x[6:9] * [1, -1, -1], atol=1e-15)
        np.testing.assert_allclose(rate, x[9:12] * [1, -1, -1], atol=1e-15)
        assert np.linalg.norm(quat) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(quat_to_rotmat(quat), FLIP @ _rot(*x[3:6]) @ FLIP,
                                   atol=1e-12)
    x = np.zeros(12)
    x[3] = 0.3
    heading = quat_to_rotmat(flu_state(x)[2])[:, 0]
    np.testing.assert_allclose(heading, [np.cos(0.3), -np.sin(0.3), 0.0], atol=1e-12)


@needs_rtb
def test_parameter_set_and_hover_from_the_model_dict():
    """The model dict's b = Ct rho A r^2 and k = Cq rho A r^3 (Cq = Ct sqrt(Ct / 2)); the set:
    M 4 kg, J, rotors at FLIP D_i ((d, 0), (0, -d), (-d, 0), (0, d), 7 mm above the CoM),
    spins +1, -1, +1, -1; the block at four hover speeds sqrt(M g / 4 b) = 860.98 rad/s,
    level and still: no acceleration (1e-12): the thrust is M g."""
    from benchmarks.rtb_source import hover_speed, make_plant, rtb_model, vehicle_params

    q = rtb_model()
    assert (q["M"], q["g"], q["d"], q["h"], q["r"]) == (M, G, D, H, R)
    assert q["b"] == pytest.approx(B, rel=1e-12) and q["k"] == pytest.approx(K, rel=1e-12)
    params = vehicle_params()
    np.testing.assert_allclose(params.inertia, J, rtol=1e-12)
    np.testing.assert_allclose(params.rotor_positions,
                               [[D, 0, -H], [0, -D, -H], [-D, 0, -H], [0, D, -H]], atol=1e-15)
    np.testing.assert_allclose(params.rotor_spins, [1, -1, 1, -1])
    assert hover_speed() == pytest.approx(HOVER, rel=1e-12)
    assert HOVER == pytest.approx(860.984, abs=1e-3)
    assert 4 * B * HOVER ** 2 == pytest.approx(M * G, rel=1e-12)
    plant = make_plant(_job())
    x = np.zeros(12)
    x[2] = -1.5
    d = plant.deriv(0.0, [np.array([1.0, -1.0, 1.0, -1.0]) * HOVER], x)
    np.testing.assert_allclose(d, 0.0, atol=1e-12)


def _job(**changes):
    """A flight job (rtb_source._job's fields) with the nominal values and ``changes``."""
    job = {"mass": M, "com": np.zeros(3), "J": J.copy(), "ct_scale": 1.0,
           "rotor_scale": np.ones(4), "motor_tau": 0.03, "flap": 1.0, "wind": np.zeros(3),
           "rate_damping": np.zeros(3), "torque": np.zeros(3), "torque_hz": 0.0,
           "force": 0.0, "force_hz": 0.0}
    job.update(changes)
    return job


def _accel(job, v_ned=(0.0, 0.0, 0.0)):
    """(acceleration, angular acceleration) in quadsim's frames of the block through
    rtb_source.derivative, level at yaw 0, at four hover speeds and NED velocity ``v_ned``."""
    from benchmarks.rtb_source import derivative, make_plant

    y = np.zeros(16)
    y[2], y[6:9], y[12:16] = -1.5, v_ned, HOVER
    d = derivative(make_plant(job), job, 0.0, y, np.full(4, HOVER))
    return FLIP @ d[6:9], FLIP @ d[9:12]


@needs_rtb
def test_block_flapping_wind_and_case_handles():
    """Level at yaw 0 and hover speeds: at 1 m/s north the flapping drag is -4 FLAP Omega v
    / M (1e-4: the block's 1 / (1 - mu^2 / 2)), twice that at blade angles x 2, none with a
    wind of the same 1 m/s; a CoM at (cx, cy) (FLU) gives J^-1 (-cy M g, cx M g, 0); every
    Ct x 0.9 gives a_z = -0.1 g, rotor 2 x 0.9 -0.1 g / 4 and the torques (0.1 d, 0, -0.1 k /
    b) M g / 4 (rotor 2 on -y, spin -1: a tenth of its +k Omega^2 about z lost); a mass
    +10 %: a_z = -g 0.1 / 1.1 (1e-9)."""
    acc, _ = _accel(_job(), (1.0, 0.0, 0.0))
    assert acc[0] == pytest.approx(-4 * FLAP * HOVER / M, rel=1e-4)
    acc2, _ = _accel(_job(flap=2.0), (1.0, 0.0, 0.0))
    assert acc2[0] == pytest.approx(2 * acc[0], rel=1e-4)
    acc, _ = _accel(_job(wind=np.array([1.0, 0.0, 0.0])), (1.0, 0.0, 0.0))
    np.testing.assert_allclose(acc, 0.0, atol=1e-12)
    c = np.array([0.02, -0.01, 0.0])
    _, alpha = _accel(_job(com=c))
    np.testing.assert_allclose(alpha, np.linalg.solve(J, [-c[1] * M * G, c[0] * M * G, 0.0]),
                               atol=1e-9)
    acc, _ = _accel(_job(ct_scale=0.9))
    assert acc[2] == pytest.approx(-0.1 * G, abs=1e-9)
    acc, alpha = _accel(_job(rotor_scale=np.array([1.0, 0.9, 1.0, 1.0])))
    assert acc[2] == pytest.approx(-0.1 * G / 4, abs=1e-9)
    np.testing.assert_allclose(J @ alpha, np.array([0.1 * D, 0.0, -0.1 * K / B]) * M * G / 4,
                               atol=1e-9)
    acc, _ = _accel(_job(mass=1.1 * M))
    assert acc[2] == pytest.approx(-G * 0.1 / 1.1, abs=1e-9)


@needs_rtb
def test_case_list_frozen_and_mapped_to_the_library():
    """The 28 frozen cases (drones-sim's table), the same on a second draw: 6 no-effect, 20
    in-library, 2 outside; each in-library truth (not a delay) named by its true difference on
    top of the shared motor lag and flapping drag; the draws within the module table; the
    shared effects' closed forms (30 ms; FLAP, nothing along the axis)."""
    from benchmarks import rtb_cases

    cases = check_case_table(rtb_cases, (6, 20, 2), ("motor_lag", "rotor_drag"))
    check_drawn(cases, M, D, {"mass": (0.05, 0.2), "payload": ((0.2, 0.6), (0.03, 0.1)),
                              "com": (0.03, 0.1), "motor_slow": (1.5, 2.5),
                              "drag_scale": (1.5, 2.5), "wind": (1.0, 3.0)})
    lag, drag = rtb_cases.shared_effects()
    assert lag.time_constant == pytest.approx(0.03, rel=1e-12)
    assert drag.coefficient == pytest.approx(FLAP, rel=1e-12)
    assert drag.axial_coefficient == 0.0


@needs_rtb
def test_short_flight_log_obeys_the_source_force_law():
    """A 1-s nominal flight with no sensor noise: quaternions near level, commands in 0..1;
    the logged specific force times M is the thrust b sum Omega^2 on z (0.2 %: the flapping
    tilt) and below 3 % of the weight in the plane (the flapping on the air speed and
    the body rates); the rotor speeds stay within 40 % of hover (28 % on this
    flight: the weave on a 4 kg vehicle) and follow the
    command through the motor lag as RK4 steps it (1e-9 relative)."""
    from benchmarks.rtb_source import CONTROL_HZ, MAX_SPEED, MOTOR_TAU, rtb_flights

    log, _ = quiet_flight(rtb_flights, "roboticstoolbox")
    assert np.all(log.quat[:, 0] > 0.9)
    assert np.all((log.rotor_command >= 0) & (log.rotor_command <= 1))
    thrust = B * np.sum(log.rotor_speed ** 2, axis=1)
    np.testing.assert_allclose(M * log.accel[:, 2], thrust, rtol=2e-3)
    assert np.all(np.abs(M * log.accel[:, :2]) < 0.03 * M * G)
    dev = np.abs(log.rotor_speed / HOVER - 1)
    assert np.all(dev < 0.4), dev.max()
    x = 1 / CONTROL_HZ / MOTOR_TAU
    a = x - x ** 2 / 2 + x ** 3 / 6 - x ** 4 / 24
    cmd = log.rotor_command * MAX_SPEED
    np.testing.assert_allclose(log.rotor_speed[1:], log.rotor_speed[:-1]
                               + a * (cmd[:-1] - log.rotor_speed[:-1]), rtol=1e-9)
