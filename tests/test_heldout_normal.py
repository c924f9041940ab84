"""Issue 47 in held-out mode: the training flights' discrepancy term and practical
significance (quadsim.gap.diagnose)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.effects import make_effect
from quadsim.gap import diagnose
from quadsim.gap.diagnose import _beyond
from quadsim.gap.reference import Discrepancy, columns
from quadsim.vehicle.params import load_params

EFFECTS = ["mass_offset", "com_offset", "thrust_mismatch", "rotor_drag"]


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def _logs(cf, effects, seeds):
    return [synthetic_flight(cf, effects, seed=s, duration=4.0, speed=1.2) for s in seeds]


def test_a_trait_the_training_flights_share_is_normal_and_a_change_on_top_is_named(cf):
    """Every flight carries a quadratic body drag (C_d A 40 cm^2) the candidates hold only
    as a linear rotor drag: without the training flights' discrepancy term rotor_drag was
    named at > 99 % (+3 mN per m/s); with it the no-effect held-out flight is
    no_significant_gap, and +4 g on every flight is named mass_offset at +4 g."""
    drag = [make_effect("body_drag", cd_area=0.004)]
    logs = _logs(cf, drag, range(60, 66))
    v = diagnose(logs[:5], cf, holdout=logs[5:], kstep=False, max_combination=1,
                 effects=EFFECTS)["verdict"]
    assert v["outcome"] == "no_significant_gap", v["answer"]
    logs = _logs(cf, drag + [make_effect("mass_offset", mass=0.004)], range(60, 66))
    v = diagnose(logs[:5], cf, holdout=logs[5:], kstep=False, max_combination=1,
                 effects=EFFECTS)["verdict"]
    assert v["outcome"] == "effect" and v["effect"] == "mass_offset", v["answer"]
    assert v["params"]["mass_offset.mass"] == pytest.approx(0.004, abs=5e-4)


def test_the_held_out_likelihood_marginalises_the_flights_own_coefficients_exactly():
    """_beyond's log-likelihood is the exact Gaussian marginal of r = X beta + e (beta ~
    N(0, L Lᵀ), e ~ N(0, 1 / w)), computed independently from the full covariance; its
    residual is r less the posterior mean of X beta."""
    rng = np.random.default_rng(3)
    n = 40
    states = SimpleNamespace(t=np.arange(n) * 0.01, quat=np.tile([1.0, 0, 0, 0], (n, 1)),
                             velocity=rng.normal(size=(n, 3)),
                             body_rate=rng.normal(size=(n, 3)),
                             body_accel=rng.normal(size=(n, 3)))
    names = ("|v|v_x", "wd_x", "wd_y", "wd_z")
    factor = np.tril(rng.uniform(0.2, 1.0, (4, 4)))
    disc = Discrepancy((0,), (names,), (np.zeros(4),), (factor,), 6, np.zeros(6))
    weights = np.array([4.0, 1.0, 2.0, 1.0, 1.0, 3.0])
    reference = SimpleNamespace(discrepancy=disc, weights=weights)
    r = rng.normal(size=(n, 6))
    got, ll = _beyond(r, states, reference)
    # independently: the full covariance of vec(r), row n C + c
    x = columns(states, disc, weights) / np.tile(np.sqrt(weights), n)[:, None]
    cov = np.diag(np.tile(1.0 / weights, n)) + x @ x.T
    sign, logdet = np.linalg.slogdet(cov)
    vec = r.ravel()
    exact = -0.5 * vec @ np.linalg.solve(cov, vec) - 0.5 * logdet \
        - 0.5 * np.sum(np.log(np.tile(weights, n)))      # _beyond leaves out log det(1/w)
    assert ll == pytest.approx(exact, rel=1e-10, abs=1e-8)
    mean = x @ (x.T @ np.linalg.solve(cov, vec))
    assert np.allclose(got.ravel(), vec - mean)
