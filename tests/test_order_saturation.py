"""Issue 47 item 7: the rotor-order check leaves saturated samples out
(quadsim.logs.checks.ORDER_SATURATED)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks.synthetic import flyable_flight, synthetic_flight
from quadsim.core.errors import InputError
from quadsim.logs.checks import (
    ORDER_CHI2,
    _saturated,
    check_rotor_order,
    rotor_order_evidence,
    rotor_order_status,
)
from quadsim.vehicle.params import load_params


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def _capped(cf, seed):
    """A commands-only log whose rotor 1 sits at the full-command cap on its top 10 % of
    samples (the controller asks for more than the motor gives: the logged 1.0 overstates
    the speed the vehicle's motion shows). The flight under it is exact
    (:func:`benchmarks.synthetic.flyable_flight`): the cap is written into its commands here
    (at 1.5 m/s seed 1's path held rotors 1 and 3 at the lower speed bound for 13 and 5
    samples, a saturation at the other end, which this test is not about)."""
    log = flyable_flight(cf, [], seed=seed, duration=6.0, speed=1.5)
    cmd = log.rotor_command.copy()
    cmd[:, 0] = np.where(cmd[:, 0] >= np.percentile(cmd[:, 0], 90), 1.0, cmd[:, 0])
    return dataclasses.replace(log, rotor_command=cmd, rotor_speed=None)


def test_a_saturated_log_in_the_right_order_is_confirmed_and_a_swapped_one_refused(cf):
    log = _capped(cf, 1)
    assert np.mean(_saturated(log, cf)) == pytest.approx(0.1, abs=0.01)
    # with the capped samples in the balance the right order was not told apart from its
    # best rival (Delta chi^2 -2.6, measured before the change); without them it is
    # confirmed by far
    status = rotor_order_status(log, cf)
    assert status.confirmed and status.evidence < -100 * ORDER_CHI2, status
    # rotors 1 and 2 swapped in the same log: refused, naming the map that undoes it
    swapped = dataclasses.replace(log, rotor_command=log.rotor_command[:, [1, 0, 2, 3]])
    evidence = rotor_order_evidence(swapped, cf, commands=True)
    assert max(evidence, key=evidence.get) == (1, 0, 2, 3)
    assert max(evidence.values()) > 100 * ORDER_CHI2
    with pytest.raises(InputError, match="rotor order"):
        check_rotor_order(dataclasses.replace(swapped, rotor_speed=swapped.rotor_command
                                              * cf.max_speed), cf)


def test_a_log_without_saturation_is_scored_as_before(cf):
    """No sample at the cap: the windows and sums are those of the whole log (the
    unsaturated balance, measured before the change: -2665.77 on this log)."""
    log = synthetic_flight(cf, [], seed=1, duration=6.0, speed=1.0)
    # the rotor speeds read (with the commands logged too, the better-fitting signal is)
    log = dataclasses.replace(log, rotor_command=None)
    assert not _saturated(log, cf).any()
    evidence = rotor_order_evidence(log, cf)
    assert max(evidence.values()) == pytest.approx(-2665.7676, rel=1e-6)
