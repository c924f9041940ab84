"""Practical significance counts each estimation noise once (issue 47): the references'
physical between-flight spread is their readings' scatter less their own posterior noise
(quadsim.gap.calibrate.Spread.of, negligible, against_text)."""

from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap.calibrate import (
    PRACTICAL_Z,
    SelfCheck,
    Spread,
    against_text,
    negligible,
    readings,
    spreads,
)


def _evidence(name, values, post, determined=True):
    return SimpleNamespace(name=name, explanation=SimpleNamespace(variant="", parts=()),
                           values=dict(values), post_sd=dict(post),
                           determined={k: determined for k in values}, log_z=0.0)


def test_the_physical_spread_is_the_scatter_less_the_readings_own_noise():
    values = np.array([0.010, 0.014, 0.006, 0.012, 0.008])     # var (ddof 1) 1.0e-5
    post = np.array([0.001, 0.002, 0.002, 0.001, 0.002])        # mean square 2.8e-6
    s = Spread.of(values, post)
    assert s.mean == pytest.approx(0.010)
    # tau^2 = 1e-5 - 2.8e-6 = 7.2e-6, above the floor sqrt(2 / 4) x 1e-5 = 7.07e-6
    assert s.sd == pytest.approx(np.sqrt(7.2e-6))
    assert s.noise == pytest.approx(np.sqrt(2.8e-6))
    assert s.mean_se == pytest.approx(np.sqrt(1.0e-5 / 5))
    assert s.count == 5


def test_a_spread_below_the_noise_is_floored_at_what_the_references_resolve():
    """Readings whose scatter (1.3e-4) is below their posterior SDs (3.6e-4, a PyFlyt
    finding): the method of moments gives 0; the spread is floored at one standard error of
    the sample variance, sqrt(2 / (n - 1)) var: 9 readings -> 0.5 var, not the whole scatter
    (the rule before) and not 0."""
    rng = np.random.default_rng(1)
    v = rng.normal(0.0, 1.0, 9)
    v = (v - v.mean()) / v.std(ddof=1) * 1.3e-4
    s = Spread.of(v, np.full(9, 3.6e-4))
    assert s.sd == pytest.approx(np.sqrt(0.5) * 1.3e-4)
    assert s.noise == pytest.approx(3.6e-4)
    # 3 readings or fewer: the floor is the whole scatter (capped); 101: 0.376 of it
    assert Spread.of([0.0, 1e-4, 2e-4], [1e-3] * 3).sd == pytest.approx(1e-4)
    many = Spread.of(np.linspace(-1.0, 1.0, 101), [10.0] * 101)
    assert many.sd == pytest.approx((2 / 100) ** 0.25 * np.linspace(-1.0, 1.0, 101).std(ddof=1))


def test_spreads_read_the_references_values_and_posterior_sds():
    rows = [[_evidence("thrust_factor", {"thrust_factor.change": v},
                       {"thrust_factor.change": sd})] for v, sd in ((0.01, 0.003), (0.03, 0.004),
                                                                   (0.02, 0.005))]
    per = [readings(r) for r in rows]
    assert per[0] == {("thrust_factor", ""): {"thrust_factor.change": (0.01, 0.003)}}
    s = spreads(per)[("thrust_factor", "")]["thrust_factor.change"]
    assert s.noise == pytest.approx(np.sqrt((9e-6 + 16e-6 + 25e-6) / 3))
    assert s.sd == pytest.approx(0.01)          # 3 readings: the floor, their whole scatter


def test_noise_is_counted_once_in_the_rule():
    """The references' readings: scatter 0.010 of which noise 0.006, so tau = 0.008. The
    judged reading (sd_post 0.002) is a difference beyond |v - mean| = 1.96 sqrt(0.002^2 +
    se_mean^2) + 2 x 0.008, not 2 x 0.010 (the old rule's scatter with the noise in it)."""
    s = Spread(0.0, 0.008, 20, 0.006, 0.010 / np.sqrt(20))
    check = SelfCheck(("a", "b"), (), (), {("thrust_factor", ""): {"thrust_factor.change": s}})
    edge = PRACTICAL_Z * 0.008 + 1.96 * np.hypot(0.002, 0.010 / np.sqrt(20))
    assert edge == pytest.approx(0.02188, abs=1e-6)       # 0.016 + 1.96 x 0.003

    def ev(v):
        return _evidence("thrust_factor", {"thrust_factor.change": v},
                         {"thrust_factor.change": 0.002})

    assert negligible(ev(edge - 1e-6), check) and not negligible(ev(edge + 1e-6), check)
    # a reading 0.023 from the mean: inside the old band (2 x 0.010 + 1.96 x 0.002 = 0.0239),
    # a difference now
    assert not negligible(ev(0.023), check)


def test_references_without_physical_spread_leave_the_statistical_rule_and_say_so():
    """sd 0 (readings that do not vary): the reading is a difference as soon as its
    interval about the references' mean (its own and the mean's error) excludes it; the
    words state that interval, never "inf SDs"."""
    s = Spread(9.2e-5, 0.0, 8, 3.6e-4, 1e-4)
    check = SelfCheck(("a", "b"), (), (), {("thrust_factor", ""): {"thrust_factor.change": s}})
    half = 1.96 * np.hypot(3e-4, 1e-4)

    def ev(v):
        return _evidence("thrust_factor", {"thrust_factor.change": v},
                         {"thrust_factor.change": 3e-4})

    assert negligible(ev(s.mean + half - 1e-7), check)
    assert not negligible(ev(s.mean + half + 1e-7), check)
    words = against_text(ev(s.mean + 0.002), check, lambda key: "1")
    assert "inf" not in words and "SDs" not in words
    assert words == ("change +0.00209 against the references' +9.2e-05, which vary no more "
                     "than their estimation noise (± 0.00036): 95 % interval of the "
                     "difference +0.002 ± 0.00062")
    # with a physical spread the size is in its SDs
    wide = SelfCheck(("a", "b"), (), (), {("thrust_factor", ""): {
        "thrust_factor.change": Spread(0.0, 0.004, 20, 0.001, 0.001)}})
    assert against_text(ev(0.02), wide) == \
        "change +0.02 against the references' +0 ± 0.004 (5 SDs)"


def _delay(value, post, name="signal_delay", variant="rotor"):
    ev = _evidence(name, {"delay.rotor": value}, {"delay.rotor": post})
    ev.explanation = SimpleNamespace(variant=variant, parts=())
    return ev


def test_a_rotor_timing_reading_is_compared_with_the_references_own():
    """The rotor speeds' timing is every explanation's nuisance but ``signal_delay``'s
    reading (calibrate._own): the references' own timing readings give its spread, and a
    flight's delay within it is no difference that matters (the campaigns' calm flights
    read 29-44 ms where their references read 0-60 ms each against the others: CHANGELOG,
    "The references' inertia at its bound"); the nuisance stays out of every other reading."""
    refs = [[_delay(v, 0.001), _evidence("mass_offset", {"mass_offset.mass": 0.001,
                                                         "delay.rotor": v},
                                         {"mass_offset.mass": 1e-4, "delay.rotor": 0.001})]
            for v in (0.0, 0.03, -0.01, 0.045, 0.01, 0.02)]
    per = [readings(r) for r in refs]
    assert per[1][("signal_delay", "rotor")] == {"delay.rotor": (0.03, 0.001)}
    assert "delay.rotor" not in per[1][("mass_offset", "")]
    check = SelfCheck(("a",) * 6, (), (), spreads(per))
    s = check.spreads[("signal_delay", "rotor")]["delay.rotor"]
    assert s.mean == pytest.approx(np.mean([0.0, 0.03, -0.01, 0.045, 0.01, 0.02]))
    assert negligible(_delay(0.03, 0.001), check)          # within the references' own
    assert not negligible(_delay(0.20, 0.001), check)      # a 200 ms late log is a difference
    words = against_text(_delay(0.0594, 0.001), check)
    size = abs(0.0594 - s.mean) / s.sd
    assert words == (f"timing +59.4 ms against the references' {1e3 * s.mean:+.2g} ± "
                     f"{1e3 * s.sd:.2g} ms ({size:.3g} SDs)"), words
    assert words.startswith("timing +59.4 ms against the references' +16 ± "), words
