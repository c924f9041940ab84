"""The MuJoCo runner: state convention, refusal of non-physical sets, divergence, batching,
per-simulation models, hover equilibrium."""

import mujoco
import numpy as np
import pytest

from quadsim.core.errors import ModelError, SimulationError
from quadsim.core.frames import euler_to_quat, quat_derivative, quat_to_rotmat
from quadsim.effects import EffectSet, make_effect
from quadsim.sim.engines import initial_state, simulate
from quadsim.sim.linear import hover_point
from quadsim.sim.mujoco_engine import compile_model, default_timestep
from quadsim.vehicle.params import load_params


@pytest.fixture(scope="module")
def physical():
    return load_params("physical")


def test_freejoint_velocity_convention(physical):
    """qvel[0:3] is the body-origin velocity in the world frame and qvel[3:6] the angular
    velocity in the body frame (checked by finite differences of qpos) — the Trajectory
    convention, so the runner needs no conversion."""
    model = compile_model(physical.replace(com=np.array([0.03, -0.02, 0.01])), 1e-4)
    data = mujoco.MjData(model)
    data.qpos[:] = [0.1, 0.2, 1.0, *euler_to_quat(np.array([0.4, -0.3, 1.2]))]
    data.qvel[:] = [0.5, -0.4, 0.3, 2.0, -1.0, 3.0]
    before = data.qpos.copy()
    dt = 1e-7
    qpos = before.copy()
    mujoco.mj_integratePos(model, qpos, data.qvel, dt)
    assert np.allclose((qpos[0:3] - before[0:3]) / dt, data.qvel[0:3], atol=1e-6)
    rate_body = quat_derivative(before[3:7], data.qvel[3:6])
    assert np.allclose((qpos[3:7] - before[3:7]) / dt, rate_body, atol=1e-5)
    rate_world = quat_derivative(before[3:7],
                                 quat_to_rotmat(before[3:7]).T @ data.qvel[3:6])
    assert not np.allclose(rate_body, rate_world, atol=1e-2)   # the frames do differ here


@pytest.mark.parametrize("name", ["physical", "computational"])
def test_hover_residual_acceleration(name):
    params = load_params(name)
    model = compile_model(params, 1e-3)
    data = mujoco.MjData(model)
    x0, u0 = hover_point(params)
    data.qpos[:] = [*x0[0:3], 1, 0, 0, 0]
    data.ctrl[:] = u0**2
    mujoco.mj_forward(model, data)
    assert np.abs(data.qacc).max() <= 1e-9


def test_report_set_is_refused_in_one_line():
    params = load_params("report", check=False)
    with pytest.raises(ModelError, match="MuJoCo refuses .*triangle inequality") as info:
        simulate(params, engine="mujoco", duration=0.1)
    assert "\n" not in str(info.value)
    with pytest.raises(ModelError, match="triangle inequality"):
        load_params("report")


def test_divergence_is_reported(physical):
    start = initial_state(position=(0, 0, 1), velocity=(2e6, 0, 0))
    with pytest.raises(SimulationError, match="mujoco engine: simulation\\(s\\) \\[0\\] diverged"):
        simulate(physical, engine="mujoco", initial=start, duration=0.02)


def test_batch_is_bit_identical_to_single_runs(physical):
    series = np.stack([np.full((50, 4), 560.0), np.full((50, 4), 580.0)])
    start = initial_state(position=(0, 0, 1), euler=(0.1, 0.2, 0.3))
    both = simulate(physical, engine="mujoco", initial=start, duration=0.5,
                    rotor_speed_series=series)
    for i in range(2):
        one = simulate(physical, engine="mujoco", initial=start, duration=0.5,
                       rotor_speed_series=series[i])
        assert np.array_equal(both.select(i).position, one.position)
        assert np.array_equal(both.select(i).quat, one.quat)


def test_per_simulation_models_from_effects(physical):
    """A mass offset in one simulation of the batch changes only that simulation's model."""
    heavy = EffectSet((make_effect("mass_offset", mass=0.1),))
    traj = simulate(physical, engine="mujoco", effects=[EffectSet(), heavy],
                    initial=initial_state(position=(0, 0, 1)), duration=0.5,
                    rotor_speed_series=np.full((50, 4), hover_point(physical)[1][0]))
    assert np.abs(traj.position[0, :, 2] - 1).max() <= 1e-9      # nominal hovers
    assert traj.position[1, -1, 2] < 0.99                          # the heavier one sinks


def test_commands_are_clipped_to_rotor_range(physical):
    traj = simulate(physical, engine="mujoco", duration=0.1,
                    rotor_speed_series=np.full((10, 4), 5 * physical.max_speed))
    assert np.allclose(traj.rotor_command, physical.max_speed)


def test_default_timestep_divides_control_period():
    assert default_timestep(0.01) == pytest.approx(1e-3)
    assert default_timestep(0.0025) == pytest.approx(0.0025 / 3)
    assert default_timestep(0.0005) == pytest.approx(0.0005)
