"""What the speed-ups of issue 43 item 7 keep must be what was computed: the kept discrepancy
centre, the kept profile of a marginal, the measured wrench kept per motion, the rotor speeds
and their derivative shifted in one transform, and the thrust-curve slope decided before the
refinement (on the real references, where present); the memo's entries kept by the flight's
length, and the rotor matrices kept by the vehicle's geometry; the linear step's R factor,
the rotor channel's key."""

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap import residual as memo_mod
from quadsim.gap.evidence import Marginal
from quadsim.gap.reference import centre_term, fit_discrepancy, read_later, rotor_spectra, shifted

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "crazyflie21_brushless"


def _states(n, seed):
    rng = np.random.default_rng(seed)
    return SimpleNamespace(t=np.arange(n) * 0.01, quat=np.tile([1.0, 0, 0, 0], (n, 1)),
                           velocity=rng.normal(0, 1.0, (n, 3)),
                           body_rate=rng.normal(0, 1.0, (n, 3)),
                           body_accel=rng.normal(0, 5.0, (n, 3)))


def test_kept_centre_term_is_the_computed_one_and_follows_the_motion():
    flights = [_states(300, k) for k in range(12)]
    rng = np.random.default_rng(5)
    disc = fit_discrepancy([rng.normal(0, 1, (300, 6)) for _ in flights], flights)
    memo: dict = {}
    first = centre_term(flights[0], disc, 6, memo)
    np.testing.assert_array_equal(first, centre_term(flights[0], disc, 6))
    assert centre_term(flights[0], disc, 6, memo) is first          # kept
    other = centre_term(flights[1], disc, 6, memo)                  # other motion: its own
    np.testing.assert_array_equal(other, centre_term(flights[1], disc, 6))
    assert not np.array_equal(other, first)


def test_marginal_profile_kept_for_the_last_vector_only():
    rng = np.random.default_rng(1)
    jac, spread = rng.normal(size=(400, 5)), np.array([0.5, 1.0, 2.0, 1.5, 0.1])
    marg, fresh = Marginal(jac, spread), Marginal(jac, spread)
    r1, r2 = rng.normal(size=400), rng.normal(size=400)
    a1 = marg.profile(r1)
    np.testing.assert_array_equal(a1[0], fresh.profile(r1)[0])
    assert marg.profile(r1) is a1
    a2 = marg.profile(r2)
    np.testing.assert_array_equal(a2[1], fresh.profile(r2)[1])
    # du minimises |r + j du|^2 + |du|^2: j^T (r + j du) + du = 0
    aug, du = a2
    np.testing.assert_allclose(marg.j.T @ aug, -du, atol=1e-9)
    cols = rng.normal(size=(400, 3))              # matrices are not kept
    np.testing.assert_array_equal(marg.profile(cols)[0], fresh.profile(cols)[0])


def test_memoised_with_a_tuple_of_references_compares_each_by_identity():
    a, b = np.zeros(3), np.ones(3)
    memo: dict = {}
    calls = []

    def compute():
        calls.append(1)
        return len(calls)

    key = ("measured", id(a), id(b))
    assert memo_mod.memoised(memo, key, (a, b), compute) == 1
    assert memo_mod.memoised(memo, key, (a, b), compute) == 1       # a new tuple, same arrays
    assert memo_mod.memoised(memo, key, (a, np.ones(3)), compute) == 2   # another array


def test_entries_kept_per_flight_follow_its_length_with_the_old_counts_as_floor():
    # 2^23 values over 16 per sample: a 888-sample fit view keeps 590 entries per kind, a
    # 30 000-sample flight the old floor
    assert memo_mod.entries_kept(888, memo_mod.KEPT) == 2 ** 23 // (16 * 888) == 590
    assert memo_mod.entries_kept(30_000, memo_mod.KEPT) == memo_mod.KEPT == 48
    assert memo_mod.entries_kept(30_000, 64) == 64
    n = 888
    states = SimpleNamespace(t=np.arange(n) * 0.01, position=np.zeros((n, 3)),
                             velocity=np.zeros((n, 3)), quat=np.tile([1.0, 0, 0, 0], (n, 1)),
                             body_rate=np.zeros((n, 3)))
    _, motion = memo_mod.flight_memo({}, states)
    for k in range(600):
        memo_mod.kept(motion, "loads", (k,), (), lambda k=k: k)
    store = motion["loads"]
    assert len(store) == 590 and next(iter(store)) == (10,)     # the 10 oldest evicted
    calls = []
    assert memo_mod.kept(motion, "loads", (10,), (), lambda: calls.append(1) or -1) == 10
    assert memo_mod.kept(motion, "loads", (9,), (), lambda: calls.append(1) or -1) == -1
    assert len(calls) == 1
    # a dict not made by flight_memo keeps KEPT
    plain: dict = {}
    for k in range(60):
        memo_mod.kept(plain, "loads", (k,), (), lambda k=k: k)
    assert len(plain["loads"]) == memo_mod.KEPT


def test_memoised_keeps_entries_by_the_flight_length():
    n = 888
    states = SimpleNamespace(t=np.arange(n) * 0.01)
    memo: dict = {}
    for k in range(591):
        memo_mod.memoised(memo, ("wrench", k), states, lambda k=k: k)
    assert len(memo) == 591                   # past the old 64, within 590 + the one added
    memo_mod.memoised(memo, ("wrench", 591), states, lambda: 591)
    assert len(memo) == 592 - 147 and ("wrench", 0) not in memo and ("wrench", 147) in memo


def test_speed_and_derivative_shifted_together_read_as_each_alone():
    rng = np.random.default_rng(3)
    n = 257
    import dataclasses

    @dataclasses.dataclass(frozen=True)
    class S:
        t: np.ndarray
        rotor_speed: np.ndarray
        rotor_accel: np.ndarray

    s = S(np.arange(n) * 0.004, rng.normal(2000, 50, (n, 4)), rng.normal(0, 800, (n, 4)))
    out = shifted(s, 0.0063, rotor_spectra(s))
    np.testing.assert_array_equal(out.rotor_speed, read_later(s.t, s.rotor_speed, 0.0063))
    np.testing.assert_array_equal(out.rotor_accel, read_later(s.t, s.rotor_accel, 0.0063))
    # a whole-sample delay reads the next samples (away from the mirrored ends)
    whole = shifted(s, 0.008, rotor_spectra(s))
    np.testing.assert_allclose(whole.rotor_speed[10:-10], s.rotor_speed[12:-8], atol=1e-8)


@pytest.mark.skipif(not (DATA / "nominal").is_dir(), reason="shared real data absent")
def test_early_slope_decision_agrees_with_the_whole_calibration_on_real_references():
    """On the 20 real nominal flights the slope is dropped: its spread read at the fit
    without it (calibrate._slope_spread) says so, and so does the whole calibration with it."""
    import warnings

    from quadsim.gap.diagnose import prepare
    from quadsim.logs.checks import check_logs
    from quadsim.logs.flightlog import load_log
    from quadsim.vehicle.params import load_params

    from _helpers import early_and_full

    params = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logs, _ = check_logs([load_log(p) for p in sorted((DATA / "nominal").glob("*.csv.gz"))],
                             params)
        flights = prepare(logs, params)
    early, full = early_and_full(flights, params)
    assert early > 1.5 and (full is None or full > 1.5)     # both well above the threshold


def test_rotor_matrices_kept_by_geometry_are_the_computed_ones():
    from quadsim.vehicle.params import load_params

    params = load_params("crazyflie21")
    motion: dict = {}
    heavier = params.replace(mass=params.mass * 1.1, inertia=np.asarray(params.inertia) * 1.2)
    shifted_com = params.replace(com=np.asarray(params.com, dtype=float) + [0.004, 0.0, 0.0])
    first = memo_mod._vehicle_matrices(params, motion)[1]
    same = memo_mod._vehicle_matrices(heavier, motion)[1]
    other = memo_mod._vehicle_matrices(shifted_com, motion)[1]
    assert same is first                                  # mass and inertia alone: shared
    for got, vehicle in ((first, params), (same, heavier), (other, shifted_com)):
        want = memo_mod.rotor_matrices(vehicle)
        for g, w in zip(got, want):
            assert np.array_equal(g, w)
    assert not np.array_equal(other[0], first[0])         # the torque arms moved with the CoM


def test_linear_step_factor_is_numpys_qr_bit_for_bit():
    from quadsim.gap.evidence import _upper_factor

    rng = np.random.default_rng(4)
    for rows, cols in ((7, 1), (300, 3), (5300, 6), (5300, 12)):
        m = rng.normal(size=(rows, cols)) * rng.uniform(1e-6, 1e6, cols)
        kept = m.copy()
        r = _upper_factor(m)
        np.testing.assert_array_equal(m, kept)                  # the input is not written to
        np.testing.assert_array_equal(r, np.linalg.qr(m, mode="r"))


def test_rotor_channel_keyed_by_the_speed_factor_a_propeller_gives():
    from quadsim.effects import make_effect
    from quadsim.vehicle.params import load_params

    params = load_params("crazyflie21")
    states = SimpleNamespace(command=np.zeros((5, 4)))
    lag = make_effect("motor_lag", time_constant=0.03)
    plain = memo_mod.rotor_key(states, params, [lag])
    # a thrust deviation without a speed-per-command exponent gives no factor: the same key
    worn = make_effect("thrust_mismatch", rotor_2=-0.05)
    assert memo_mod.rotor_key(states, params, [lag, worn]) == plain
    # with one, its factor enters the key, and the same factor gives the same key
    loaded = make_effect("thrust_mismatch", rotor_2=-0.05, alpha=0.3)
    key = memo_mod.rotor_key(states, params, [lag, loaded])
    assert key != plain
    assert key == memo_mod.rotor_key(states, params, [lag, make_effect(
        "thrust_mismatch", rotor_2=-0.05, alpha=0.3)])
    assert key != memo_mod.rotor_key(states, params, [lag, make_effect(
        "thrust_mismatch", rotor_2=-0.04, alpha=0.3)])
    # an effect with rotor dynamics still enters by its values
    assert plain != memo_mod.rotor_key(states, params, [make_effect("motor_lag",
                                                                    time_constant=0.04)])
