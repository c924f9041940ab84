"""A shared value whose pooled fit stops at a bound no plausible vehicle has is held in
every explanation's profile (quadsim.gap.explanations.marginal_sd, pinned_at_bound); one at
a physical floor keeps its spread."""

from types import SimpleNamespace

import numpy as np

from quadsim.gap.explanations import marginal_sd, pinned_at_bound, prior_spreads
from quadsim.vehicle.params import load_params

NAMES = ("inertia_error.xx", "inertia_error.yy", "motor_lag.time_constant", "wind.vx")


def _reference(theta, at_bound):
    params = load_params("crazyflie21")
    return SimpleNamespace(
        params=params, candidate=SimpleNamespace(parameter_names=list(NAMES)),
        s_ref=np.array([1.6, 1.6, 0.01, 0.3]), at_bound=dict(at_bound),
        values=lambda: dict(zip(NAMES, theta)))


def test_an_implausible_bound_is_pinned_a_physical_floor_is_not():
    # the references' roll and pitch inertia at +200 % (their fit's upper bound: the logged
    # speeds' noise), the motor lag at its floor, a quarter of a fit sample
    ref = _reference([2.0, 2.0, 0.0025, 0.1],
                     {"inertia_error.xx": "upper", "inertia_error.yy": "upper",
                      "motor_lag.time_constant": "lower"})
    assert pinned_at_bound(ref) == {"inertia_error.xx", "inertia_error.yy"}
    sd = marginal_sd(ref)
    np.testing.assert_array_equal(sd[:2], [0.0, 0.0])
    # the others: s_ref and the physical prior w combined by precision, (s^-2 + w^-2)^-1/2
    w = prior_spreads(ref.params)
    for k in (2, 3):
        prior = w.get(NAMES[k], w.get(NAMES[k].split(".")[0]))
        expected = ref.s_ref[k] if prior is None else (ref.s_ref[k] ** -2 + prior ** -2) ** -0.5
        assert sd[k] > 0 and np.isclose(sd[k], expected, rtol=1e-12)


def test_without_a_bound_nothing_is_pinned():
    ref = _reference([0.3, 0.2, 0.02, 0.1], {})
    assert pinned_at_bound(ref) == set()
    assert np.all(marginal_sd(ref) > 0)
