"""A parameter set whose rotor spins are all the wrong way round is named as such by the
rotor-order check (``quadsim.logs.checks.spin_reversal_evidence``), not as a column order:
on an X quadrotor the order that flips every spin also turns roll and pitch by 90 deg."""

from __future__ import annotations

import dataclasses

import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import InputError, QuadsimWarning
from quadsim.logs.checks import (
    ORDER_CHI2,
    check_rotor_order,
    order_reading,
    rotor_order_evidence,
    rotor_order_status,
    spin_reversal_evidence,
)
from quadsim.vehicle.params import load_params


def _reversed(params):
    """``params`` with every rotor's spin reversed (cw <-> ccw)."""
    return dataclasses.replace(params, rotors=tuple(dataclasses.replace(r, spin=-r.spin)
                                                    for r in params.rotors))


@pytest.fixture(scope="module")
def flight():
    cf = load_params("crazyflie21")
    return cf, synthetic_flight(cf, [], seed=7, duration=4.0, speed=1.5)


def test_reversed_spins_are_named_not_an_order(flight):
    cf, log = flight
    wrong = _reversed(cf)
    spins = spin_reversal_evidence(log, wrong)
    assert spins > ORDER_CHI2                       # the yaw balance: far better reversed
    assert spin_reversal_evidence(log, cf) < -ORDER_CHI2   # the right set: far worse reversed
    with pytest.raises(InputError, match=r"rotor_\*: rotor spins: the yaw torque balance fits "
                                         r"better with every rotor's spin reversed"):
        check_rotor_order(log, wrong)
    check_rotor_order(log, cf)                      # the right set passes
    status = rotor_order_status(log, wrong)
    assert status.doubtful and "rotor spins not confirmed" in status.note
    assert not rotor_order_status(log, cf).doubtful


def test_a_wrong_column_order_is_still_named_as_an_order(flight):
    """Rotors 1 and 2 swapped in the log (not the spins): the order is named, its
    --rotor-map given, and reversing the spins explains far less."""
    cf, log = flight
    swapped = dataclasses.replace(log, rotor_speed=log.rotor_speed[:, [1, 0, 2, 3]],
                                  rotor_command=log.rotor_command[:, [1, 0, 2, 3]])
    evidence = rotor_order_evidence(swapped, cf)
    assert evidence[(1, 0, 2, 3)] > ORDER_CHI2
    assert spin_reversal_evidence(swapped, cf) < evidence[(1, 0, 2, 3)] - 4
    with pytest.raises(InputError, match=r"rotor order: .* --rotor-map 2,1,3,4"):
        check_rotor_order(swapped, cf)


def test_the_old_keyword_forms_are_read_with_a_warning(flight):
    """Callers written before the one-reading check (CHANGELOG.md, speedfix): the
    ``evidence=`` keyword and (source, evidence) pairs still give the same result, with a
    warning saying what to pass instead."""
    cf, log = flight
    wrong = _reversed(cf)
    with pytest.warns(QuadsimWarning, match=r"pass reading="):
        with pytest.raises(InputError, match=r"rotor spins"):
            check_rotor_order(log, wrong, evidence=rotor_order_evidence(log, wrong))
    pairs = [order_reading(part, wrong, commands=True) for part in log.parts()]
    assert all(len(p) == 2 for p in pairs)
    with pytest.warns(QuadsimWarning, match=r"read again from the log"):
        old = rotor_order_status(log, wrong, readings=pairs)
    assert old == rotor_order_status(log, wrong)
