"""The lack-of-fit test of quadsim.gap.judge: a channel beyond the references' residual is
"not in the library", unless the reading leaves no more than FORM_ERROR of the flight's gap
(the form error of the library's effect). Closed-form mean squares, no fitting."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap.judge import FORM_ERROR, LOF_P, Baseline
from quadsim.gap.judge import lack_of_fit as _lack_of_fit
from quadsim.vehicle.params import load_params

CHANNELS = 6


def _reference():
    """Ten references whose log mean squares scatter by 0.3 about 0 on every channel; a
    sigma far above the noise floor, so the floor never hides a channel."""
    return SimpleNamespace(names=[f"r{k}" for k in range(10)], lof_sd=0.3,
                           lof_mean=np.zeros(CHANNELS), lof_dof=CHANNELS * 9,
                           sigma=np.full(CHANNELS, 10.0), params=load_params("crazyflie21"),
                           rotor=False)


def _ev(ms):
    return SimpleNamespace(ms=np.asarray(ms, float))


def lack_of_fit(ev, ref, null=None):
    """The per-flight use of the one rule: against the reference flights, "no difference"
    never its own form error."""
    return _lack_of_fit(ev.ms, Baseline.of_reference(ref), ref,
                        null_ms=None if null is None or null is ev else null.ms)


def test_a_channel_far_beyond_the_references_lacks_fit():
    ref = _reference()
    lead = _ev([1, 1, 9, 1, 1, 1])                   # Fz at 3x the references' RMS
    lack = lack_of_fit(lead, ref)
    assert list(lack) == ["Fz"] and lack["Fz"][0] == pytest.approx(3.0, rel=1e-12)
    # the limit: the Student-t quantile at 1 - LOF_P / C on log(ms) / (0.3 sqrt(1.1))
    from scipy.stats import t as student_t
    limit = student_t.ppf(1 - LOF_P / CHANNELS, CHANNELS * 9) * 0.3 * np.sqrt(1.1)
    assert lack["Fz"][1] == pytest.approx(np.log(9) / (0.3 * np.sqrt(1.1)), rel=1e-12)
    assert not lack_of_fit(_ev([1, 1, 0.99 * np.exp(limit), 1, 1, 1]), ref)


def test_a_reading_that_leaves_at_most_the_form_error_of_the_gap_explains_the_flight():
    """"No difference" left an excess of 400 (sigma^2 units) on Fz; a reading leaving 8 there
    (2 %) explains the flight although Fz is at 3x the references'; one leaving 24 (6 %,
    beyond FORM_ERROR = 5 %) does not."""
    ref = _reference()
    null = _ev([1, 1, 401, 1, 1, 1])
    assert FORM_ERROR == pytest.approx(0.05)
    assert lack_of_fit(_ev([1, 1, 9, 1, 1, 1]), ref, null) == {}
    assert list(lack_of_fit(_ev([1, 1, 25, 1, 1, 1]), ref, null)) == ["Fz"]
    # "no difference" itself is never its own form error
    assert list(lack_of_fit(null, ref, null)) == ["Fz"]


def test_moderated_spread_follows_the_channels_own_scatter():
    """quadsim.gap.reference (Smyth 2004): channels whose spreads differ 4x keep them
    (each moderated spread within 35 % of its own truth on 8 flights x 10 channels, the quiet
    ones below the pooled spread, the noisy ones above it on average); channels alike come out
    at the pooled spread when their scatter is no more than chance (excess <= 0: exactly the
    pooled spread and its C (n - 1) degrees of freedom)."""
    from quadsim.gap.reference import moderated_spread

    rng = np.random.default_rng(7)
    truth = np.array([0.1] * 5 + [0.4] * 5)
    x = rng.normal(size=(8, 10)) * truth
    spread, dof, (pooled, pooled_dof) = moderated_spread(x)
    assert pooled_dof == 70 and 8 <= dof < 70
    np.testing.assert_allclose(spread, truth, rtol=0.35)
    assert spread[:5].max() < pooled < spread[5:].mean()
    # identical per-channel variances: no scatter beyond chance
    same = np.tile(np.array([[1.0], [-1.0], [1.0], [-1.0], [1.0], [-1.0], [1.0], [-1.0]]),
                   (1, 10)) * 0.3
    spread, dof, (pooled, pooled_dof) = moderated_spread(same)
    assert dof == pooled_dof == 70
    np.testing.assert_allclose(spread, pooled, rtol=1e-12)


def test_outside_the_envelope_a_channel_is_tested_with_at_least_the_pooled_spread():
    """envelope.local_reference: inside the references' envelope each channel keeps its own
    (moderated) spread; a flight outside it gets max(own, pooled) with the pooled degrees of
    freedom, since a quiet channel's spread says nothing of how it grows beyond them."""
    import dataclasses

    from quadsim.gap.reference import Position, local_reference

    model = dataclasses.make_dataclass("Model", ["lof_sd", "lof_dof", "lof_pooled", "envelope"])
    ref = model(np.array([0.1, 0.5]), 9, (0.3, 14), None)     # no trend: the envelope alone
    inside = local_reference(ref, Position(np.zeros(3), 0.0, "speed", None, "", None))
    np.testing.assert_array_equal(inside.lof_sd, [0.1, 0.5])
    assert inside.lof_dof == 9
    outside = local_reference(ref, Position(np.zeros(3), 0.2, "speed", None, "", None))
    np.testing.assert_array_equal(outside.lof_sd, [0.3, 0.5])
    assert outside.lof_dof == 14


def test_one_rule_counts_every_judged_flight_in_its_bonferroni_limit():
    """judge.lack_of_fit is the rule of both modes: with H judged flights (held out) the
    limit is the Student-t quantile at 1 - LOF_P / (C H); a channel z between the C-limit
    and the 2C-limit lacks fit on one flight, not among two. The ratio is the RMS over the
    baseline's typical, the largest z over the flights is kept."""
    from scipy.stats import t as student_t

    ref = _reference()
    base = Baseline.of_reference(ref)
    scale = 0.3 * np.sqrt(1.1)
    one = student_t.ppf(1 - LOF_P / CHANNELS, CHANNELS * 9)
    two = student_t.ppf(1 - LOF_P / (2 * CHANNELS), CHANNELS * 9)
    z = 0.5 * (one + two)
    ms = [1, 1, float(np.exp(z * scale)), 1, 1, 1]
    lack = _lack_of_fit(ms, base, ref)
    assert list(lack) == ["Fz"] and lack["Fz"][1] == pytest.approx(z, rel=1e-12)
    assert lack["Fz"][0] == pytest.approx(np.exp(0.5 * z * scale), rel=1e-12)
    assert _lack_of_fit([ms, [1] * CHANNELS], base, ref) == {}


def test_held_out_baseline_pools_the_training_flights_spread():
    """Baseline.of_training: log mean squares of the training pieces, mean per channel,
    one spread pooled over channels with C (n - 1) degrees of freedom; one training flight
    is cut in its two halves."""
    sigma = np.ones(2)
    flights = [np.full((10, 2), 1.0), np.full((10, 2), np.e)]     # ms 1 and e^2
    base = Baseline.of_training(flights, sigma)
    np.testing.assert_allclose(base.mean, [1.0, 1.0], rtol=1e-12)
    # deviations +-1 on 2 channels x 2 flights: sum 4 over C (n - 1) = 2
    np.testing.assert_allclose(base.spread, [np.sqrt(2.0)] * 2, rtol=1e-12)
    assert (base.dof, base.count, base.against) == (2, 2, "training")
    halves = Baseline.of_training([np.concatenate(flights)], sigma)
    assert halves.count == 2 and halves.dof == 2
    np.testing.assert_allclose(halves.mean, base.mean, rtol=1e-12)
