"""Changes written into real logs (benchmarks.injected): the closed forms they promise, on a
generated log of the crazyflie21 set (its per-rotor map, battery-voltage law and time
constant), and the scoring rule."""
import numpy as np
import pytest

from benchmarks.injected import (
    Change,
    commands_for,
    injected,
    score,
    speeds_with_mass,
    speeds_with_rotor,
)
from benchmarks.synthetic import commands_through_map, synthetic_flight
from quadsim.vehicle.params import load_params
from quadsim.vehicle.rotors import allocation_matrix


@pytest.fixture(scope="module")
def flight():
    params = load_params("crazyflie21")
    log = commands_through_map(synthetic_flight(params, [], seed=3, duration=4.0), params)
    return params, log


def test_a_mass_scales_the_collective_thrust_and_adds_no_torque(flight):
    params, log = flight
    added = 0.003
    new = injected(log, params, Change("mass", added))
    a = allocation_matrix(params)
    before, after = np.square(log.rotor_speed) @ a.T, np.square(new.rotor_speed) @ a.T
    np.testing.assert_allclose(after[:, 2], before[:, 2] * (1 + added / params.mass),
                               rtol=1e-12)
    np.testing.assert_allclose(after[:, 3:], before[:, 3:], atol=1e-12 * np.abs(before).max())
    np.testing.assert_array_equal(new.body_rate, log.body_rate)      # the motion as logged
    np.testing.assert_array_equal(new.accel, log.accel)


def test_a_weaker_propeller_gives_the_logged_wrench_at_its_own_factor(flight):
    params, log = flight
    speed = speeds_with_rotor(log.rotor_speed, 3, -0.08)
    a = allocation_matrix(params)
    factor = np.array([1.0, 1.0, 0.92, 1.0])
    np.testing.assert_allclose(np.square(speed) * factor @ a.T,
                               np.square(log.rotor_speed) @ a.T, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(speed[:, [0, 1, 3]], log.rotor_speed[:, [0, 1, 3]])


def test_the_commands_move_through_the_map_by_the_led_speed_change(flight):
    """map(c', v) - map(c, v) = d + tau d', the steady speed change the command model needs
    (it lags by tau), at the logged battery voltage."""
    params, log = flight
    mm = params.motor_map
    speed = speeds_with_mass(log.rotor_speed, params, 0.002)
    command = commands_for(log, params, speed)
    delta = speed - log.rotor_speed
    led = delta + mm.time_constant * np.gradient(delta, log.t, axis=0)
    np.testing.assert_allclose(mm.speed_at(command, log.vbat) - mm.speed_at(log.rotor_command,
                                                                            log.vbat),
                               led, rtol=1e-9, atol=1e-9)


def test_none_is_the_log_itself_and_scores(flight):
    params, log = flight
    assert injected(log, params, Change("none")) is log
    plain = {"outcome": "no_significant_gap", "verdict": "no_significant_gap"}
    assert score(Change("none"), plain)["right"]
    heavy = {"outcome": "effect", "verdict": "mass_offset", "tentative": False,
             "params": {"mass_offset.mass": 0.0021}}
    assert score(Change("mass", 0.002), heavy)["right"]
    assert not score(Change("mass", 0.004), heavy)["right"]        # 2.1 g for 4 g: off
    assert score(Change("mass", 0.004), heavy)["confident_wrong"]
    assert score(Change("none"), heavy)["confident_wrong"]
    weak = {"outcome": "effect", "verdict": "thrust_mismatch", "tentative": True,
            "params": {"thrust_mismatch.rotor_2": -0.09}}
    assert score(Change("rotor", -0.10, 2), weak)["right"]
    assert not score(Change("rotor", -0.10, 3), weak)["right"]
    assert not score(Change("rotor", -0.10, 3), weak)["confident_wrong"]   # tentative
