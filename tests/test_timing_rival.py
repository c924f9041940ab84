"""Per flight, a rotor timing the data cannot separate into a lag or a delay is stated as
both (quadsim.gap.judge.timing_rival, quadsim.gap.calibrate.timing_margin,
quadsim.gap.words.timing_words; issue 47: drone-models' case 24, rotor speeds logged
11.6 ms late, read as a 62 ms lag 6.3 log units above a 9 ms delay, where its eight
references, each judged against the others, give the lag -1.1..+8.6 over the delay)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import t as student_t

from quadsim.gap.calibrate import timing_margin
from quadsim.gap.judge import LOF_P, timing_rival
from quadsim.gap.words import timing_words

#: drone-models' references: the lag's margin over the delay, each against the others
REFS = np.array([-1.1, -1.5, -0.6, 1.0, 2.3, 4.4, 5.9, 8.6])
CHECK = SimpleNamespace(timing=REFS)
#: the bound in closed form: mean + t(1 - 1e-3, 7) sd sqrt(1 + 1/8)
BOUND = REFS.mean() + student_t.ppf(1 - LOF_P, 7) * REFS.std(ddof=1) * np.sqrt(1 + 1 / 8)


def _ev(name, log_z):
    return SimpleNamespace(name=name, log_z=log_z)


def test_the_margin_is_each_readings_best_row():
    rows = [_ev("no_difference", -168.7), _ev("motor_lag", -155.9), _ev("motor_lag", -163.4),
            _ev("signal_delay", -162.2)]
    assert timing_margin(rows) == pytest.approx(6.3, abs=1e-12)
    assert timing_margin(rows[:3]) is None


def test_a_margin_within_the_references_margins_states_both():
    """Case 24: lag over delay by 6.3 < bound (about 20): the delay is the rival; case 25
    the other way, the delay over the lag by 2.4 (the references' -8.6..+1.5 that way)."""
    lag, delay = _ev("motor_lag", -155.9), _ev("signal_delay", -162.2)
    assert 6.3 < BOUND
    assert timing_rival("motor_lag", [lag, delay], CHECK) is delay
    lag25, delay25 = _ev("motor_lag", -199.1), _ev("signal_delay", -196.7)
    assert timing_rival("signal_delay", [lag25, delay25], CHECK) is lag25


def test_a_margin_beyond_the_references_names_one():
    """Just beyond the bound, or a margin like a true 95 ms lag's (255): one name; a lead
    that is no timing, or fewer than 3 references' margins: no rival."""
    delay = _ev("signal_delay", -200.0)
    assert timing_rival("motor_lag", [_ev("motor_lag", -200.0 + BOUND + 1e-6), delay],
                        CHECK) is None
    assert timing_rival("motor_lag", [_ev("motor_lag", -200.0 + BOUND - 1e-6), delay],
                        CHECK) is delay
    assert timing_rival("motor_lag", [_ev("motor_lag", 55.3), delay], CHECK) is None
    assert timing_rival("mass_offset", [_ev("motor_lag", -199.0), delay], CHECK) is None
    assert timing_rival("motor_lag", [_ev("motor_lag", -199.0), delay],
                        SimpleNamespace(timing=REFS[:2])) is None


def test_the_answer_states_both_timings():
    text = timing_words({"name": "motor_lag", "magnitude": "a 62 ms lag"},
                        {"name": "signal_delay", "magnitude": "a 9 ms delay"})
    assert "a 62 ms lag (motor_lag), or a 9 ms delay (signal_delay)" in text
    assert "cannot separate" in text
