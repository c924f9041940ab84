"""The lack-of-fit test of quadsim.gap.judge: a channel beyond the references' residual is
"not in the library", unless the reading leaves no more than FORM_ERROR of the flight's gap
(the form error of the library's effect). Closed-form mean squares, no fitting."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap.judge import FORM_ERROR, LOF_P, lack_of_fit
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
    """quadsim.gap.moderated (Smyth 2004): channels whose spreads differ 4x keep them
    (each moderated spread within 35 % of its own truth on 8 flights x 10 channels, the quiet
    ones below the pooled spread, the noisy ones above it on average); channels alike come out
    at the pooled spread when their scatter is no more than chance (excess <= 0: exactly the
    pooled spread and its C (n - 1) degrees of freedom)."""
    from quadsim.gap.moderated import moderated_spread

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

    from quadsim.gap.envelope import Position, local_reference

    model = dataclasses.make_dataclass("Model", ["lof_sd", "lof_dof", "lof_pooled", "envelope"])
    ref = model(np.array([0.1, 0.5]), 9, (0.3, 14), None)     # no trend: the envelope alone
    inside = local_reference(ref, Position(np.zeros(3), 0.0, "speed", None, "", None))
    np.testing.assert_array_equal(inside.lof_sd, [0.1, 0.5])
    assert inside.lof_dof == 9
    outside = local_reference(ref, Position(np.zeros(3), 0.2, "speed", None, "", None))
    np.testing.assert_array_equal(outside.lof_sd, [0.3, 0.5])
    assert outside.lof_dof == 14
