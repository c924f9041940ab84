"""The shared rotor delay's prior: the references' predictive spread, the estimator's
repeatability counted once (quadsim.gap.explanations.reference_delay_sd)."""

from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap.explanations import predictive_delay_sd, reference_delay_sd
from quadsim.logs.delays import REPEAT_TOL_S


def test_the_estimators_error_is_counted_once_not_added_to_the_references_spread():
    # the references' estimates already carry the estimator's error: with many references
    # the prior is their spread itself, not hypot(spread, repeatability)
    sd = 1.8e-3
    assert predictive_delay_sd(sd, 10 ** 6, REPEAT_TOL_S) == pytest.approx(sd, rel=1e-5)
    assert np.hypot(sd, REPEAT_TOL_S) > 1.9 * sd     # the rule it replaces


def test_the_predictive_spread_in_closed_form():
    # s_mod^2 = (s0^2 + (n - 1) s^2) / n, times (1 + 1/n); PyFlyt's 8 references: 1.84 ms
    s, n, s0 = 1.8364853855744596e-3, 8, 3e-3
    want = np.sqrt((s0 ** 2 + 7 * s ** 2) / 8 * (9 / 8))
    assert predictive_delay_sd(s, n, s0) == pytest.approx(want, rel=1e-12)
    assert want == pytest.approx(2.141e-3, abs=1e-6)
    ref = SimpleNamespace(delays_ms={"rotor": (4.3125, 1e3 * s, n)})
    assert reference_delay_sd(ref) == pytest.approx(want, rel=1e-12)
    # no references' estimate: the repeatability alone; one: it, with its mean's own error
    assert reference_delay_sd(SimpleNamespace(delays_ms={})) == REPEAT_TOL_S
    assert predictive_delay_sd(0.0, 1, s0) == pytest.approx(s0 * np.sqrt(2), rel=1e-12)


def test_one_more_nominal_flight_falls_inside_the_prior_as_often_as_it_says():
    # references' estimates and one more flight's drawn from the same population (spread
    # equal to the repeatability, the case the moderation assumes): |new - mean| beyond
    # 1.96 predictive spreads about 5 % of the time (a t with n degrees of freedom: 8.5 %
    # at n = 8), not the 1 % a doubled-count prior gives (1.96 sqrt(2) / sqrt(9/8) = 2.6 SDs)
    rng = np.random.default_rng(4)
    n, draws, s0 = 8, 20000, REPEAT_TOL_S
    refs = rng.normal(0.0, s0, (draws, n))
    new = rng.normal(0.0, s0, draws)
    sds = refs.std(axis=1, ddof=1)
    pred = np.sqrt((s0 ** 2 + (n - 1) * sds ** 2) / n * (1 + 1 / n))
    outside = np.mean(np.abs(new - refs.mean(axis=1)) > 1.96 * pred)
    assert 0.04 < outside < 0.10
    doubled = np.mean(np.abs(new - refs.mean(axis=1)) > 1.96 * np.hypot(sds, s0))
    assert doubled < 0.02
