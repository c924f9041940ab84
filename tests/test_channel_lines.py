"""Beyond the references' excitation of a channel, the lack of fit expected there follows the
references' own line of that channel's residual against its excitation, with the line's
prediction spread (quadsim.gap.reference.fit_channel_lines, ChannelLines, local_reference;
issue 47: Crazyflow's no-effect cases 04/05 drive Fy 1.22x beyond every reference)."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from test_envelope import COORDS, _reference, _states  # noqa: E402

from quadsim.gap.reference import (
    Envelope,
    excitation,
    fit_channel_lines,
    growth_law,
    local_reference,
    position,
)

#: four references' log excitations of 10 channels (6 wrench + 4 rotors), spread 0.3
EXCITE = np.log(np.outer([1.0, 1.1, 1.2, 1.35], np.linspace(0.5, 5.0, 10)))


def test_excitation_is_the_log_rms_about_the_mean_per_channel():
    n = 400
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    states = SimpleNamespace(
        specific_force=np.c_[0.2 * sign, 0.3 * sign, 9.81 + 0.4 * sign],
        body_accel=np.c_[5 * sign, 6 * sign, 7 * sign],
        rotor_speed=1500 + np.outer(sign, [10.0, 20.0, 30.0, 40.0]))
    np.testing.assert_allclose(excitation(states),
                               np.log([0.2, 0.3, 0.4, 5, 6, 7, 10, 20, 30, 40]), atol=1e-12)
    no_rotor = SimpleNamespace(**{**vars(states), "rotor_speed": None})
    assert len(excitation(no_rotor)) == 6


def test_an_exact_line_is_recovered_and_predicts_beyond_the_references():
    """Log mean squares exactly 2 x the excitation (a residual proportional to the
    channel's signal): slope 2 on every channel, no residual spread; a flight 0.2 beyond the
    largest reference on Fy only moves Fy's expected lack of fit by 2 (x - mean)."""
    log_ms = 2.0 * (EXCITE - EXCITE.mean(axis=0))
    lines = fit_channel_lines(EXCITE, log_ms)
    np.testing.assert_allclose(lines.slope, 2.0, rtol=1e-12)
    assert lines.sd < 1e-12 and lines.dof == 10 * 2 and lines.n == 4
    x = EXCITE[2].copy()
    x[1] = EXCITE[:, 1].max() + 0.2
    out, move, _ = lines.beyond(x)
    assert out.tolist() == [False, True] + [False] * 8
    assert move[1] == pytest.approx(2.0 * (x[1] - EXCITE[:, 1].mean()), rel=1e-12)
    assert fit_channel_lines(EXCITE[:2], log_ms[:2]) is None        # below 3 references
    assert fit_channel_lines(None, log_ms) is None


def test_the_prediction_spread_is_the_regressions():
    """Noisy lines: spread sd sqrt(1 + L^2 / (S_xx (1 + 1/n))), so that the lack-of-fit
    test's sqrt(1 + 1/n) makes it the regression's prediction spread
    sd sqrt(1 + 1/n + L^2 / S_xx), L the law's lever d(move)/d(slope) (|d| for a straight
    line, d = x - mean); sd pooled over the channels with C (n - 2) dof."""
    rng = np.random.default_rng(3)
    log_ms = 1.5 * EXCITE + 0.1 * rng.standard_normal(EXCITE.shape)
    lines = fit_channel_lines(EXCITE, log_ms)
    dx = EXCITE - EXCITE.mean(axis=0)
    rest = log_ms - log_ms.mean(axis=0) - dx * lines.slope
    assert lines.sd == pytest.approx(np.sqrt(np.sum(rest ** 2) / 20), rel=1e-12)
    x = EXCITE.max(axis=0) + 0.3
    _, move, spread = lines.beyond(x)
    d = x - EXCITE.mean(axis=0)
    # the lever: the law's log (1 + (slope / 2) (e^(2 d) - 1)) differentiated in the slope
    # (central differences, on the channels whose slope lies within (0, 2), where the share
    # f = slope / 2 is not clipped), never below |d|
    inner = (lines.slope > 0) & (lines.slope < 2)
    assert inner.sum() >= 8
    h = 1e-6
    law = lambda s: np.log1p(s / 2 * np.expm1(2 * d))       # noqa: E731
    lever = np.maximum(np.abs(law(lines.slope + h) - law(lines.slope - h)) / (2 * h), np.abs(d))
    want = lines.sd * np.sqrt(1 + 1 / 4 + lever ** 2 / np.sum(dx ** 2, axis=0))
    np.testing.assert_allclose((spread * np.sqrt(1 + 1 / 4))[inner], want[inner], rtol=1e-6)
    assert np.all(move >= lines.slope * d - 1e-12)


def test_the_growth_law_is_noise_plus_an_error_in_proportion():
    """ms = t ((1 - f) + f e^(2 d)), f = slope / 2: at slope 0 (noise only) and 2 (all of it
    in proportion) the straight line itself; in between the log of that sum, above the line
    (convex, tangent at d = 0); a falling line (slope < 0) keeps its own move where it is the
    larger and the law's 0 beyond."""
    d = np.array([-1.0, -0.2, 0.0, 0.4, 1.8])
    for slope in (0.0, 2.0):
        move, lever = growth_law(np.full(5, slope), d)
        np.testing.assert_allclose(move, slope * d, atol=1e-12)
    move, lever = growth_law(np.full(5, 0.1), d)
    np.testing.assert_allclose(move, np.log(0.95 + 0.05 * np.exp(2 * d)), rtol=1e-12)
    assert np.all(move >= 0.1 * d - 1e-15)
    # mixed flight 100's Fz cut to IMU and commands: a slope of 0.1174, 1.811 beyond the mean
    assert growth_law(np.array([0.1174]), np.array([1.811]))[0][0] == pytest.approx(
        1.143, abs=1e-3)
    move, _ = growth_law(np.full(5, -0.3), d)
    np.testing.assert_allclose(move, np.maximum(-0.3 * d, 0.0), atol=1e-12)


def test_a_proportional_error_hidden_under_the_noise_is_expected_beyond_the_references():
    """References whose residual is noise plus a model error in proportion to the signal,
    the error 5 % of the noise's mean square at their mean excitation: their straight line
    is nearly flat, yet a flight flown e-fold harder than the largest of them meets the
    error grown by e^2 there. The law's move tracks the true log mean square within the
    line's standard error times its lever; the straight line falls short by more than that."""
    x = np.linspace(-0.6, 0.6, 20)[:, None].repeat(6, axis=1)
    true = lambda z: np.log(1.0 + 0.05 * np.exp(2 * z))      # noqa: E731
    lines = fit_channel_lines(x, true(x) - true(x).mean(axis=0))
    flight = np.full(6, x.max() + 1.0)
    _, move, spread = lines.beyond(flight)
    want = true(flight) - true(x).mean(axis=0)
    se = 1.0 / np.sqrt(lines.s_xx)           # per unit of the pooled spread
    _, lever = growth_law(lines.slope, flight - lines.mean)
    assert np.all(np.abs(move - want) < 0.15 * want)
    assert np.all(want - lines.slope * (flight - lines.mean) > 0.5)
    assert np.all(lever * se > flight - lines.mean)


def test_the_reference_model_carries_the_line_only_where_the_flight_is_beyond():
    """A reference whose trend along its place is flat (lof slope 0): inside every channel's
    excitation nothing moves; with Fy driven beyond, Fy's lack-of-fit mean grows by the
    line's move, its noise scale stays (the flight's own effect may drive the channel), its
    spread is at least the line's prediction spread, and the other channels keep the
    references' statistics."""
    ref, _, _ = _reference(COORDS, slope=0.0, lof_slope=0.0)
    log_ms = 2.0 * (EXCITE - EXCITE.mean(axis=0)) \
        + 0.05 * np.random.default_rng(1).standard_normal(EXCITE.shape)
    lines = fit_channel_lines(EXCITE, log_ms)
    ref.envelope = Envelope(ref.envelope.coords, ref.envelope.trend, lines)
    pos = position(_states(*COORDS[1:3].mean(0)), Envelope(ref.envelope.coords,
                                                          ref.envelope.trend))
    inside = local_reference(ref, dataclasses.replace(pos, excite=EXCITE[1:3].mean(axis=0)))
    np.testing.assert_array_equal(inside.sigma, ref.sigma)
    np.testing.assert_array_equal(inside.lof_sd, np.broadcast_to(ref.lof_sd, (10,)))
    x = EXCITE[1:3].mean(axis=0)
    x[1] = EXCITE[:, 1].max() + 0.2
    local = local_reference(ref, dataclasses.replace(pos, excite=x))
    _, move, spread = lines.beyond(x)
    assert move[1] > 0.1
    np.testing.assert_array_equal(local.sigma, ref.sigma)
    assert local.lof_mean[1] == pytest.approx(ref.lof_mean[1] + move[1], abs=1e-12)
    lof_sd = np.broadcast_to(ref.lof_sd, (10,))
    assert local.lof_sd[1] == pytest.approx(max(lof_sd[1], spread[1]), rel=1e-12)
    keep = np.arange(10) != 1
    np.testing.assert_array_equal(local.sigma[keep], ref.sigma[keep])
    np.testing.assert_array_equal(local.lof_sd[keep], lof_sd[keep])


def test_a_residual_between_the_straight_line_and_the_law_is_grown_not_a_lack_of_fit():
    """References whose Fy residual grows with a slope of 0.3 per log excitation (a share
    0.15 of their mean square in proportion to the signal): a flight driving Fy 2 beyond
    their mean keeps the straight line's expectation beside the law's (``lof_line``), and a
    residual between the two is no lack of fit (the law's) but is grown (the straight
    line's, judge.grown_lack), with the sentence that says so; inside the references'
    excitation nothing is kept and nothing is grown."""
    from quadsim.gap.judge import Baseline, grown_lack, lack_of_fit
    from quadsim.gap.words import grown_words

    ref, _, _ = _reference(COORDS, slope=0.0, lof_slope=0.0)
    rng = np.random.default_rng(7)
    log_ms = 0.3 * (EXCITE - EXCITE.mean(axis=0)) + 0.02 * rng.standard_normal(EXCITE.shape)
    lines = fit_channel_lines(EXCITE, log_ms)
    ref.envelope = Envelope(ref.envelope.coords, ref.envelope.trend, lines)
    pos = position(_states(*COORDS[1:3].mean(0)), Envelope(ref.envelope.coords,
                                                          ref.envelope.trend))
    inside = local_reference(ref, dataclasses.replace(pos, excite=EXCITE[1:3].mean(axis=0)))
    assert inside.lof_line is None
    x = EXCITE[1:3].mean(axis=0)
    x[1] = EXCITE[:, 1].mean() + 2.0
    local = local_reference(ref, dataclasses.replace(pos, excite=x))
    _, line_move, line_spread = lines.beyond(x, straight=True)
    _, law_move, _ = lines.beyond(x)
    assert local.lof_line is not None
    assert local.lof_line[0][1] == pytest.approx(ref.lof_mean[1] + line_move[1], abs=1e-12)
    assert local.lof_mean[1] == pytest.approx(ref.lof_mean[1] + law_move[1], abs=1e-12)
    assert law_move[1] - line_move[1] > 1.4          # log(1 + 0.15 (e^4 - 1)) = 2.2 vs 0.6
    keep = np.arange(10) != 1
    np.testing.assert_array_equal(local.lof_line[0][keep], local.lof_mean[keep])
    # a flight whose Fy mean square lies at the law's expectation: within it, beyond the line
    ms = np.exp(local.lof_mean.copy())
    assert lack_of_fit(ms, Baseline.of_reference(local), local) == {}
    grown = grown_lack(ms, local)
    assert list(grown) == ["Fy"]
    assert grown["Fy"][0] == pytest.approx(np.exp(0.5 * (law_move[1] - line_move[1])),
                                           rel=1e-9)
    assert grown_lack(ms, inside) == {}
    text = grown_words(grown)
    assert text.startswith(" Not sure: this flight drives Fy harder than every reference")
    assert f"Fy {grown['Fy'][0]:.2g}x" in text and grown_words({}) == ""
