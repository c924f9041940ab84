"""The per-flight mode's fixed part passes what one stage computed to the next instead of
computing it again (issue 43 item 7); each shortcut against the path it replaces, on
generated flights: a judged flight's residual series on the weighing's states and memo
against a new alignment and Jacobian; the rotor-order status read from the checks' torque
balances against :func:`quadsim.logs.checks.rotor_order_status` on the checked log; the
calibration's flight views (rotor spectra computed once) against
:func:`quadsim.gap.calibrate.aligned`. Equality is exact: the shortcuts reuse the same
computations, they do not reorder them."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import QuadsimWarning
from quadsim.gap import logcheck
from quadsim.gap.calibrate import calibrate
from quadsim.gap.diagnose import ToJudge, judge_one, prepare, weigh_flight
from quadsim.gap.page import flight_series
from quadsim.logs.checks import check_logs, order_reading, rotor_order_status
from quadsim.vehicle.params import load_params

from _helpers import shared_effects

#: one xdist worker runs this module's tests: its module-scoped fixtures are built once
pytestmark = pytest.mark.xdist_group("test_fast_paths_fixed")


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def calibrated(cf):
    """Three generated references (shared motor lag and rotor drag) and their calibration."""
    logs = [synthetic_flight(cf, shared_effects(), duration=3.0, seed=s, speed=0.6 + 0.1 * s)
            for s in range(3)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        flights = prepare(logs, cf)
        return flights, calibrate(flights, cf)


def test_the_series_on_the_weighings_memo_is_the_series_from_scratch(cf, calibrated):
    _, ref = calibrated
    log = synthetic_flight(cf, shared_effects(), duration=3.0, seed=7, speed=0.9)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        flight = prepare([log], ref.params)[0]
        weighed = weigh_flight(flight, ref, None, name=flight.name)
        fast = flight_series(weighed.states, weighed.reference, weighed.rows,
                             name=flight.name, memo=weighed.memo)
        slow = flight_series(weighed.reference.align(flight), weighed.reference,
                             weighed.rows, name=flight.name)
        verdict = judge_one(log, ref)
    assert np.array_equal(fast.before, slow.before)
    assert np.array_equal(fast.after, slow.after)
    assert np.array_equal(verdict.series.before, slow.before)
    assert np.array_equal(verdict.series.after, slow.after)


def _swapped(log):
    """``log`` with rotor columns 1 and 2 exchanged (a wrong rotor order)."""
    order = [1, 0, 2, 3]
    return dataclasses.replace(log, rotor_speed=log.rotor_speed[:, order],
                               rotor_command=log.rotor_command[:, order])


def test_the_checks_rotor_order_is_the_status_of_the_checked_log(cf):
    log = synthetic_flight(cf, shared_effects(), duration=4.0, seed=11, speed=1.0)
    commands_only = dataclasses.replace(log, rotor_speed=None)
    orders: list = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        checked, _ = check_logs([log, commands_only], cf, orders=orders)
    assert orders[0] == rotor_order_status(checked[0], cf)
    assert orders[0] == logcheck.order_statuses([checked[0]], cf)[0]
    assert "rotor speeds" in orders[0].source
    # without rotor speeds the check reads no signal and the status the commands: not kept
    assert orders[1] is None


def test_one_reading_is_the_source_and_the_evidence(cf):
    log = _swapped(synthetic_flight(cf, shared_effects(), duration=4.0, seed=12, speed=1.0))
    from quadsim.logs.checks import rotor_order_evidence, rotor_order_source

    for commands in (False, True):
        source, evidence = order_reading(log, cf, commands=commands)
        assert source == rotor_order_source(log, cf, commands=commands)
        assert evidence == rotor_order_evidence(log, cf, commands=commands)
    # the swapped columns: the rival order (2,1,3,4) fits better
    assert max(evidence, key=evidence.get) == (1, 0, 2, 3)


def test_one_reading_is_the_spins_too(cf):
    """The evidence and the spins from one set of torque balances (``_read_order``) are
    :func:`order_reading`'s and :func:`spin_reversal_evidence`'s, each on its own."""
    from quadsim.logs import checks

    log = synthetic_flight(cf, shared_effects(), duration=4.0, seed=12, speed=1.0)
    for flight in (log, _swapped(log), dataclasses.replace(log, rotor_speed=None)):
        for commands in (False, True):
            source, evidence, spins = checks._read_order(flight, cf, commands)
            assert (source, evidence) == order_reading(flight, cf, commands=commands)
            assert spins == checks.spin_reversal_evidence(flight, cf, commands=commands)


def test_the_checks_read_one_set_of_torque_balances(cf, monkeypatch):
    """The rotor-order check, its spins and the status kept for the judged flight: one
    torque balance per signal (rotor speeds, commands) and stretch, with or without the
    status (before: 4 without it, 6 with it)."""
    from quadsim.logs import checks

    log = synthetic_flight(cf, shared_effects(), duration=4.0, seed=11, speed=1.0)
    balances = []
    original = checks._torque_balance

    def counted(*args, **kwargs):
        balances.append(kwargs.get("sensor"))
        return original(*args, **kwargs)

    monkeypatch.setattr(checks, "_torque_balance", counted)
    for orders in (None, []):
        balances.clear()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            checked, _ = check_logs([log], cf, orders=orders)
        assert len(checked[0].parts()) == 1
        assert sorted(balances) == [False, True]          # commands, rotor speeds
    monkeypatch.setattr(checks, "_torque_balance", original)
    assert orders[0] == rotor_order_status(checked[0], cf)


def test_a_judged_flight_with_the_checks_order_is_judged_as_without(cf, calibrated):
    _, ref = calibrated
    log = synthetic_flight(cf, shared_effects(), duration=3.0, seed=8, speed=0.8)
    orders: list = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        (checked,), _ = check_logs([log], cf, orders=orders)
        given = judge_one(checked, ref, order=orders[0])
        read = judge_one(checked, ref)
    assert json.dumps(given.to_json(), sort_keys=True) == json.dumps(read.to_json(),
                                                                     sort_keys=True)
    assert ToJudge(checked, orders[0]).path == checked.path


def test_the_refinements_views_are_the_flights_aligned_anew(calibrated):
    """The calibration's views (each flight's rotor spectra computed once) give
    :func:`quadsim.gap.calibrate.aligned`'s states at every timing, bit for bit."""
    from quadsim.gap.calibrate import _Views, aligned

    flights, _ = calibrated
    views = _Views(flights)
    for delay in (0.0, 0.0123, -0.004, 0.0123):
        for i, f in enumerate(flights):
            got, want = views.at(i, delay), aligned(f, delay)
            assert np.array_equal(got.rotor_speed, want.rotor_speed)
            assert np.array_equal(got.rotor_accel, want.rotor_accel)
            assert got.t is want.t and got.quat is want.quat
    assert all(s is not None for s in views.spectra)
