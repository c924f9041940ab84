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
