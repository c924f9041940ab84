"""A battery-sag reading's practical significance is the sag on this flight, not its full
voltage alone (issue 47): the references flew at one voltage, so their readings of V_full
are readings of their speed per command; a flight whose battery falls 5 % reads the same
V_full and is 5 % slower per command at its end (quadsim.gap.judge.at_reference_voltage,
negligible_at). Before, the sensor pipeline's two battery-sag flights were called "no
difference" by practical significance and ``unexplained`` by the lack of fit."""

import numpy as np
import pytest

from quadsim.gap.calibrate import SelfCheck, Spread, negligible
from quadsim.gap.evidence import Evidence
from quadsim.gap.explanations import Explanation
from quadsim.gap.judge import at_reference_voltage, negligible_at, rows_at_reference_voltage

KEY = "battery_sag.full_voltage"
V_REF = 4.2
#: the references' readings of V_full (the crazyflie21 pipeline's: 8 flights at 4.2 V)
CHECK = SelfCheck(tuple("abcdefgh"), (), (), {("battery_sag", ""): {
    KEY: Spread(4.20005, 1.6e-4, 8, 1.9e-4, 7.5e-5)}})


def _sag(full=4.19975, sd=4.4e-4):
    expl = Explanation("battery_sag", "", (("battery_sag", {}, ("full_voltage",)),),
                       (V_REF,), (0.42,))
    return Evidence(expl, {KEY: full}, {KEY: sd}, {KEY: 0.42}, {KEY: True}, 0.0,
                    np.ones(10))


def test_the_full_voltage_at_the_references_voltage_in_closed_form():
    """Four quarters of a log falling linearly 4.2 -> 3.99 V (800 samples, no noise): quarter
    q's mean m_q, V_eq = V_full x 4.2 / m_q, its spread V_eq x hypot(sd / V_full, se_q / m_q)
    with se_q the quarter's sample SD over sqrt(200)."""
    vbat = np.linspace(4.2, 3.99, 800)
    ev = _sag()
    out = at_reference_voltage(ev, vbat, V_REF)
    assert len(out) == 4
    for q, e in zip(np.split(vbat, 4), out):
        m = q.mean()
        eq = 4.19975 * 4.2 / m
        assert e.values[KEY] == pytest.approx(eq, rel=1e-12)
        se = q.std(ddof=1) / np.sqrt(200)
        assert e.post_sd[KEY] == pytest.approx(eq * np.hypot(4.4e-4 / 4.19975, se / m),
                                               rel=1e-12)
    # the last quarter's mean 4.0163 V: V_eq 4.392 V, 1200 of the references' SDs away
    assert out[-1].values[KEY] == pytest.approx(4.3920, abs=1e-4)
    # nothing else of the reading changes
    assert out[0].log_z == ev.log_z and out[0].explanation is ev.explanation


def test_a_sagging_flight_is_a_difference_a_steady_one_is_not():
    """The same V_full reading (4.19975 V, within the references' band): on a flight whose
    log stays at 4.2 V it is no difference that matters (as before); on a flight whose
    battery falls 5 % it is one (the rule before this said "no difference" here)."""
    ev = _sag()
    rng = np.random.default_rng(3)
    steady = V_REF + 0.01 * rng.standard_normal(800)           # the pipeline's 10 mV noise
    sagging = np.linspace(4.2, 3.99, 800) + 0.01 * rng.standard_normal(800)
    assert negligible(ev, CHECK)                 # the rule on V_full alone
    assert negligible_at(ev, CHECK, steady, V_REF)
    assert not negligible_at(ev, CHECK, sagging, V_REF)


def test_without_a_voltage_log_or_a_full_voltage_the_rule_is_unchanged():
    ev = _sag(full=4.2030)                       # 3 mV off: beyond 2 SDs + the interval
    assert not negligible(ev, CHECK)
    assert at_reference_voltage(ev, None, V_REF) == [ev]
    assert at_reference_voltage(ev, np.full(100, 4.2), None) == [ev]
    assert negligible_at(ev, CHECK, None, V_REF) == negligible(ev, CHECK)
    other = Evidence(Explanation("thrust_factor", "", (("thrust_factor", {}, ("change",)),),
                                 (0.0,), (0.1,)),
                     {"thrust_factor.change": 0.01}, {"thrust_factor.change": 0.001},
                     {"thrust_factor.change": 0.1}, {"thrust_factor.change": True}, 0.0,
                     np.ones(10))
    assert at_reference_voltage(other, np.linspace(4.2, 3.9, 100), V_REF) == [other]


def test_references_readings_are_taken_at_the_references_voltage_too():
    """Like with like: a reference flown at 4.0 V (the set's mean 4.2 V) reading V_full
    4.19975 V enters the spread as 4.19975 x 4.2 / 4.0 V (its whole flight, one piece); its
    other readings are left as they are."""
    other = Evidence(Explanation("thrust_factor", "", (("thrust_factor", {}, ("change",)),),
                                 (0.0,), (0.1,)),
                     {"thrust_factor.change": 0.01}, {"thrust_factor.change": 0.001},
                     {"thrust_factor.change": 0.1}, {"thrust_factor.change": True}, 0.0,
                     np.ones(10))
    vbat = np.r_[np.full(50, 3.9), np.full(50, 4.1)]         # mean 4.0 V, se 0.01 V
    sag, same = rows_at_reference_voltage([_sag(), other], vbat, V_REF)
    assert sag.values[KEY] == pytest.approx(4.19975 * 4.2 / 4.0, rel=1e-12)
    se = np.std(vbat, ddof=1) / 10.0
    assert sag.post_sd[KEY] == pytest.approx(
        4.19975 * 4.2 / 4.0 * np.hypot(4.4e-4 / 4.19975, se / 4.0), rel=1e-12)
    assert same is other


def test_a_refit_of_the_references_own_law_is_sized_by_its_full_voltage():
    """Where the references' voltage varied (the law is in their model: the reading
    ``replaces`` it, the real Crazyflie's 20 nominal flights at 3.61-3.86 V), the model
    follows this flight's voltage already: its V_full alone is the size, whatever it sags."""
    ev = _sag()
    shared = Evidence(Explanation("battery_sag", "", ev.explanation.parts, (V_REF,), (0.42,),
                                  replaces=("battery_sag",)),
                      ev.values, ev.post_sd, ev.prior_sd, ev.determined, 0.0, np.ones(10))
    sagging = np.linspace(4.2, 3.99, 800)
    assert at_reference_voltage(shared, sagging, V_REF) == [shared]
    assert rows_at_reference_voltage([shared], sagging, V_REF) == [shared]
    assert negligible_at(shared, CHECK, sagging, V_REF)
