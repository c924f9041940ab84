"""benchmarks.synthetic.synthetic_flight's commands: by default (``commands="fly"``) the
convention ``quadsim.fly`` logs (quadsim.logs.generate.logged_command: the set's motor map at
the battery voltage), checked through the map's own forward law; ``commands="max_speed"``
``speed / max_speed``."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.effects import make_effect
from quadsim.vehicle.params import load_params


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def test_max_speed_commands_are_the_speed_over_max_speed(cf):
    """Noise off, no effect: each command times max_speed (2750 rad/s) is the logged speed."""
    log = synthetic_flight(cf, seed=2, duration=2.0, noise=None, commands="max_speed")
    np.testing.assert_allclose(log.rotor_command * cf.max_speed, log.rotor_speed, rtol=1e-12)


def test_fly_commands_give_the_speed_back_through_the_sets_map(cf):
    """``commands="fly"``, noise off: the set's map read forward at the logged voltage,
    (a_i + k_i u)(1 + 0.249 (v - 3.7104)), is the logged speed (crazyflie21's map: a line per
    rotor and a voltage law; the sag 4.2 -> 4.05 V moves the speed per command 3.4 %); a
    battery sag's factor is in the commanded speed (speed / factor), as with
    ``commands="max_speed"``; ``"fly"`` is the default."""
    mm = cf.motor_map
    for effects in ([], [make_effect("battery_sag", full_voltage=4.3)]):
        log = synthetic_flight(cf, effects, seed=2, duration=2.0, noise=None)
        a, k = mm.speed[:, 0], mm.speed[:, 1] - mm.speed[:, 0]
        law = 1.0 + mm.voltage_gain * (log.vbat - mm.reference_voltage)
        commanded = (a + k * log.rotor_command) * law[:, None]
        plain = synthetic_flight(cf, effects, seed=2, duration=2.0, noise=None,
                                 commands="max_speed")
        np.testing.assert_allclose(commanded / cf.max_speed, plain.rotor_command, rtol=1e-9)
    assert mm.voltage_gain == 0.249 and mm.reference_voltage == 3.7104


def test_fly_commands_without_a_map_are_the_default_bytes(cf):
    bare = cf.replace(motor_map=None)
    one = synthetic_flight(bare, seed=5, duration=1.0)
    two = synthetic_flight(bare, seed=5, duration=1.0, commands="max_speed")
    assert np.array_equal(one.rotor_command, two.rotor_command)
    with pytest.raises(ValueError, match="commands 'pwm'"):
        synthetic_flight(cf, seed=5, duration=1.0, commands="pwm")
