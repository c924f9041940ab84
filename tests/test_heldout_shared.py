"""Held out against nominal references, the lack of fit is what the training flights share
(issue 47, judge.against_reference): each training flight is judged as per flight, at its
own place on the references' envelope, and a channel is a lack of fit only where it lies
beyond on every training flight. The third --references run's no-effect misses were one
training flight each, the fastest (flown 1.1x the held-out flight's speed, 1.7-1.9x the
references' largest specific-force variation): alone beyond the references there (per flight
that flight is `unexplained` too), the other training flight and the held-out flight clear."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import t as student_t

from quadsim.gap.judge import (
    LOF_P,
    Baseline,
    against_reference,
    alone,
    lack_of_fit,
    mean_squares,
    outcome_of,
    training_lack,
)
from quadsim.vehicle.params import load_params

SIGMA = 100 * np.array([0.02, 0.02, 0.02, 1e-3, 1e-3, 1e-3])
N = 2000


def _model(cf, move=0.0, extra=0.0):
    """The references' model (10 references, log mean square 0, spread 0.1 per channel) at
    a place where their trend moves the lack-of-fit mean by ``move`` and its variance by
    ``extra`` (the fields of quadsim.gap.reference.local_reference the rule reads)."""
    c = len(SIGMA)
    return SimpleNamespace(params=cf, rotor=False, sigma=SIGMA, lof_mean=np.full(c, move),
                           lof_sd=np.sqrt(0.1 ** 2 + np.full(c, extra)), lof_dof=9,
                           names=tuple("abcdefghij"))


def _flight(rng, fy_ms):
    """(N, 6) residual: noise of SIGMA, Fy's mean square ``fy_ms`` sigma^2."""
    r = rng.standard_normal((N, 6))
    r[:, 1] *= np.sqrt(fy_ms)
    return SIGMA * r


def test_a_gap_on_one_training_flight_alone_is_not_a_shared_difference():
    """No effect, one training flight flown outside the references' envelope (their trend
    expects 4x the mean square there) leaving 30x on Fy: beyond them at its own place
    (z = log 7.5 / (sqrt(0.06) sqrt(1.1)) = 7.8 against the per-flight limit 5.5), the other
    training flight (inside, 1x) not: no lack of fit, "no difference" stays the answer, the
    lone channel stated. The same 30x on both flights is shared: a lack of fit, and a named
    reading that removes it leaves none (a real change there is still named)."""
    cf = load_params("crazyflie21")
    rng = np.random.default_rng(11)
    inside, outside = _model(cf), _model(cf, move=np.log(4.0), extra=0.05)
    placed = (outside, inside)
    limit = float(student_t.ppf(1 - LOF_P / 6, 9))
    null = SimpleNamespace(train_residuals=[_flight(rng, 30.0), _flight(rng, 1.0)])
    per = training_lack(null, null, inside, placed)
    assert set(per[0]) == {"Fy"} and per[1] == {}
    z = (np.log(30.0) - np.log(4.0)) / (np.sqrt(0.06) * np.sqrt(1.1))
    assert per[0]["Fy"][1] == pytest.approx(z, abs=0.3) and z > limit + 2
    # closed form: RMS over the references' typical there, sqrt(30 / 4)
    assert per[0]["Fy"][0] == pytest.approx(np.sqrt(7.5), rel=0.06)
    lack, left, share = against_reference(null, null, inside, placed)
    assert lack == {} and left == {} and share == float("inf")
    assert outcome_of("no_difference", lack, {}) == "no_significant_gap"
    assert set(alone(per)) == {"Fy"} and alone(per)["Fy"][0] == 0
    # the third run's rule (both flights at one place, here the outside one; the largest z
    # over them, Bonferroni over the two) made the lone flight's gap `unexplained`
    old = lack_of_fit(mean_squares(null.train_residuals, SIGMA), Baseline.of_reference(outside),
                      outside)
    assert set(old) == {"Fy"}
    # a change every training flight shows, at each one's place: a lack of fit under "no
    # difference", none under the reading that removes it
    shared = SimpleNamespace(train_residuals=[_flight(rng, 120.0), _flight(rng, 30.0)])
    lack, _, _ = against_reference(shared, shared, inside, placed)
    assert set(lack) == {"Fy"}
    # the shared value is the flight where it lies least beyond: sqrt(120 / 4) vs sqrt(30)
    assert lack["Fy"][0] == pytest.approx(np.sqrt(30.0), rel=0.06)
    assert outcome_of("no_difference", lack, {}) == "unexplained"
    named = SimpleNamespace(train_residuals=[_flight(rng, 1.0), _flight(rng, 1.0)])
    lack, left, share = against_reference(named, shared, inside, placed)
    assert lack == {} and left == {} and share < 0.01
    assert outcome_of("mass_offset", lack, {}) == "effect"
