"""The analytic Newton–Euler engine against closed forms (free fall, constant thrust,
torque-free tumbling, an off-centre CoM) and the hover equilibrium."""

import numpy as np
import pytest

from quadsim.core.errors import InputError, SimulationError
from quadsim.core.frames import quat_to_rotmat
from quadsim.sim.analytic import BatchEffects, body_arrays, state_derivative
from quadsim.sim.engines import initial_state, simulate
from quadsim.sim.linear import hover_point
from quadsim.vehicle.params import load_params


@pytest.fixture(scope="module")
def physical():
    return load_params("physical")


def _hover_residual(params):
    x0, u0 = hover_point(params)
    y = np.concatenate([x0[0:6], [1.0, 0, 0, 0], np.zeros(3)])
    dy = state_derivative(0.0, y, body=body_arrays([params]),
                          effects=BatchEffects(None, [params]), command=u0[None])
    return dy[3:6], dy[10:13]


@pytest.mark.parametrize("name", ["physical", "computational", "crazyflie21"])
def test_hover_equilibrium_residual_below_1e9(name):
    accel, alpha = _hover_residual(load_params(name))
    assert np.abs(accel).max() <= 1e-9
    assert np.abs(alpha).max() <= 1e-9


def test_hover_with_offset_com_uses_unequal_speeds(physical):
    params = physical.replace(com=np.array([0.01, -0.005, 0.02]))
    _, speeds = hover_point(params)
    assert np.ptp(speeds) > 1.0      # the mixer shifts load to the rotors nearer the CoM
    accel, alpha = _hover_residual(params)
    assert np.abs(accel).max() <= 1e-9 and np.abs(alpha).max() <= 1e-9


def test_free_fall_is_a_parabola(physical):
    v0 = np.array([1.0, -2.0, 3.0])
    start = initial_state(position=(0, 0, 10), velocity=v0, body_rate=(0.3, -0.2, 0.1))
    traj = simulate(physical, engine="analytic", initial=start, duration=1.0,
                    rotor_speed_series=np.zeros((100, 4)))
    t = traj.t[:, None]
    expected = np.array([0, 0, 10]) + v0 * t + 0.5 * np.array([0, 0, -physical.gravity]) * t**2
    assert np.abs(traj.position - expected).max() <= 1e-9


def test_constant_collective_climb(physical):
    speed = 600.0
    traj = simulate(physical, engine="analytic", initial=initial_state(position=(0, 0, 1)),
                    duration=1.0, rotor_speed_series=np.full((100, 4), speed))
    accel = 4 * physical.thrust_factor * speed**2 / physical.mass - physical.gravity
    assert np.abs(traj.position[:, 2] - (1 + 0.5 * accel * traj.t**2)).max() <= 1e-9
    assert np.abs(traj.euler).max() <= 1e-12


def test_torque_free_tumbling_conserves_momentum_and_energy(physical):
    """Full inertia tensor with products of inertia: world angular momentum R I w and the
    kinetic energy 0.5 w.I w stay constant while the body tumbles."""
    inertia = np.array([[4e-3, 3e-4, -2e-4], [3e-4, 6e-3, 1e-4], [-2e-4, 1e-4, 9e-3]])
    params = physical.replace(inertia=inertia)
    start = initial_state(position=(0, 0, 0), body_rate=(3.0, 1.0, -2.0), euler=(0.2, -0.1, 1))
    traj = simulate(params, engine="analytic", initial=start, duration=2.0,
                    rotor_speed_series=np.zeros((200, 4)))
    momentum = np.einsum("nij,jk,nk->ni", quat_to_rotmat(traj.quat), inertia, traj.body_rate)
    energy = 0.5 * np.einsum("ni,ij,nj->n", traj.body_rate, inertia, traj.body_rate)
    assert np.abs(momentum - momentum[0]).max() <= 1e-9 * np.abs(momentum[0]).max()
    assert np.abs(energy - energy[0]).max() <= 1e-9 * energy[0]
    assert np.abs(traj.body_rate - traj.body_rate[0]).max() > 0.1   # it does tumble


def test_offset_com_flies_ballistic_while_origin_orbits(physical):
    """With rotors off the CoM (origin + R c) follows the free-fall parabola exactly, whatever
    the spin; the reported origin velocity is the CoM velocity minus R (w x c)."""
    com = np.array([0.02, -0.01, 0.03])
    params = physical.replace(com=com)
    start_rot = np.eye(3)
    w0 = np.array([0.0, 0.0, 5.0])
    v_com0 = np.array([0.5, 0.0, 2.0])
    start = initial_state(position=-start_rot @ com, velocity=v_com0 - np.cross(w0, com),
                          body_rate=w0)
    traj = simulate(params, engine="analytic", initial=start, duration=1.0,
                    rotor_speed_series=np.zeros((100, 4)))
    rot = quat_to_rotmat(traj.quat)
    com_world = traj.position + rot @ com
    t = traj.t[:, None]
    expected = v_com0 * t + 0.5 * np.array([0, 0, -physical.gravity]) * t**2
    assert np.abs(com_world - expected).max() <= 1e-9
    assert np.ptp(traj.position[:, 0] - com_world[:, 0]) > 0.01   # the origin does orbit


def test_batch_equals_single_runs(physical):
    series = np.stack([np.full((50, 4), 560.0), np.full((50, 4), 580.0)])
    start = initial_state(position=(0, 0, 1), euler=(0.1, 0, 0))
    both = simulate(physical, engine="analytic", initial=start, duration=0.5,
                    rotor_speed_series=series)
    for i in range(2):
        one = simulate(physical, engine="analytic", initial=start, duration=0.5,
                       rotor_speed_series=series[i])
        assert np.abs(both.select(i).position - one.position).max() <= 1e-10


def test_report_set_runs_in_the_analytic_engine():
    params = load_params("report", check=False)
    traj = simulate(params, engine="analytic", initial=initial_state(position=(0, 0, 1)),
                    duration=0.2)
    assert np.abs(traj.position[:, 2] - 1).max() <= 1e-9     # hover speeds hold it


def test_bad_inputs_raise_one_line_errors(physical):
    with pytest.raises(InputError, match="unknown engine 'bullet'"):
        simulate(physical, engine="bullet", duration=1.0)
    with pytest.raises(InputError, match="rotor_speed_series"):
        simulate(physical, engine="analytic", duration=1.0, rotor_speed_series=np.zeros((5, 4)))
    with pytest.raises(InputError, match="inconsistent batch sizes"):
        simulate([physical] * 2, engine="analytic", duration=0.1,
                 rotor_speed_series=np.zeros((3, 10, 4)))
    with pytest.raises(InputError, match="whole number of control periods"):
        simulate(physical, engine="analytic", duration=0.105, control_period=0.01)


def test_divergence_is_reported(physical):
    start = initial_state(position=(0, 0, 1), velocity=(2e6, 0, 0))
    with pytest.raises(SimulationError, match="diverged"):
        simulate(physical, engine="analytic", initial=start, duration=0.02)


def test_gyroscopic_torque_by_hand():
    """One ccw rotor on +z at 500 rad/s, Jr = 1e-4 kg m^2, body rolling at 1 rad/s:
    h = 0.05 z N m s, tau = -w x h = +0.05 y; spinning it up at 1000 rad/s^2: -0.1 z."""
    from quadsim.effects.gyroscopic import gyroscopic_torque

    axes, spins = np.array([[0.0, 0.0, 1.0]]), np.array([1.0])
    tau = gyroscopic_torque(1e-4, np.array([[1.0, 0, 0]]), np.array([[500.0]]),
                            np.array([[1000.0]]), axes, spins)
    assert np.allclose(tau, [[0.0, 0.05, -0.1]], atol=1e-15)
    cw = gyroscopic_torque(1e-4, np.array([[1.0, 0, 0]]), np.array([[500.0]]),
                           np.zeros((1, 1)), axes, -spins)
    assert np.allclose(cw, [[0.0, -0.05, 0.0]], atol=1e-15)


def test_cross_matches_numpy_bit_for_bit_with_broadcasting():
    """quadsim.core.frames.cross (engines, effects, residual) against np.cross: the same
    products, so equal to the bit, over (N, 3) x (N, 3), (N, 3) x (3,) and (B, R, 3) x
    (B, 1, 3); e_x x e_y = e_z."""
    from quadsim.core.frames import cross

    rng = np.random.default_rng(7)
    for a, b in ((rng.normal(size=(50, 3)), rng.normal(size=(50, 3))),
                 (rng.normal(size=(50, 3)), rng.normal(size=3)),
                 (rng.normal(size=(2, 4, 3)), rng.normal(size=(2, 1, 3)))):
        assert np.array_equal(cross(a, b), np.cross(a, b))
    assert np.array_equal(cross(np.array([1.0, 0, 0]), np.array([0, 1.0, 0])), [0, 0, 1.0])
