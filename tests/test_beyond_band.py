"""Beyond the references' envelope, "no difference" only as far as the data carry it (issue
47): a reading counted as no difference by practical significance whose interval is wider
than the references' band (calibrate.band_share, judge.sure_null)."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import norm

from quadsim.gap.calibrate import (
    PRACTICAL_Z,
    SelfCheck,
    Spread,
    band_share,
    negligible,
)
from quadsim.gap.judge import beyond_envelope, null_members, posterior, sure_null

KEY = ("body_drag", "")
AREA = "body_drag.area"


def _evidence(value, sd, log_z=0.0, name="body_drag"):
    return SimpleNamespace(name=name, explanation=SimpleNamespace(variant="", parts=()),
                           values={AREA: value} if name != "no_difference" else {},
                           post_sd={AREA: sd} if name != "no_difference" else {},
                           determined={AREA: True} if name != "no_difference" else {},
                           log_z=log_z)


def _check(mean=2e-4, sd=0.1e-4, mean_se=0.02e-4):
    return SelfCheck(("a", "b"), ("no_significant_gap",) * 2, (),
                     {KEY: {AREA: Spread(mean, sd, 10, 0.3e-4, mean_se)}})


def test_band_share_is_the_posterior_mass_within_the_references_band():
    check = _check()
    s = check.spreads[KEY][AREA]
    scale = np.hypot(0.3e-4, s.mean_se)
    # a reading at the references' mean, three times wider than their band: negligible
    # (its interval does not lie beyond the band) and only partly within it
    ev = _evidence(s.mean, 0.3e-4)
    assert negligible(ev, check)
    band = PRACTICAL_Z * s.sd
    assert band_share(ev, check) == pytest.approx(2 * norm.cdf(band / scale) - 1)
    assert band_share(ev, check) == pytest.approx(0.4941, abs=1e-3)
    # off the mean by one band: the mass between the band's edges
    off = _evidence(s.mean + band, 0.3e-4)
    assert band_share(off, check) == pytest.approx(norm.cdf(0.0) - norm.cdf(-2 * band / scale))
    # a precise reading inside the band: all of it; far outside: none
    assert band_share(_evidence(s.mean, 1e-9), check) == pytest.approx(1.0)
    assert band_share(_evidence(s.mean + 10 * band, 1e-9), check) == pytest.approx(0.0)
    # nothing to compare with: 1 (negligible says False there: the statistical rule alone)
    assert band_share(ev, None) == 1.0
    assert band_share(ev, SelfCheck((), (), (), {})) == 1.0


def test_sure_null_weighs_each_reading_by_its_share_within_the_band():
    check = _check()
    null = _evidence(0.0, 0.0, log_z=-10.0, name="no_difference")
    wide = _evidence(2e-4, 0.3e-4, log_z=-10.0 + np.log(6.0))   # 6x the null's evidence
    rows = [null, wide]

    def near(ev):
        return negligible(ev, check)

    post = posterior(rows, near)
    assert post[0][0] == "no_difference" and post[0][1] == pytest.approx(1.0)
    # the null row weighs 1/7 of the group (its prior: one reading), the reading 6/7
    members = null_members(rows, near, lambda ev: band_share(ev, check))
    assert [w for w, _, _ in members] == pytest.approx([1 / 7, 6 / 7])
    share = band_share(wide, check)
    assert sure_null(rows, near, lambda ev: band_share(ev, check)) == pytest.approx(
        1 / 7 + 6 / 7 * share)
    # a reading beyond the band is not in the group: the null alone, all of it sure
    far = _evidence(4e-4, 0.01e-4, log_z=-10.0)
    assert sure_null([null, far], near, lambda ev: band_share(ev, check)) == 1.0
    # an empty group
    assert sure_null([far], near, lambda ev: band_share(ev, check)) == 1.0


def test_beyond_envelope_reads_the_flights_distance():
    assert not beyond_envelope(SimpleNamespace(place=None))
    assert not beyond_envelope(SimpleNamespace(place=SimpleNamespace(distance=0.0)))
    assert beyond_envelope(SimpleNamespace(place=SimpleNamespace(distance=0.3)))
    assert not beyond_envelope(SimpleNamespace())
