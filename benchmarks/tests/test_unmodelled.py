"""Issue 47's out-of-library effects (:mod:`benchmarks.unmodelled`) against their closed forms
on sample states, and the case lists that fly them (appended: no earlier seed or cache key
moves)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.unmodelled import FrameMoment, RotorWake, draw_unmodelled
from quadsim.effects.base import EffectContext
from quadsim.vehicle.params import load_params
from quadsim.vehicle.rotors import rotor_wrench


def _ctx(params, air_body, yaw: float = 0.0):
    """One sample: level attitude at ``yaw`` (rad), body-frame air velocity ``air_body``
    (m/s, turned into the world frame), hover rotor speeds."""
    c, s = np.cos(yaw), np.sin(yaw)
    world = np.array([[c * air_body[0] - s * air_body[1], s * air_body[0] + c * air_body[1],
                       air_body[2]]])
    quat = np.array([[np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]])
    speed = np.full((1, params.rotor_count), 0.6 * params.max_speed)
    return EffectContext(np.zeros(1), np.zeros((1, 3)), world, quat, np.zeros((1, 3)), world,
                         speed, np.zeros_like(speed), params)


def test_rotor_wake_forward_flight_rear_pair_of_an_x_quad():
    """Crazyflie (X, hubs at (+-35.4, +-35.4) mm), 1.5 m/s along body +x, k = 0.03 s/m: the
    two rear rotors (x < 0) keep 1 - 0.03 x 1.5 / sqrt(2) = 0.968180 of their thrust, the
    front pair all of it; yawed 90 deg with the same body air velocity, the same."""
    params = load_params("crazyflie21")
    rear = params.rotor_positions[:, 0] < 0
    expected = np.where(rear, 1.0 - 0.03 * 1.5 / np.sqrt(2.0), 1.0)
    for yaw in (0.0, np.pi / 2):
        scale = RotorWake(k_wake=0.03).loads(_ctx(params, [1.5, 0.0, 0.3], yaw)).thrust_scale
        np.testing.assert_allclose(scale[0], expected, rtol=1e-12)
    assert expected[rear] == pytest.approx([0.9681802, 0.9681802], abs=1e-7)


def test_rotor_wake_moment_has_the_flapping_form_in_every_direction():
    """On four hubs 90 deg apart at equal speeds the loss's moment is k b Omega^2 L |v| about
    -(e_z x v) whatever the direction of flight (module doc): the testbed ("+", L = 0.197667
    m) flying along x and along the diagonal, through quadsim's own rotor wrench."""
    params = load_params("physical")
    arm = 0.197667
    for direction in (np.array([1.0, 0.0]), np.array([1.0, 1.0]) / np.sqrt(2.0)):
        v = 1.2 * direction
        ctx = _ctx(params, [v[0], v[1], 0.0])
        loads = RotorWake(k_wake=0.04).loads(ctx)
        torque = rotor_wrench(params, ctx.rotor_speed, thrust_scale=loads.thrust_scale)[1]
        nominal = rotor_wrench(params, ctx.rotor_speed)[1]
        thrust = params.thrust_factor * ctx.rotor_speed[0, 0] ** 2
        expected = -0.04 * thrust * arm * np.array([-v[1], v[0]])
        # roll/pitch (the yaw part is the lost drag torque, spin-signed)
        np.testing.assert_allclose((torque - nominal)[0, :2], expected, atol=1e-12)
        # the thrust lost: |cos psi| + |sin psi| rotors' worth of k |v| (psi from a hub)
        lost = thrust * (4.0 - loads.thrust_scale.sum())
        psi = np.arctan2(v[1], v[0])
        assert lost == pytest.approx(0.04 * 1.2 * thrust * (abs(np.cos(psi)) + abs(np.sin(psi))))


def test_frame_moment_closed_form():
    """tau = -0.5 rho C_dA h |v| (e_z x v): rho 1.225, C_dA 0.2 m^2, h = -0.08 m (below the
    CoM), body air velocity (1, -2, 0.5) m/s (|v| = 2.291288): 0.5 x 1.225 x 0.2 x 0.08
    x 2.291288 = 0.0224546 times (2, 1, 0) N m: nose down in forward flight."""
    params = load_params("physical")
    assert params.air_density == pytest.approx(1.225)
    for yaw in (0.0, 1.0):
        loads = FrameMoment(cd_area=0.2, height=-0.08).loads(_ctx(params, [1.0, -2.0, 0.5], yaw))
        np.testing.assert_allclose(loads.torque_body[0], [0.0449093, 0.0224546, 0.0], rtol=1e-5)
        np.testing.assert_array_equal(loads.force_world, 0.0)
        np.testing.assert_array_equal(loads.thrust_scale, 1.0)


def test_draws_are_the_documented_sizes():
    """k_wake 0.02-0.04 s/m; the frame's drag 1-4 % of the weight at 1.5 m/s on a lever of
    25-50 % of the arm (testbed 0.197667 m), above or below."""
    params = load_params("physical")
    rng = np.random.default_rng(0)
    for _ in range(50):
        (wake,) = draw_unmodelled("rotor_wake", params, rng)
        (frame,) = draw_unmodelled("frame_moment", params, rng)
        assert 0.02 <= wake.k_wake <= 0.04
        drag = 0.5 * params.air_density * frame.cd_area * 1.5 ** 2 / params.weight
        assert 0.01 <= drag <= 0.04
        assert 0.25 * 0.197667 <= abs(frame.height) <= 0.5 * 0.197667
    with pytest.raises(ValueError, match="no out-of-library effect"):
        draw_unmodelled("gust", params, rng)


def test_case_lists_append_the_new_cases_only():
    """Independent cases: 64 as before (the first and last seeds kept) + 6 pipeline cases
    seeds 5064-5069, scored as outside; their cache keys carry their module's hash, no other
    key does. Self-generated: 76 as before + 4 outside cases seeds 1076-1079."""
    from benchmarks import gap_benchmark
    from benchmarks.cases import _unmodelled_hash, case_list, scored_kind, unmodelled_cases

    cases = case_list()
    assert len(cases) == 70
    assert (cases[0]["seed"], cases[63]["seed"], cases[63]["truth"]) == (5000, 5063,
                                                                       "rate_damping")
    new = unmodelled_cases()
    assert [(c["source"], c["vehicle"], c["truth"], c["seed"]) for c in new] == [
        ("pipeline", "physical", "rotor_wake", 5064),
        ("pipeline", "crazyflie21", "rotor_wake", 5065),
        ("pipeline", "physical", "frame_moment", 5066),
        ("pipeline", "crazyflie21", "frame_moment", 5067),
        ("pipeline", "physical", "gyro_misalignment", 5068),
        ("pipeline", "crazyflie21", "gyro_misalignment", 5069)]
    assert all(scored_kind(c) == "outside" for c in new)
    assert all(_unmodelled_hash(c) == {} for c in cases[:64])
    assert all(len(_unmodelled_hash(c)["unmodelled"]) == 16 for c in new[:4])
    assert all(list(_unmodelled_hash(c)) == ["imu_error"] for c in new[4:])
    self_cases = gap_benchmark.case_list()
    assert len(self_cases) == 80
    assert [(c["truth"], c["seed"], c["kind"]) for c in self_cases[76:]] == [
        ("rotor_wake", 1076, "outside"), ("rotor_wake", 1077, "outside"),
        ("frame_moment", 1078, "outside"), ("frame_moment", 1079, "outside")]
    assert self_cases[75]["seed"] == 1075


def test_gyro_misalignment_turns_the_logged_rates():
    """Rodrigues against closed forms: 2 deg about z turns a roll rate of 1 rad/s into
    (cos 2 deg, sin 2 deg, 0) = (0.999391, 0.034899, 0); 90 deg about k = (1, 1, 1)/sqrt(3):
    R e_x = k x e_x + (k . e_x) k = (1/3, 1/3 + 1/sqrt(3), 1/3 - 1/sqrt(3)), R R^T = I,
    R k = k; the flight's other signals stay; draws turn by 1-3 deg."""
    from benchmarks.imu_error import GyroMisalignment, draw_gyro_misalignment, rotation_matrix
    from quadsim.logs.flightlog import FlightLog

    rates = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    log = FlightLog(np.array([0.0, 0.004]), np.zeros((2, 3)),
                    np.tile([1.0, 0.0, 0.0, 0.0], (2, 1)), body_rate=rates)
    turned = GyroMisalignment((0.0, 0.0, np.radians(2.0))).apply(log)
    np.testing.assert_allclose(turned.body_rate, [[0.9993908, 0.0348995, 0.0], [0, 0, 2.0]],
                               atol=1e-7)
    np.testing.assert_array_equal(turned.quat, log.quat)
    k = np.ones(3) / np.sqrt(3.0)
    r = rotation_matrix(np.pi / 2 * k)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(r @ k, k, atol=1e-12)
    np.testing.assert_allclose(r[:, 0], [1 / 3, 1 / 3 + 1 / np.sqrt(3), 1 / 3 - 1 / np.sqrt(3)],
                               atol=1e-12)
    rng = np.random.default_rng(1)
    for _ in range(50):
        (gyro,) = draw_gyro_misalignment(load_params("crazyflie21"), rng)
        assert 1.0 <= np.degrees(np.linalg.norm(gyro.rotvec)) <= 3.0
