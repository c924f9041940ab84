"""Cable payload, rate damping and canted rotor against hand calculations and closed forms.

Engine agreement of all three (MuJoCo vs analytic, 1e-4 m / 1e-4 rad) is part of
``tests/test_effects_engines.py`` (they are in ``TESTBED_EXAMPLES``); here: the payload's
swing period and its static equivalence to a rigid mass, a longer payload agreement run with
a lateral manoeuvre, the rate-damping decay and the canted rotor's force.
"""

from __future__ import annotations

import numpy as np
import pytest

from quadsim.core.errors import InputError
from quadsim.core.frames import quat_conjugate, quat_multiply
from quadsim.effects import EffectContext, EffectSet, make_effect
from quadsim.effects.cable_payload import CablePayload, swing_period
from quadsim.sim import engines
from quadsim.vehicle.params import hover_speed, load_params
from quadsim.vehicle.rotors import rotor_wrench

PARAMS = load_params("physical")
HOVER = hover_speed(PARAMS)
M = PARAMS.mass
G = PARAMS.gravity


class _Swinging(CablePayload):
    """The payload starts displaced by ``ANGLE`` (rad) in the world x-z plane, at rest."""

    ANGLE = 0.03

    def initial_state(self, params, vehicle):
        state = super().initial_state(params, vehicle)
        drop = self.length + self.mass * params.gravity / self.stiffness
        state[:, 0] += drop * np.sin(self.ANGLE)
        state[:, 2] += drop * (1 - np.cos(self.ANGLE))
        state[:, 3:6] = 0.0
        return state


def _payload_hover(mass: float) -> np.ndarray:
    """Rotor speeds that hold (M + m) g on the symmetric physical testbed."""
    return np.full(4, HOVER * np.sqrt((M + mass) / M))


def test_payload_swing_period_matches_closed_form():
    mass, length = 0.1, 0.5
    effect = _Swinging(mass=mass, length=length)           # attachment at the CoM (origin)
    duration = 3.0
    traj = engines.simulate(PARAMS, engine="analytic", effects=EffectSet((effect,)),
                            rotor_speed_series=np.tile(_payload_hover(mass), (30, 1)),
                            duration=duration, control_period=0.1, rtol=1e-8, atol=1e-10)
    t, x = traj.t, traj.position[:, 0]
    # the vehicle swings against the payload at the pendulum frequency: fit x = c + a cos + b sin
    from scipy.optimize import least_squares

    def resid(theta):
        w, c, a, b = theta
        return c + a * np.cos(w * t) + b * np.sin(w * t) - x

    stretched = length + mass * G / effect.stiffness
    expected = swing_period(stretched, mass, M, G)
    guess = [2 * np.pi / expected * 1.05, 0.0, -1e-3, 0.0]
    w = least_squares(resid, guess, x_scale=[1.0, 1e-3, 1e-3, 1e-3]).x[0]
    period = 2 * np.pi / w
    # amplitude correction of the period: theta0^2 / 16 = 6e-5
    assert abs(period / expected - 1) < 1e-3, (period, expected)
    fixed_pivot = 2 * np.pi * np.sqrt(stretched / G)
    assert abs(period / fixed_pivot - 1) > 0.03    # the vehicle's mass coupling is visible
    # momentum: the system's CoM does not move sideways, so the vehicle's swing amplitude is
    # m L theta0 / (M + m)
    amplitude = np.ptp(x) / 2
    np.testing.assert_allclose(amplitude, mass * stretched * np.sin(0.03) / (M + mass),
                               rtol=0.02)


def test_payload_hanging_still_is_a_rigid_mass():
    effect = make_effect("cable_payload", mass=0.1, length=0.5, z=-0.05)
    state = effect.initial_state(PARAMS, {"position": np.array([[0.0, 0.0, 1.0]]),
                                          "velocity": np.zeros((1, 3)),
                                          "quat": np.array([[1.0, 0, 0, 0]]),
                                          "body_rate": np.zeros((1, 3))})
    ctx = EffectContext(t=np.zeros(1), position=np.array([[0.0, 0.0, 1.0]]),
                        velocity=np.zeros((1, 3)), quat=np.array([[1.0, 0, 0, 0]]),
                        body_rate=np.zeros((1, 3)), air_velocity=np.zeros((1, 3)),
                        rotor_speed=np.full((1, 4), HOVER), rotor_accel=np.zeros((1, 4)),
                        params=PARAMS, effect_state=state)
    loads = effect.loads(ctx)
    np.testing.assert_allclose(loads.force_world, [[0.0, 0.0, -0.1 * G]], rtol=1e-12)
    np.testing.assert_allclose(loads.torque_body, 0.0, atol=1e-15)   # below the CoM
    np.testing.assert_allclose(effect.state_rate(ctx)[:, 3:], 0.0, atol=1e-12)
    # the vehicle holds still at the hover speed of the same mass rigidly attached
    rigid = make_effect("mass_offset", mass=0.1, z=-0.05).apply_to_params(PARAMS)
    for engine in ("analytic", "mujoco"):
        traj = engines.simulate(PARAMS, engine=engine, effects=EffectSet((effect,)),
                                initial=engines.initial_state(position=(0, 0, 1)),
                                rotor_speed_series=np.full((20, 4), hover_speed(rigid)),
                                duration=0.2, control_period=0.01)
        assert np.abs(traj.position - [0, 0, 1]).max() < 1e-9, engine


def test_payload_agrees_between_engines_in_a_lateral_manoeuvre():
    """Roll differential for 0.3 s, then level: the payload swings (0.6 s in the suite; 5 s open
    loop and 20 s closed loop in scripts/effects_agreement.py)."""
    effect = EffectSet((make_effect("cable_payload", mass=0.1, length=0.5, z=-0.05),))
    base = _payload_hover(0.1)
    series = np.tile(base, (60, 1))
    series[:20] *= [1.0, 0.995, 1.0, 1.005]
    series[20:40] *= [1.0, 1.005, 1.0, 0.995]
    run = lambda engine: engines.simulate(PARAMS, engine=engine, effects=effect,  # noqa: E731
                                          rotor_speed_series=series, duration=0.6,
                                          initial=engines.initial_state(position=(0, 0, 1)))
    m, a = run("mujoco"), run("analytic")
    relative = quat_multiply(quat_conjugate(m.quat), a.quat)
    angle = 2 * np.arcsin(np.clip(np.linalg.norm(relative[..., 1:], axis=-1), 0, 1)).max()
    assert np.abs(m.position - a.position).max() < 1e-4
    assert angle < 1e-4
    # the swing is there: without the payload's dynamics (rigid mass) the flight differs
    rigid = make_effect("mass_offset", mass=0.1, z=-0.05)
    r = engines.simulate(PARAMS, engine="analytic", effects=EffectSet((rigid,)),
                         rotor_speed_series=series, duration=0.6,
                         initial=engines.initial_state(position=(0, 0, 1)))
    assert np.abs(r.position - a.position).max() > 1e-3


def test_rate_damping_torque_and_decay():
    effect = make_effect("rate_damping", x=0.01, y=0.02, z=0.002)
    ctx = EffectContext(t=np.zeros(1), position=np.zeros((1, 3)), velocity=np.zeros((1, 3)),
                        quat=np.array([[1.0, 0, 0, 0]]), body_rate=np.array([[1.0, -2.0, 3.0]]),
                        air_velocity=np.zeros((1, 3)), rotor_speed=np.full((1, 4), HOVER),
                        rotor_accel=np.zeros((1, 4)), params=PARAMS)
    np.testing.assert_allclose(effect.loads(ctx).torque_body, [[-0.01, 0.04, -0.006]])
    # a yaw rate decays as exp(-k t / Izz) at hover (no other torque about z)
    izz = PARAMS.inertia[2, 2]
    for engine in ("analytic", "mujoco"):
        traj = engines.simulate(PARAMS, engine=engine, effects=EffectSet((effect,)),
                                initial=engines.initial_state(body_rate=(0, 0, 2.0)),
                                duration=1.0, control_period=0.01)
        expected = 2.0 * np.exp(-0.002 * traj.t / izz)
        np.testing.assert_allclose(traj.body_rate[:, 2], expected, rtol=1e-6, err_msg=engine)


def test_canted_rotor_force_and_torque():
    effect = make_effect("canted_rotor", rotor=1, angle=0.05, azimuth=np.pi / 2)
    tilted = effect.apply_to_params(PARAMS)
    np.testing.assert_allclose(tilted.rotor_axes[0], [np.sin(0.05), 0, np.cos(0.05)],
                               atol=1e-15)
    omega = np.full(4, HOVER)
    force, torque = rotor_wrench(tilted, omega)
    thrust, drag = PARAMS.thrust_factor * HOVER**2, PARAMS.drag_factor * HOVER**2
    np.testing.assert_allclose(force, [thrust * np.sin(0.05), 0, thrust * (3 + np.cos(0.05))],
                               rtol=1e-12, atol=1e-12)
    arm = PARAMS.rotor_positions[0, 0]
    # rotor 1 (front, ccw): arm x tilted thrust, and its drag torque along the tilted axis
    np.testing.assert_allclose(torque[[0, 1]], [-drag * np.sin(0.05),
                                                -arm * thrust * np.cos(0.05) + arm * thrust],
                               rtol=1e-9, atol=1e-15)
    # in flight: the vehicle accelerates forward at b Omega^2 sin(angle) / M
    traj = engines.simulate(PARAMS, engine="mujoco", effects=EffectSet((effect,)),
                            duration=0.1, control_period=0.01)
    np.testing.assert_allclose(traj.position[-1, 0], 0.5 * thrust * np.sin(0.05) / M * 0.01,
                               rtol=0.01)
    with pytest.raises(Exception, match="rotor = 5"):
        make_effect("canted_rotor", rotor=5, angle=0.1).apply_to_params(PARAMS)


def test_translational_lift_closed_form():
    """k_h |v - (v . a) a|^2 per rotor, along its axis: body-z rotors see the body x-y air
    speed (RotorPy's form); a canted rotor sees its own plane; rolled 90 deg, the world
    vertical air speed is in the rotor plane; a wind moves the air speed, not the ground
    speed; an off effect gives no loads."""
    k_h = 0.01
    v = np.array([[1.5, 0.0, 0.3], [0.0, -2.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    quat = np.tile([1.0, 0, 0, 0], (4, 1))
    quat[2] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0]          # rolled 90 deg about x
    air = v.copy()
    air[3] = [1.0, -1.0, 0.0]                                        # ground speed 1, wind +1 y
    speed = np.full((4, 4), HOVER)
    tilted = make_effect("canted_rotor", rotor=1, angle=0.05,
                         azimuth=np.pi / 2).apply_to_params(PARAMS)
    ctx = EffectContext(t=np.zeros(4), position=np.zeros((4, 3)), velocity=v, quat=quat,
                        body_rate=np.zeros((4, 3)), air_velocity=air, rotor_speed=speed,
                        rotor_accel=np.zeros_like(speed), params=tilted)
    loads = make_effect("translational_lift", k_h=k_h).loads(ctx)
    a = tilted.rotor_axes[0]
    expected = k_h * np.array([[2.25] * 4, [4.0] * 4, [1.0] * 4, [2.0] * 4])
    expected[0, 0] = k_h * (np.sum(v[0] ** 2) - (v[0] @ a) ** 2)      # the canted rotor
    expected[3, 0] = k_h * (2.0 - (air[3] @ a) ** 2)
    np.testing.assert_allclose(loads.thrust_offset, expected, rtol=1e-12)
    assert expected[0, 0] != pytest.approx(k_h * 2.25, rel=1e-3)      # the cant matters
    np.testing.assert_allclose(loads.force_world, 0.0)
    np.testing.assert_allclose(loads.torque_body, 0.0)
    assert make_effect("translational_lift").loads(ctx) is None
    with pytest.raises(InputError, match=r"^effect translational_lift: k_h = 2 kg/m outside"):
        make_effect("translational_lift", k_h=2.0)
