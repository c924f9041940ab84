"""The bounded fits solved through the residual's R factor (quadsim.gap.lsq, issue 43 item 7)
against scipy's ``least_squares`` on the full residual: the same iterates up to rounding."""
import numpy as np
import pytest
from scipy.optimize import least_squares

from quadsim.gap.lsq import compact_least_squares, forward_steps


def _problem(m=4000, seed=0):
    """A tall bounded exponential-and-sine fit (m samples, 4 parameters) whose optimum puts
    one parameter on its upper bound."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 4.0, m)
    truth = np.array([1.3, -0.7, 2.1, 0.4])
    data = (truth[0] * np.exp(truth[1] * t) + truth[3] * np.sin(truth[2] * t)
            + 0.01 * rng.standard_normal(m))

    def fun(x):
        return x[0] * np.exp(x[1] * t) + x[3] * np.sin(x[2] * t) - data

    lower = np.array([0.0, -2.0, 1.0, -1.0])
    upper = np.array([1.2, 0.0, 3.0, 1.0])          # truth[0] = 1.3 lies beyond: bound active
    return fun, np.array([0.5, -0.1, 1.8, 0.0]), (lower, upper)


@pytest.mark.parametrize("start", [None, "zero"])
def test_the_compact_solver_takes_scipys_steps(start):
    fun, x0, bounds = _problem()
    if start == "zero":             # a zero start: scipy's fallback step sqrt(eps)
        bounds = (bounds[0] - x0, bounds[1] - x0)
        shifted = fun
        x0_ = x0.copy()

        def fun(z, shifted=shifted, x0_=x0_):
            return shifted(x0_ + z)

        x0 = np.zeros(4)
    old = least_squares(fun, x0, bounds=bounds, diff_step=1e-4, max_nfev=40, method="trf",
                        x_scale=1.0)
    new = compact_least_squares(fun, x0, bounds=bounds, diff_step=1e-4, max_nfev=40)
    assert (new.status, new.nfev, new.njev) == (old.status, old.nfev, old.njev)
    assert np.array_equal(new.active_mask, old.active_mask)
    assert new.active_mask[0] == 1                  # the bound is reached in both
    np.testing.assert_allclose(new.x, old.x, rtol=1e-9, atol=1e-12)
    assert new.cost == pytest.approx(old.cost, rel=1e-12)
    np.testing.assert_allclose(new.fun, old.fun, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(new.jac.T @ new.jac, old.jac.T @ old.jac, rtol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(new.jac, axis=0),
                               np.linalg.norm(old.jac, axis=0), rtol=1e-8)


def test_the_forward_steps_are_scipys():
    """The steps of scipy's 2-point differences with a relative step and bounds: the
    relative one, the absolute fallback at zero, a step turned back from a near bound, a
    step cut to the farther bound where neither side fits."""
    x = np.array([2.0, 0.0, 1.0 - 1e-6, 0.5])
    lower = np.array([-5.0, -1.0, 0.0, 0.5 - 1e-9])
    upper = np.array([5.0, 1.0, 1.0, 0.5 + 2e-9])
    h = forward_steps(x, lower, upper, 1e-4)
    assert h[0] == 2e-4
    assert h[1] == np.finfo(float).eps ** 0.5
    assert h[2] == -(1e-4 * (1.0 - 1e-6))
    assert h[3] == pytest.approx(2e-9, rel=1e-6)     # above >= below: to the upper bound


def test_the_calibration_fit_is_the_full_residuals_fit():
    """fit_candidate with compact=True against the full least squares on two generated
    flights: the same values, standard errors and identifiability."""
    from benchmarks.synthetic import synthetic_flight
    from quadsim.gap.calibrate import per_flight_candidate
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import (
        fit_candidate,
        fit_motor_map,
        noise_floor,
        noise_scale,
        residuals,
    )
    from quadsim.vehicle.params import load_params

    params = load_params("crazyflie21")
    states = [f.fit for f in prepare([synthetic_flight(params, [], seed=s, duration=3.0)
                                      for s in (0, 1)], params)]
    params = fit_motor_map(states, params)
    sigma = noise_scale(np.concatenate([residuals(s, params, [], rotor_channel=True)
                                        for s in states]), float(states[0].t[1] - states[0].t[0]),
                        floor=noise_floor(params, True))
    cand = per_flight_candidate(True, False)
    old = fit_candidate(cand, states, params, sigma, rotor_channel=True, max_nfev=20)
    new = fit_candidate(cand, states, params, sigma, rotor_channel=True, max_nfev=20,
                        compact=True)
    # the first 20 evaluations; the thrust scale and the curve's curvature are nearly
    # collinear on these noiseless flights (condition 1e5-1e6), which amplifies round-off:
    # within 5e-5 of each parameter's typical size (measured 7e-6; on the 20 real
    # references, the whole calibration: 1e-9 relative)
    from quadsim.gap.fitting import typical_scales

    typical = typical_scales(cand, params)
    np.testing.assert_allclose(new.theta / typical, old.theta / typical, rtol=0, atol=5e-5)
    # standard errors to 1e-5 relative, or 1e-9 of the typical size (the thrust scale's
    # is round-off, 1e-15, in both)
    assert np.all(np.abs(new.stderr - old.stderr) <= 1e-5 * old.stderr + 1e-9 * typical)
    assert new.identifiable == old.identifiable
    assert new.cost == pytest.approx(old.cost, rel=1e-9)
