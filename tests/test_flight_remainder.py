"""Per flight, a named reading that leaves a systematic remainder beyond the references' own
is tentative (quadsim.gap.judge.remainder_of: the held-out remainder rule against the
references' normal). Closed-form numbers, no fitting."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import t as student_t

from quadsim.gap.calibrate import self_check_of
from quadsim.gap.evidence import slow_ms
from quadsim.gap.judge import LOF_P, remainder_of, slow_floor, slow_part, slow_share
from quadsim.vehicle.params import load_params

CHANNELS = 6
#: the references' slow-part mean squares: 8 flights, log scatter +-0.1 about log 0.04 on
#: every channel (the Crazyflie wake case's references: Fz 0.03-0.05)
LOGS = np.log(0.04) + 0.1 * np.array([-1.5, -1, -0.5, 0, 0, 0.5, 1, 1.5])


def _reference():
    return SimpleNamespace(sigma=np.full(CHANNELS, 10.0), params=load_params("crazyflie21"),
                           rotor=False)


def _check(logs=LOGS):
    return SimpleNamespace(slow=np.repeat(np.exp(logs)[:, None], CHANNELS, axis=1))


def _ev(slow):
    return SimpleNamespace(slow=np.asarray(slow, float))


def test_a_slow_part_far_beyond_the_references_is_a_remainder():
    # the wake's thrust loss under a flapping reading: Fz slow part 0.44 against 0.04
    left = remainder_of(_ev([0.04, 0.04, 0.44, 0.04, 0.04, 0.04]), _check(), _reference())
    assert list(left) == ["Fz"]
    n, sd = len(LOGS), np.std(LOGS, ddof=1)
    assert left["Fz"][0] == pytest.approx(np.sqrt(11.0), rel=1e-12)    # RMS ratio
    assert left["Fz"][1] == pytest.approx(np.log(11.0) / (sd * np.sqrt(1 + 1 / n)), rel=1e-12)


def test_the_limit_is_the_student_t_quantile_on_the_references_spread():
    n, sd = len(LOGS), np.std(LOGS, ddof=1)
    limit = student_t.ppf(1 - LOF_P / CHANNELS, n - 1) * sd * np.sqrt(1 + 1 / n)
    inside = np.exp(np.mean(LOGS) + 0.999 * limit)
    outside = np.exp(np.mean(LOGS) + 1.001 * limit)
    assert not remainder_of(_ev([inside] * CHANNELS), _check(), _reference())
    assert set(remainder_of(_ev([outside] * CHANNELS), _check(), _reference())) == \
        {"Fx", "Fy", "Fz", "Mx", "My", "Mz"}


def test_no_normal_no_test():
    ev = _ev([0.04, 0.04, 40.0, 0.04, 0.04, 0.04])
    assert remainder_of(ev, None, _reference()) == {}                  # no self-check
    assert remainder_of(ev, _check(LOGS[:2]), _reference()) == {}      # two references
    assert remainder_of(_ev(None), _check(), _reference()) == {}       # not measured
    assert remainder_of(ev, SimpleNamespace(slow=None), _reference()) == {}


def test_below_the_noise_floor_a_slow_part_is_no_remainder():
    ref = _reference()
    ref.sigma = np.full(CHANNELS, 1e-9)          # every channel far below its floor
    assert remainder_of(_ev([0.04, 0.04, 40.0, 0.04, 0.04, 0.04]), _check(), ref) == {}


def test_the_slow_part_is_the_held_out_rules_moving_average():
    r = np.random.default_rng(3).normal(size=(700, 4))
    r[:, 2] += 0.3
    for dt in (0.01, 0.004, 0.3):
        assert slow_ms(r, dt) == pytest.approx(np.mean(slow_part(r, dt) ** 2, axis=0),
                                               rel=1e-10)
    # a constant c over N samples, window n (zero padded ends): mean square
    # c^2 (N - (n - 1) + 2 sum_{k=(n+1)/2}^{n-1} (k/n)^2) / N
    n_s, n = 1000, 51
    ends = 2 * sum((k / n) ** 2 for k in range((n + 1) // 2, n))
    got = slow_ms(np.full((n_s, 1), 2.0), 0.01)[0]
    assert got == pytest.approx(4.0 * (n_s - (n - 1) + ends) / n_s, rel=1e-12)


def test_the_self_check_keeps_each_references_no_difference_slow_part():
    def rows(value):
        null = SimpleNamespace(name="no_difference", slow=np.full(CHANNELS, value),
                               values={}, explanation=SimpleNamespace(variant=""))
        return [null]

    verdict = SimpleNamespace(name="no_significant_gap", outcome="no_significant_gap",
                              lack_of_fit={}, differ_on=())
    check = self_check_of(["a", "b", "c"], [rows(0.1), None, rows(0.3)],
                          lambda j, others: verdict)
    assert check.slow.shape == (2, CHANNELS)
    assert check.slow[:, 0].tolist() == [0.1, 0.3]


# --- the floor of a slow part (quadsim.gap.judge.slow_floor) -------------------------------
#: a noiseless simulator's references (pymulticopter, issue 47): every channel's noise scale
#: at its floor (sigma = f), correlation time 2.8 samples, the slow part's window 51 samples
#: (0.5 s at 100 Hz): a noise at the floor keeps 2.8 / 51 = 5.5 % of its mean square there
TAU, WINDOW = 2.8, 51
#: their slow parts under "no difference": log scatter +-0.1 about log 0.02 (sigma^2 units)
NOISELESS = np.log(0.02) + 0.1 * np.array([-1.5, -1, -0.5, 0, 0, 0.5, 1, 1.5])


def _at_floor():
    from quadsim.gap.fitting import noise_floor

    params = load_params("crazyflie21")
    return SimpleNamespace(sigma=noise_floor(params, False), params=params, rotor=False,
                           tau=np.full(CHANNELS, TAU))


def _timed(slow, window=WINDOW):
    return SimpleNamespace(slow=np.asarray(slow, float), slow_window=window)


def test_the_slow_share_of_a_noise():
    assert slow_share(np.array([1.0, TAU, 51.0, 200.0]), WINDOW) == pytest.approx(
        [1 / 51, TAU / 51, 1.0, 1.0], rel=1e-12)
    ref = _at_floor()
    assert slow_floor(ref, WINDOW) == pytest.approx(np.full(CHANNELS, TAU / WINDOW), rel=1e-12)
    assert slow_floor(ref, None) == pytest.approx(np.ones(CHANNELS), rel=1e-12)
    ref.sigma = 2 * ref.sigma                    # a noisier channel: the floor is further down
    assert slow_floor(ref, WINDOW) == pytest.approx(np.full(CHANNELS, TAU / WINDOW / 4),
                                                    rel=1e-12)


def test_a_remainder_under_the_full_floor_but_above_a_slow_parts_is_one():
    """A thrust bias read as a thrust gain (pymulticopter case 18): the moments' slow part
    0.82 sigma^2 (0.9 of the floor's RMS) against the references' 0.02: beyond their spread,
    above the floor of a slow part (0.055), under the full floor (1), which hid it."""
    check = SimpleNamespace(slow=np.repeat(np.exp(NOISELESS)[:, None], CHANNELS, axis=1))
    ev = _timed([0.02, 0.02, 0.02, 0.82, 0.82, 0.02])
    left = remainder_of(ev, check, _at_floor())
    assert list(left) == ["Mx", "My"]
    assert left["Mx"][0] == pytest.approx(np.sqrt(0.82 / np.exp(np.mean(NOISELESS))),
                                          rel=1e-12)      # 6.4x the references' slow RMS
    sd = np.std(NOISELESS, ddof=1)
    assert left["Mx"][1] == pytest.approx((np.log(0.82) - np.mean(NOISELESS))
                                          / (sd * np.sqrt(1 + 1 / len(NOISELESS))), rel=1e-12)
    # without the window (the full floor, as before): hidden
    assert remainder_of(_timed(ev.slow, None), check, _at_floor()) == {}


def test_a_slow_part_beyond_the_references_but_under_a_slow_parts_floor_is_none():
    """References far under the floor (slow parts 0.002 sigma^2): a slow part 10x theirs,
    0.02, lies beyond their spread but under what a noise at the floor gives a slow part
    (0.055): within the resolution the floor states, no remainder."""
    logs = NOISELESS - np.log(10.0)
    check = SimpleNamespace(slow=np.repeat(np.exp(logs)[:, None], CHANNELS, axis=1))
    n, sd = len(logs), np.std(logs, ddof=1)
    z = (np.log(0.02) - np.mean(logs)) / (sd * np.sqrt(1 + 1 / n))
    assert z > student_t.ppf(1 - LOF_P / CHANNELS, n - 1)
    assert remainder_of(_timed([0.002, 0.002, 0.002, 0.02, 0.02, 0.002]), check,
                        _at_floor()) == {}


def test_a_name_leaving_what_the_references_leave_is_unchanged():
    """A right reading on the noiseless simulator: its slow parts within the references'
    spread (the largest 1.5x their typical) are no remainder, with the slow part's floor
    as with the full one."""
    check = SimpleNamespace(slow=np.repeat(np.exp(NOISELESS)[:, None], CHANNELS, axis=1))
    slow = 0.02 * np.array([0.7, 1.0, 1.2, 1.5, 0.9, 1.1])
    assert remainder_of(_timed(slow), check, _at_floor()) == {}
    assert remainder_of(_timed(slow, None), check, _at_floor()) == {}
