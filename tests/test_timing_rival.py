"""Per flight, a rotor timing the data cannot separate into a lag or a delay is stated as
both (quadsim.gap.judge.timing_rival, quadsim.gap.words.timing_words; issue 47: drone-models'
case 24, rotor speeds logged 11.6 ms late, read as a 62 ms lag or a 9 ms delay whose rotor
residuals differ by 0.5-7 % against the references' spread of 17-19 % on the log scale)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from quadsim.gap.judge import Baseline, timing_rival
from quadsim.gap.words import timing_words

SPREAD = np.full(10, 0.18)      # the references' lack-of-fit spread, log scale
BASE = Baseline(np.zeros(10), SPREAD, 60, 8, "references")


def _ev(name, ms, log_z):
    return SimpleNamespace(name=name, ms=np.asarray(ms, float), log_z=log_z)


def test_lag_and_delay_within_the_references_spread_are_both_stated():
    """Case 24's numbers: rotor mean squares 0.379/0.399/0.443/0.359 (lag) against
    0.408/0.414/0.452/0.354 (delay), |log ratio| at most 0.074 < 0.18 on every channel,
    the wrench the largest at Fz log(0.713/0.639) = 0.109: the delay is the rival, whatever
    the evidence's margin (6.3 log units)."""
    wrench_lag = [0.561, 0.545, 0.713, 0.213, 0.206, 0.473]
    wrench_delay = [0.564, 0.546, 0.639, 0.235, 0.221, 0.476]
    lag = _ev("motor_lag", wrench_lag + [0.379, 0.399, 0.443, 0.359], -155.9)
    delay = _ev("signal_delay", wrench_delay + [0.408, 0.414, 0.452, 0.354], -162.2)
    weaker = _ev("signal_delay", wrench_delay + [0.5, 0.5, 0.5, 0.5], -170.0)
    rows = [_ev("no_difference", np.ones(10), -168.7), lag, delay, weaker]
    assert timing_rival("motor_lag", lag, rows, BASE) is delay
    assert timing_rival("signal_delay", delay, rows, BASE) is lag


def test_a_rival_beyond_the_spread_on_one_channel_is_separated():
    """Case 16 (a true 95 ms lag): the delay leaves rotor 1 at 1.02 against the lag's
    0.42, log ratio 0.89 > 0.18: one name. A lead that is no timing has no rival."""
    lag = _ev("motor_lag", [0.65, 0.49, 0.53, 0.2, 0.19, 0.46, 0.42, 0.49, 0.48, 0.49], -173.8)
    delay = _ev("signal_delay", [0.67, 0.49, 1.22, 0.48, 0.35, 0.48, 1.02, 1.11, 1.21, 1.34],
                -429.1)
    assert timing_rival("motor_lag", lag, [lag, delay], BASE) is None
    assert timing_rival("mass_offset", lag, [lag, delay], BASE) is None
    edge = _ev("signal_delay", lag.ms * np.exp(np.r_[np.zeros(9), 0.181]), -180.0)
    assert timing_rival("motor_lag", lag, [lag, edge], BASE) is None
    inside = _ev("signal_delay", lag.ms * np.exp(np.r_[np.zeros(9), 0.179]), -180.0)
    assert timing_rival("motor_lag", lag, [lag, inside], BASE) is inside


def test_the_answer_states_both_timings():
    text = timing_words({"name": "motor_lag", "magnitude": "a 62 ms lag"},
                        {"name": "signal_delay", "magnitude": "a 9 ms delay"})
    assert "a 62 ms lag (motor_lag), or a 9 ms delay (signal_delay)" in text
    assert "cannot separate" in text
