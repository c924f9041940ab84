"""PyFlyt's translational-lift cases against the references' own reading (issue 47;
benchmarks/README.md "PyFlyt: the in-library misses traced"): the measured readings, put
through quadsim.gap.calibrate's practical-significance rule. The references' own readings of
``translational_lift`` (each judged against the other seven) and the two cases' readings
are the values measured on main 08dbdfd (k_h in kg/m per rotor, with their posterior SDs)."""

from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap.calibrate import PRACTICAL_Z, SelfCheck, Spread, negligible

#: the eight PyFlyt references' k_h readings against the other seven (value, posterior SD)
REFERENCES = ((6.194e-4, 4.561e-4), (6.738e-4, 4.375e-4), (7.465e-4, 4.573e-4),
              (4.284e-4, 3.505e-4), (4.793e-4, 3.082e-4), (6.023e-4, 2.980e-4),
              (3.464e-4, 2.457e-4), (5.548e-4, 2.262e-4))
#: cases 24 and 25: the k_h read per flight, its posterior SD, the k_h PyFlyt added
CASES = ((1.0315e-3, 2.919e-4, 8.470e-4), (9.832e-4, 3.348e-4, 9.021e-4))


def _check():
    v, s = np.array(REFERENCES).T
    spread = Spread.of(v, s)
    return spread, SelfCheck(("r",) * 8, (), (), {("translational_lift", ""):
                                                  {"translational_lift.k_h": spread}})


def _lift(value, sd):
    """A determined ``translational_lift`` reading (the Evidence fields the rule reads)."""
    key = "translational_lift.k_h"
    return SimpleNamespace(name="translational_lift",
                           explanation=SimpleNamespace(variant="", parts=()),
                           values={key: value}, post_sd={key: sd}, determined={key: True},
                           log_z=0.0)


def test_the_references_read_a_lift_of_their_own():
    """Their mean 5.6e-4 kg/m is 11.9 standard errors from zero: a lift-like trait they share,
    with a physical spread (9.7e-5) below each reading's own noise (3.6e-4 RMS)."""
    spread, _ = _check()
    assert spread.mean == pytest.approx(5.560e-4, rel=1e-3)
    assert spread.sd == pytest.approx(9.67e-5, rel=1e-2)
    assert spread.noise == pytest.approx(3.58e-4, rel=1e-2)
    assert spread.mean / spread.mean_se == pytest.approx(11.9, rel=1e-2)


@pytest.mark.parametrize("value, sd, added", CASES)
def test_the_lift_cases_as_read_are_no_difference_and_at_their_true_size_would_not_be(
        value, sd, added):
    """As read (56 % / 47 % of the k_h added above the references' mean) both lie within
    the band; the references' mean plus the k_h PyFlyt added, read with the same noise,
    would lie beyond it, by 7e-5 / 5e-5: at the edge of what one flight resolves."""
    spread, check = _check()
    assert negligible(_lift(value, sd), check)
    assert not negligible(_lift(spread.mean + added, sd), check)
    band = 1.96 * np.hypot(sd, spread.mean_se) + PRACTICAL_Z * spread.sd
    assert (value - spread.mean) / added == pytest.approx(0.56 if value > 1e-3 else 0.47,
                                                          abs=0.01)
    assert added - band == pytest.approx(7.4e-5 if value > 1e-3 else 4.6e-5, abs=0.1e-5)
