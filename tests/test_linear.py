"""Linearisation about hover: closed form vs finite differences of both engines, the B
matrix against the '+' rotor geometry by hand, poles, controllability, LQR stability."""

import numpy as np
import pytest

from quadsim.sim.linear import (
    LQRController,
    dynamics_jacobian_fd,
    hover_point,
    is_controllable,
    linearize,
    lqr_gain,
)
from quadsim.vehicle.params import load_params


@pytest.fixture(scope="module")
def physical():
    return load_params("physical")


def _variants():
    base = load_params("physical")
    yield "physical", base, 0.0
    yield "offset CoM, yawed", base.replace(com=np.array([0.01, -0.02, 0.015])), 0.7
    yield "computational", load_params("computational"), 0.0


@pytest.mark.parametrize("engine", ["analytic", "mujoco"])
def test_closed_form_matches_finite_differences(engine):
    for label, params, yaw0 in _variants():
        sys = linearize(params, yaw0=yaw0)
        x0, u0 = hover_point(params, yaw0=yaw0)
        a_fd, b_fd = dynamics_jacobian_fd(params, engine, x0, u0)
        assert np.abs(a_fd - sys.A).max() <= 1e-6, label
        assert np.abs(b_fd - sys.B).max() <= 1e-6 * np.abs(sys.B).max(), label


def test_b_matrix_matches_plus_layout_by_hand(physical):
    """Rotor 1 front (+x, ccw), 2 right (-y, cw), 3 back (-x, ccw), 4 left (+y, cw)."""
    sys = linearize(physical)
    _, u0 = hover_point(physical)
    omega0 = u0[0]
    b, d, m = physical.thrust_factor, physical.drag_factor, physical.mass
    arm = physical.rotors[0].position[0]
    ixx, iyy, izz = np.diag(physical.inertia)
    lift = 2 * b * omega0
    expected = np.zeros((12, 4))
    expected[5] = lift / m
    expected[9] = [0, -arm * lift / ixx, 0, arm * lift / ixx]      # roll: y_i * thrust
    expected[10] = [-arm * lift / iyy, 0, arm * lift / iyy, 0]     # pitch: -x_i * thrust
    expected[11] = -np.array([1, -1, 1, -1]) * 2 * d * omega0 / izz   # yaw: -spin * drag
    assert np.allclose(u0, omega0)
    assert np.abs(sys.B - expected).max() <= 1e-12 * np.abs(expected).max()
    # gravity tilts the thrust: d(vx)/d(pitch) = +g, d(vy)/d(roll) = -g
    assert sys.A[3, 7] == pytest.approx(physical.gravity, rel=1e-12)
    assert sys.A[4, 6] == pytest.approx(-physical.gravity, rel=1e-12)


def test_open_loop_poles_and_controllability(physical):
    sys = linearize(physical)
    assert np.abs(np.linalg.eigvals(sys.A)).max() == 0.0      # twelve integrators at hover
    assert is_controllable(sys)
    assert sys.nstates == 12 and sys.ninputs == 4


def test_lqr_closed_loop_is_stable(physical):
    sys = linearize(physical)
    gain, poles = lqr_gain(sys)
    closed = np.linalg.eigvals(sys.A - sys.B @ gain)
    assert np.all(closed.real < 0)
    assert np.allclose(np.sort_complex(closed), np.sort_complex(poles), atol=1e-8)
    controller = LQRController(physical)
    state = {"position": np.array([[0.0, 0.0, 1.0]]), "velocity": np.zeros((1, 3)),
             "quat": np.array([[1.0, 0, 0, 0]]), "body_rate": np.zeros((1, 3))}
    assert np.allclose(controller(np.zeros(1), state), hover_point(physical)[1])
