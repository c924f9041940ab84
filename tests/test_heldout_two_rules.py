"""Held out, the two per-flight rules of issue 47 through the same functions (issue 43, "one
judgment for both modes"): a rotor timing the flights do not separate into a lag or a delay
is stated as both (quadsim.gap.judge.timing_rival, its margin per judged flight), and the
named reading's probability is net of "outside the library" against nominal references
(quadsim.gap.judge.rows_with_outside: outside_library and with_outside on the share the lead
leaves on the training flights, each against the references).

Held out, the log evidence is of the training and held-out flights together, so the timing
margin is taken per judged flight against the references' one-flight margins."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import t as student_t

from quadsim.gap.judge import LOF_P, OUTSIDE_LIBRARY, timing_rival
from quadsim.gap.result import Reading

#: drone-models' references: the lag's log-evidence margin over the delay, each judged
#: against the others (tests/test_timing_rival.py)
REFS = np.array([-1.1, -1.5, -0.6, 1.0, 2.3, 4.4, 5.9, 8.6])
BOUND = REFS.mean() + student_t.ppf(1 - LOF_P, 7) * REFS.std(ddof=1) * np.sqrt(1 + 1 / 8)


def _ev(name, log_z):
    return SimpleNamespace(name=name, log_z=log_z)


def test_held_out_the_margin_is_per_judged_flight():
    """Three flights (two training, one held out): a lag 45 log units over the delay is
    15 per flight, within the one-flight bound (about 20): both stated; the same margin on
    one flight is beyond it: one name. Per flight (``flights`` 1) as before."""
    assert 15 < BOUND < 45
    lag, delay = _ev("motor_lag", -455.0), _ev("signal_delay", -500.0)
    check = SimpleNamespace(timing=REFS)
    assert timing_rival("motor_lag", [lag, delay], check, flights=3) is delay
    assert timing_rival("motor_lag", [lag, delay], check) is None
    assert timing_rival("motor_lag", [lag, delay], check, flights=1) is None
    # the bound's edge, per flight: 3 (BOUND -/+ 1e-6)
    near = _ev("motor_lag", -500.0 + 3 * (BOUND - 1e-6))
    far = _ev("motor_lag", -500.0 + 3 * (BOUND + 1e-6))
    assert timing_rival("motor_lag", [near, delay], check, flights=3) is delay
    assert timing_rival("motor_lag", [far, delay], check, flights=3) is None


def _w(name, log_z, flights=(2, 1)):
    """A Weighed-like reading on 2 training flights and 1 held out."""
    return SimpleNamespace(name=name, total=_ev(name, log_z),
                           train_residuals=[None] * flights[0],
                           held_residuals=[None] * flights[1])


def test_held_out_the_rival_timing_is_stated_beside_the_lead():
    """drone-models' case 25 held out against its references (rotor speeds 21.6 ms late):
    the delay -554.24, the lag -569.96: 15.72 log units over 3 flights, 5.24 per flight,
    within the references' bound the delay's way (their margins negated: 16.14), so the lag
    is stated beside it (its posterior row; main held out: `signal_delay` alone,
    confident). A lag 45.76 below is within per flight, beyond as one flight's margin. A
    lead that is no timing, or references without the margins: none."""
    from quadsim.gap.judge import _timing_row  # new (main: none held out)

    delay, lag = _w("signal_delay", -554.2416), _w("motor_lag", -569.9632)
    null = _w("no_difference", -729.9078)
    rows = [_row("signal_delay", 1.0), _row("motor_lag", 1.5e-7), _row("no_difference", 0.0)]
    decision = SimpleNamespace(lead=delay, lead_name="signal_delay", weighed=(null, delay, lag),
                               ranked=[("signal_delay", 1.0, delay), ("motor_lag", 1.5e-7, lag),
                                       ("no_difference", 0.0, null)], rows=rows)
    reference = SimpleNamespace(self_check=SimpleNamespace(timing=REFS))
    bound = -REFS.mean() + student_t.ppf(1 - LOF_P, 7) * REFS.std(ddof=1) * np.sqrt(1 + 1 / 8)
    assert bound == pytest.approx(16.137, abs=1e-3)
    assert _timing_row(decision, reference) is rows[1]
    # a lag 45.76 below: 15.25 per flight, within; one flight's 45.76 is not
    far = _w("motor_lag", -600.0)
    wide = SimpleNamespace(**{**vars(decision), "weighed": (null, delay, far),
                              "ranked": [("signal_delay", 1.0, delay), ("motor_lag", 0.0, far),
                                         ("no_difference", 0.0, null)]})
    assert _timing_row(wide, reference) is rows[1]
    one = SimpleNamespace(**{**vars(wide), "lead": _w("signal_delay", -554.2416, (1, 0))})
    assert _timing_row(one, reference) is None
    mass = SimpleNamespace(**{**vars(decision), "lead_name": "mass_offset"})
    assert _timing_row(mass, reference) is None
    assert _timing_row(decision, SimpleNamespace(self_check=None)) is None


def _row(name, p):
    return Reading(name, p, f"{name} in words", -100.0)


def test_the_lead_is_net_of_outside_the_library_against_references():
    """The per-flight classes on the held-out share: a flagged lead leaving 5 % of the
    training flights' gap keeps p (1 - q), q = OUTSIDE_LIBRARY.probability(0.05) (closed
    form: logistic of (mu_O - mu_R) / sigma^2 ln(0.05 / 0.10) at prior 1/2), the others
    theirs, the sum unchanged; unflagged, nothing moves; leaving 30 % (beyond the classes'
    boundary, 10 %), the outside hypothesis is more probable than the name."""
    from quadsim.gap.judge import rows_with_outside  # new (main: none held out)

    rows = [_row("mass_offset", 0.95), _row("thrust_factor", 0.04), _row("no_difference", 0.01)]
    got, p_out = rows_with_outside(rows, 0.05, True)
    m = OUTSIDE_LIBRARY
    slope = (m.outside_mean - m.right_mean) / m.spread ** 2
    q = 1.0 / (1.0 + np.exp(-slope * np.log(0.05 / 0.10)))
    assert 0.08 < q < 0.09
    assert p_out == pytest.approx(0.95 * q, rel=1e-12)
    assert got[0]["probability"] == pytest.approx(0.95 * (1 - q), rel=1e-12)
    assert got[0]["name"] == "mass_offset" and got[1:] == rows[1:]
    assert sum(r["probability"] for r in got) + p_out == pytest.approx(1.0, rel=1e-12)
    same, none = rows_with_outside(rows, 0.05, False)
    assert none == 0.0 and same == rows
    stand, p_stand = rows_with_outside(rows, 0.30, True)
    assert p_stand > stand[0]["probability"]
