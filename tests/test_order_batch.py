"""The rotor-order test's fits of every column order at once (quadsim.logs.checks._fit_orders,
issue 43 item 7) against the per-order loop (_fit_order): the same residuals and lag-1
autocorrelations to round-off, a gain <= 0 included."""
import itertools
import warnings

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.logs import checks
from quadsim.vehicle.params import load_params
from quadsim.vehicle.rotors import allocation_matrix


def _compare(balance, rows):
    orders = list(itertools.permutations(range(balance.rotors)))
    loop = [checks._fit_order(balance, rows, o) for o in orders]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        checks._fit_orders(balance, rows, orders)
    for o, (rss, rho) in zip(orders, loop):
        got_rss, got_rho = balance.fits[(rows.tobytes(), o)]
        np.testing.assert_allclose(got_rss, rss, rtol=1e-9, atol=1e-12 * balance.gram[0, 0])
        np.testing.assert_allclose(got_rho, rho, rtol=1e-9, atol=1e-9)
    return loop


def test_the_orders_of_a_generated_flight():
    params = load_params("crazyflie21")
    log = synthetic_flight(params, [], seed=2, duration=6.0)
    balance = checks._torque_balance(log, params)
    assert balance is not None
    loop = _compare(balance, allocation_matrix(params)[3:6])
    rss = np.array([x[0] for x in loop])
    assert rss.min(axis=0).max() < rss.max(axis=0).min()     # the orders do differ


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_balances_with_rejected_gains(seed):
    """Random Gram matrices (positive definite, the momentum columns negatively tied to some
    rotors so that a gain comes out <= 0 for some orders)."""
    rng = np.random.default_rng(seed)
    z = rng.standard_normal((500, 8))
    z[:, 0] -= 2.0 * z[:, 3]
    gram, lag = z.T @ z, 0.5 * (z[:-1].T @ z[1:] + z[1:].T @ z[:-1])
    balance = checks._TorqueBalance(gram, lag, 4, 400, np.ones(3))
    rows = rng.standard_normal((3, 4))
    loop = _compare(balance, rows)
    # some order's gain is rejected there: its residual is the constant torque's alone
    alone = np.diag(gram)[:3] - gram[7, :3] ** 2 / gram[7, 7]
    assert any(np.any(np.isclose(rss, alone, rtol=1e-12)) for rss, _ in loop)
