"""Issue 47 item 7 / issue 44: the rotor-order check reads the rotor signal that carries the
torque (quadsim.logs.checks.rotor_order_evidence): a log with both rotor speeds and commands
is judged on each, except a signal that fits the momentum measurably worse than the other
(its own noise in the regressor)."""

from __future__ import annotations

import dataclasses
import warnings

import pytest

from quadsim.core.errors import InputError
from quadsim.effects import EffectSet, make_effect
from quadsim.logs.checks import (
    DOUBT_CHI2,
    ORDER_CHI2,
    ORDER_NOISE_SHARE,
    _noise_share,
    _torque_balance,
    check_rotor_order,
    rotor_order_evidence,
    rotor_order_source,
    rotor_order_status,
)
from quadsim.logs.generate import generate_flight
from quadsim.logs.sensors import SensorModel
from quadsim.vehicle.params import load_params
from quadsim.vehicle.rotors import allocation_matrix

NOISE = SensorModel(noise={"position": 5e-4, "velocity": 0.01, "attitude": 2e-3,
                           "gyro": 0.02, "accel": 0.1, "rotor": 10.0})


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def windy(cf):
    """A generated IMU-only lissajous (pose dropped) in a 3 m/s wind with a rotor drag,
    rotor speeds logged with 10 rad/s of noise (their differences between rotors are at
    that noise) and the commands."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = generate_flight(cf, "lissajous", EffectSet((
            make_effect("wind", vx=3.0), make_effect("rotor_drag", coefficient=5e-7))),
            NOISE, 2, duration=5.0, speed=1.0)
    return dataclasses.replace(log, position=None, quat=None, velocity=None)


def test_the_right_order_in_a_wind_is_confirmed_by_the_signal_that_carries_the_torque(cf,
                                                                                       windy):
    # the speeds alone: their sensor's noise is most of each axis' torque column (the
    # rotors' speed differences are at it), so no axis tells an order: "cannot be ruled
    # out", never doubtful (before: rotors 3<->4 fitted better by 29.5 with the wind's
    # torque standing in, refused as "1,2,4,3 fits far better")
    speeds_only = dataclasses.replace(windy, rotor_command=None)
    shares = _noise_share(_torque_balance(speeds_only, cf, sensor=True),
                          allocation_matrix(cf)[3:6], (0, 1, 2, 3))
    assert (shares >= ORDER_NOISE_SHARE).all(), shares
    alone = rotor_order_status(speeds_only, cf)
    assert not alone.doubtful and not alone.confirmed and alone.evidence == 0.0
    # with the commands logged too, the speeds fit the momentum worse by far more than
    # ORDER_CHI2: the commands are read, and every other order fits worse by > ORDER_CHI2
    assert rotor_order_source(windy, cf) == "commands"
    status = rotor_order_status(windy, cf)
    assert status.confirmed and not status.doubtful and status.evidence < -ORDER_CHI2
    assert status.evidence == pytest.approx(-223.2, abs=0.1)
    check_rotor_order(windy, cf)


def test_a_swapped_log_is_still_refused_and_a_mixed_one_judged_on_each_signal(cf, windy):
    swapped = dataclasses.replace(windy, rotor_speed=windy.rotor_speed[:, [1, 0, 2, 3]],
                                  rotor_command=windy.rotor_command[:, [1, 0, 2, 3]])
    evidence = rotor_order_evidence(swapped, cf)
    assert max(evidence, key=evidence.get) == (1, 0, 2, 3)
    # 484.7 with quadsim.fly's commands at speed / max_speed; 483.9 with the crazyflie21
    # map's commands, read through the map (quadsim.logs.checks._command_speeds)
    assert evidence[(1, 0, 2, 3)] == pytest.approx(483.9, abs=0.1)
    assert rotor_order_status(swapped, cf).doubtful
    with pytest.raises(InputError, match="--rotor-map 2,1,3,4"):
        check_rotor_order(swapped, cf)
    # only the commands swapped (the speeds, noisier, in the right order): still refused
    mixed = dataclasses.replace(windy, rotor_command=windy.rotor_command[:, [1, 0, 2, 3]])
    assert max(rotor_order_evidence(mixed, cf).values()) > ORDER_CHI2 > DOUBT_CHI2


def test_speeds_above_their_noise_still_refuse_a_swapped_log(cf):
    """A generated steps flight (strong manoeuvres): its speeds' noise is 0.18-0.24 of the
    roll and pitch columns; rotors 1<->2 swapped in the speeds alone: refused (+225)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = generate_flight(cf, "steps", EffectSet(()), NOISE, 1, duration=5.0,
                                 speed=1.0)
    swapped = dataclasses.replace(log, rotor_speed=log.rotor_speed[:, [1, 0, 2, 3]],
                                  rotor_command=None)
    evidence = rotor_order_evidence(swapped, cf)
    assert evidence[(1, 0, 2, 3)] == pytest.approx(225.3, abs=0.1)
    with pytest.raises(InputError, match="--rotor-map 2,1,3,4"):
        check_rotor_order(swapped, cf)
