"""Held-out mode by evidence (quadsim.gap.diagnose, .judge): the noise model leaves
the gap out, the lack-of-fit tests flag a systematic remainder and a reading that does not
carry over, and the verdict carries a posterior per reading."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.effects import make_effect
from quadsim.gap import diagnose
from quadsim.gap.diagnose import NOISE_WINDOW_S, noise_model, slow_part
from quadsim.gap.judge import carry_over, remainder
from quadsim.vehicle.params import load_params

DT = 0.01          # s, the fit rate (100 Hz)


def _white(rng, n, sigma):
    return rng.normal(0.0, sigma, size=(n, len(sigma)))


def test_noise_model_leaves_a_slow_gap_out():
    """White noise of 1 and 2 plus a 0.2 Hz wave 10x larger: sigma is the noise's (within
    5 %), not the RMS (7x larger); the correlation time of white noise is ~1 sample."""
    rng = np.random.default_rng(0)
    t = np.arange(4000) * DT
    sigma_true = np.array([1.0, 2.0])
    flights = [_white(rng, len(t), sigma_true) + 10.0 * np.sin(2 * np.pi * 0.2 * t)[:, None]
               for _ in range(3)]
    sigma, tau = noise_model(flights, DT, floor=np.zeros(2))
    np.testing.assert_allclose(sigma, sigma_true, rtol=0.05)
    assert np.all(np.sqrt(np.mean(np.concatenate(flights) ** 2, axis=0)) > 3 * sigma)
    np.testing.assert_allclose(tau, 1.0, atol=0.3)


def _weighed(train, held):
    return SimpleNamespace(train_residuals=train, held_residuals=held)


def _reference(sigma, tau):
    """A noise model on the Crazyflie (noise floors 0.36 mN, 0.033 mN m: far below sigma)."""
    return SimpleNamespace(sigma=np.asarray(sigma, float), tau=np.asarray(tau, float),
                           params=load_params("crazyflie21"), rotor=False)


def test_remainder_flags_a_systematic_residual_not_the_noise():
    """Noise alone: no channel flagged (its 0.5 s mean has variance sigma^2 tau / W);
    a slow offset of 0.5 sigma on Mx (20x the noise's slow RMS of sigma / sqrt(51)) is
    flagged with its RMS in the channel's unit."""
    rng = np.random.default_rng(1)
    sigma = np.full(6, 1e-3)
    ref = _reference(sigma, np.ones(6))
    noise = [_white(rng, 800, sigma) for _ in range(4)]
    assert remainder(noise, ref, DT) == {}
    shifted = [r + np.array([0, 0, 0, 0.5e-3, 0, 0]) for r in noise]
    flagged = remainder(shifted, ref, DT)
    assert set(flagged) == {"Mx"}
    assert flagged["Mx"][0] == pytest.approx(0.5e-3, rel=0.1)        # N m, the slow RMS


def test_carry_over_flags_a_held_out_flight_beyond_the_training_residual():
    rng = np.random.default_rng(2)
    sigma = np.full(6, 1.0)
    ref = _reference(sigma, np.ones(6))
    train = [_white(rng, 500, sigma) for _ in range(4)]
    same = [_white(rng, 500, sigma)]
    assert carry_over(_weighed(train, same), ref) == {}
    worse = [same[0] * np.array([1, 1, 1.6, 1, 1, 1])]     # Fz 1.6x its training RMS
    flagged = carry_over(_weighed(train, worse), ref)
    assert set(flagged) == {"Fz"} and flagged["Fz"][0] == pytest.approx(1.6, rel=0.1)


def test_carry_over_exempts_the_form_error_and_the_noise_floor():
    """The one rule of both modes (judge.lack_of_fit, against the training flights): Fz at 1.6x its
    training RMS is no lack of fit when "no difference" leaves 30x more excess there (the reading
    explains 98 % of the held-out gap, FORM_ERROR 5 %), nor when it is below the channel's noise
    floor (sigma 1e-5 N against the Crazyflie's 0.36 mN)."""
    rng = np.random.default_rng(2)
    sigma = np.full(6, 1.0)
    ref = _reference(sigma, np.ones(6))
    train = [_white(rng, 500, sigma) for _ in range(4)]
    worse = [_white(rng, 500, sigma) * np.array([1, 1, 1.6, 1, 1, 1])]
    null = _weighed(train, [worse[0] * np.array([1, 1, 6.0, 1, 1, 1])])
    assert set(carry_over(_weighed(train, worse), ref)) == {"Fz"}
    assert carry_over(_weighed(train, worse), ref, null) == {}
    tiny = _reference(np.full(6, 1e-5), np.ones(6))
    small = _weighed([1e-5 * r for r in train], [1e-5 * worse[0]])
    assert carry_over(small, tiny) == {}


def test_slow_part_is_the_moving_average():
    x = np.arange(200, dtype=float)[:, None]
    # a moving average of a straight line is the line (away from the ends)
    np.testing.assert_allclose(slow_part(x, DT)[60:140, 0], x[60:140, 0])
    assert round(NOISE_WINDOW_S / DT) | 1 == 51


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def test_verdict_carries_a_posterior_ranked_by_its_own_key(cf):
    """A weak rotor (-8 % on rotor 2): named with its probability; the ranking is sorted by
    probability; no parameter the data do not determine is given a value; every channel
    within the noise after it."""
    logs = [synthetic_flight(cf, [make_effect("thrust_mismatch", rotor_2=-0.08)], seed=s,
                             duration=4.0) for s in (40, 41, 42)]
    result = diagnose(logs[:2], cf, holdout=logs[2:], kstep=False, max_combination=1,
                      effects=["thrust_mismatch", "com_offset", "mass_offset", "ground_effect"])
    v = result["verdict"]
    assert v["outcome"] == "effect" and v["effect"] == "thrust_mismatch"
    assert v["probability"] > 0.9 and v["tentative"] is False
    assert abs(v["params"]["thrust_mismatch.rotor_2"] + 0.08) <= v["ci"]["thrust_mismatch.rotor_2"]
    probs = [e["probability"] for e in result["effects"]]
    assert probs == sorted(probs, reverse=True)
    assert abs(sum(r["probability"] for r in v["posterior"]) - 1.0) < 1e-9
    for e in result["effects"]:
        assert not set(e["params"]) & set(e["undetermined"])
    assert all(c["at_floor"] for c in v["channels"].values())
    assert v["answer"].startswith("Behaves as if") and "rotor_2 -8" in v["answer"]
    # the plots' series: one per held-out flight, its residual with the answer below before
    assert [s.flight for s in result.held_series] == list(result["holdout"])
    assert result.series is result.held_series[0]
    s = result.held_series[0]
    assert s.before.shape == s.after.shape == (len(s.t), len(s.channels))
    assert np.mean(s.after ** 2) < np.mean(s.before ** 2)
    assert "every channel" in v["answer"]


def test_a_propeller_change_is_named_not_a_refit_of_b_and_d(cf):
    """-5 % thrust and drag torque per Omega^2 on DC motors (alpha 0.2: they spin faster per
    command) on every flight: the training flights' command -> speed map carries the faster
    spin, so the propeller reading holds the speed per command (alpha 0) and is named with
    its size; before, it counted the spin twice and "b and d refitted" (the same statement
    in two parameters) took it on all four self-generated propeller cases."""
    effect = make_effect("thrust_factor", change=-0.05, alpha=0.2)
    logs = [synthetic_flight(cf, [effect], seed=s, duration=4.0, speed=1.1) for s in (50, 51, 52)]
    result = diagnose(logs[:2], cf, holdout=logs[2:], kstep=False, max_combination=1,
                      effects=["thrust_factor", "mass_offset", "thrust_curve"])
    v = result["verdict"]
    assert v["outcome"] == "effect" and v["effect"] == "thrust_factor", v["answer"]
    assert v["params"]["thrust_factor.change"] == pytest.approx(-0.05, abs=0.003)
    assert "per command" not in v["answer"]


def test_the_held_out_reference_reads_no_rotor_delay(cf):
    """The held-out mode's reference is the parameter set (heldout.nominal_reference): it
    fits no rotor timing (``Reference.timing`` False, no cross-correlation estimate), so its
    explanations carry no delay (the per-flight mode reads one wherever the references'
    timing is fitted); a delay there had crashed the held-out pair fits (shapes 4 vs 5)."""
    from quadsim.gap.diagnose import nominal_reference, prepare
    from quadsim.gap.explanations import explanations_for

    flight = prepare([synthetic_flight(cf, [], duration=3.0, seed=5)], cf)[0]
    reference = nominal_reference([flight.fit], cf, rotor=True)
    assert reference.timing is False
    out = explanations_for(reference, flight.fit)
    assert out and all(e.shift is None for e in out)
    assert "signal_delay" not in {e.name for e in out}
