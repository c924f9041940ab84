"""Sizes beyond the references' reach held out against them (issue 47, one judgment for both
modes; quadsim.gap.judge module doc 1d): the bias bound sqrt(E) sums what every flight the
reading's values are fitted on (training and held out, each at its own allowance) earns
within its allowance (judge.flights_bias, heldout_bias), and every interval a held-out answer
states (the ``effects`` entries, the posterior rows, the verdict's, a payload's total) is
(1.96 + sqrt(E)) standard errors. Closed forms on the combination of flights (the bound exact
where the model error lies along the reading's own column on each flight), and the stated
entries against the fit's own spreads."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap.diagnose import entry_of
from quadsim.gap.judge import Z95, flights_bias, flights_share, heldout_bias, reach_bias

from _helpers import fake_reach, generated_flight

C = 3


def _reach(allowance, counts=None, typical=1.0):
    return fake_reach(allowance, counts, typical, channels=C)


def test_what_each_flight_earns_within_its_allowance_adds():
    """Flight a removes 0, 2, 29 (all within its allowance) on 10, 20, 40 effective samples,
    flight b 2, 4, 8 (within 1, 0, 4) on 30 each, a third within reach earns nothing:
    E = 20 * 2 + 40 * 29 + 30 * 1 + 30 * 4 = 1350, whatever the margin; one flight: the
    per-flight reach_bias exactly; E = 2 f margin where the share f is below 1."""
    a = _reach([0.0, 8.0, 48.0], [10.0, 20.0, 40.0])
    b = _reach([1.0, 0.0, 4.0], [30.0, 30.0, 30.0])
    ms_a, null_a = [2.0, 1.0, 2.0], [2.0, 3.0, 31.0]
    ms_b, null_b = [1.0, 1.0, 1.0], [3.0, 5.0, 9.0]
    flights = [(ms_a, null_a, a), (ms_b, null_b, b), (ms_b, null_b, None)]
    assert flights_bias(flights, 5000.0) == pytest.approx(np.sqrt(1350.0), rel=1e-12)
    assert flights_bias(flights, -1.0) == pytest.approx(np.sqrt(1350.0), rel=1e-12)
    margin = 2000.0
    assert flights_bias(flights, margin) ** 2 == pytest.approx(
        2 * margin * flights_share(flights, margin), rel=1e-12)
    one = SimpleNamespace(name="mass_offset", ms=np.asarray(ms_a), log_z=30.0)
    null = SimpleNamespace(name="no_difference", ms=np.asarray(null_a), log_z=0.0)
    assert reach_bias(one, null, a) == flights_bias([(ms_a, null_a, a)], 30.0)
    assert flights_bias([(ms_b, null_b, None)], 10.0) == 0.0
    # without every beyond flight's counts: what they remove within over what they remove,
    # times twice the margin (0 without a positive margin)
    nocount = _reach([1.0, 0.0, 4.0])
    assert flights_bias([(ms_a, null_a, a), (ms_b, null_b, nocount)], 40.0) == pytest.approx(
        np.sqrt((31 + 5) / (31 + 14) * 2 * 40.0), rel=1e-12)
    assert flights_bias([(ms_b, null_b, nocount)], -3.0) == 0.0


def _weighed(name, train, held, log_z):
    return SimpleNamespace(name=name, train_residuals=[np.asarray(r, float) for r in train],
                           held_residuals=[np.asarray(r, float) for r in held],
                           total=SimpleNamespace(log_z=log_z))


def test_heldout_bias_reads_every_flight_at_its_own_reach():
    """Mean squares over sigma: "no difference" leaves 4 on every channel of every flight,
    the reading 1. Training flight 1 within reach; training flight 2 (2 effective samples,
    allowance 1) earns 2 * 1 per channel, the held-out flight (1 sample, allowance 3)
    1 * 3: E = 6 + 9 = 15. "No difference" itself, or no flight beyond reach: 0."""
    sigma = np.array([1.0, 2.0, 0.5])
    ones = np.ones((4, C))
    null = _weighed("no_difference", [2 * ones * sigma] * 2, [2 * ones * sigma], 0.0)
    lead = _weighed("mass_offset", [ones * sigma] * 2, [ones * sigma], 30.0)
    reaches = (None, _reach([1.0] * C, [2.0] * C), _reach([3.0] * C, [1.0] * C))
    assert heldout_bias(lead, null, reaches=reaches, sigma=sigma) == pytest.approx(
        np.sqrt(15.0), rel=1e-12)
    assert heldout_bias(null, null, reaches=reaches, sigma=sigma) == 0.0
    assert heldout_bias(lead, None, reaches=reaches, sigma=sigma) == 0.0
    assert heldout_bias(lead, null, reaches=(None, None, None), sigma=sigma) == 0.0


def test_the_bound_on_a_combination_of_flights_sums_what_each_flight_removes():
    """One value fitted on three flights together (one channel each, N_j samples of unit
    noise scale): a model error e_j = c_j x_j on each, along the reading's own column on
    that flight. The stacked least-squares value moves by sum_j c_j x_j'x_j / sum_j x_j'x_j,
    which is sqrt(R) standard errors, R = (sum_j x_j'e_j)^2 / sum_j x_j'x_j the chi^2 it
    removes from e over all flights. Each flight's removal N_j r_j counts where positive
    (a flight the reading fits worse than no difference earns nothing), all within its
    allowance: E = sum_j N_j max(0, r_j) >= R, so the shift is within sqrt(E) standard
    errors; exact where every c_j is the same (no flight fitted worse), and then each
    flight alone bounds it by less."""
    rng = np.random.default_rng(3)
    sizes = (300, 200, 500)
    xs = [rng.normal(size=n) for n in sizes]
    t = 1.0
    for cs in ((0.04, 0.04, 0.04), (0.02, 0.07, -0.01)):
        es = [c * x for c, x in zip(cs, xs)]
        xx = sum(x @ x for x in xs)
        theta = sum(x @ e for x, e in zip(xs, es)) / xx
        shift_se = abs(theta) * np.sqrt(xx)
        flights, earned = [], 0.0
        for x, e, n in zip(xs, es, sizes):
            left = e - theta * x
            earned += max(0.0, e @ e - left @ left)
            flights.append(([t + left @ left / n], [t + e @ e / n],
                            SimpleNamespace(typical=np.array([t]), allowance=np.array([1e3]),
                                            counts=np.array([float(n)]))))
        bound = flights_bias(flights, 0.0)
        assert bound ** 2 == pytest.approx(earned, rel=1e-9)
        removed = sum(x @ e for x, e in zip(xs, es)) ** 2 / xx
        assert shift_se == pytest.approx(np.sqrt(removed), rel=1e-9)
        assert shift_se <= bound * (1 + 1e-9)
        if cs[0] == cs[1] == cs[2]:
            assert shift_se == pytest.approx(bound, rel=1e-9)
            assert all(flights_bias([f], 0.0) < shift_se for f in flights)
        else:       # the third flight (c < 0) is fitted worse: it earns nothing
            assert earned > removed * 1.01


def test_an_effects_entry_states_its_intervals_with_the_bias_the_fit_its_own_significance():
    """entry_of with bias b: each ci (1.96 + b) posterior spreads; ``significant`` (what the
    consistency check judges) the fit's own 1.96; b = 0: 1.96 spreads."""
    @dataclass(frozen=True)
    class Ev:
        name: str
        values: dict
        post_sd: dict
        determined: dict
        explanation: object
        post_cov: object = None

    keys = ("mass_offset.mass", "cable_payload.mass")
    ev = Ev("cable_payload+mass_offset", {keys[0]: 3e-3, keys[1]: 4e-3},
            {keys[0]: 1e-3, keys[1]: 3e-3}, {k: True for k in keys},
            SimpleNamespace(fixed_values={}))
    resid = np.ones((5, 6))
    w = SimpleNamespace(name=ev.name, train=ev, total=SimpleNamespace(log_z=12.0),
                        train_residuals=[resid], held_residuals=[resid])
    reference = SimpleNamespace(sigma=np.ones(6), rotor=False,
                                params=SimpleNamespace(rotor_count=4))
    plain = entry_of(w, 0.9, [2 * resid], reference)
    wide = entry_of(w, 0.9, [2 * resid], reference, bias=4.5)
    for k in keys:
        assert plain["ci"][k] == pytest.approx(Z95 * ev.post_sd[k], rel=1e-12)
        assert wide["ci"][k] == pytest.approx((Z95 + 4.5) * ev.post_sd[k], rel=1e-12)
    # 3 > 1.96 * 1 is significant, 4 < 1.96 * 3 is not, as without the bias
    assert wide["significant"] == plain["significant"] == {keys[0]: True, keys[1]: False}
    assert wide["params"] == plain["params"]


def test_a_generated_mass_held_out_beyond_references_flown_alike_is_covered_with_its_bias():
    """Generated closed-loop flights (quadsim.logs.generate, MuJoCo, sensor noise): three
    references flown alike (figure-8 at 1 m/s, 4 s); +7.4 g fixed to the frame flown with
    sharp stops at 1.5 m/s (about 10x the references' body rate), two flights training, one
    held out. The reading splits the mass into about 7.1 g fixed and 0.35 g on a cable (the
    truth: 7.4 g fixed, none on a cable): each part more than 3 of the fit's own 95 %
    half-intervals off, a bias the references' model error produces beyond them. Stated
    with the bias bound summed over the three flights (heldout_bias > 50 standard errors
    here), each part's and the total's interval hold the truth; the entry, the row and the
    verdict state the same intervals, the words the bound; the total in JSON."""
    from quadsim.effects import make_effect
    from quadsim.gap import diagnose
    from quadsim.vehicle.params import load_params

    cf = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        refs = [generated_flight(cf, [], s, "figure8", 1.0) for s in range(3)]
        mass = [make_effect("mass_offset", mass=0.0074)]
        train = [generated_flight(cf, mass, s, "steps", 1.5) for s in (40, 41)]
        held = [generated_flight(cf, mass, 42, "steps", 1.5)]
        result = diagnose(train, cf, holdout=held, reference=refs, kstep=False)
    v = result.verdict
    lead = v.posterior[0]
    assert v.name == "cable_payload+mass_offset" and lead.bias > 50.0, v.answer
    entry = result.effects[0]       # the lead's (most probable first; named by its key)
    for key, truth in (("mass_offset.mass", 7.4e-3), ("cable_payload.mass", 0.0)):
        noise_ci = v.ci[key] * Z95 / (Z95 + lead.bias)        # the fit's own 95 %
        off = abs(v.params[key] - truth)
        assert off > 3 * noise_ci and off <= v.ci[key], (key, off, noise_ci, v.ci[key])
        assert v.ci[key] == lead.ci[key] == entry["ci"][key]
    assert abs(v.total["mass"] - 7.4e-3) <= v.total["ci"]
    assert v.total["mass"] == pytest.approx(
        v.params["cable_payload.mass"] + v.params["mass_offset.mass"], rel=1e-12)
    assert v.total == lead.total and v.to_json()["total"] == pytest.approx(dict(v.total))
    assert "in all +" in v.answer and "The sizes stated include the bias" in v.answer
    # on another session's air (issue 47): the whole weighed mass times the spread, in
    # quadrature; the within-session intervals above unchanged
    assert v.across == lead.across
    assert v.across["total_ci"] == pytest.approx(np.hypot(
        v.total["ci"], v.across["thrust_spread"] * (cf.mass + v.total["mass"])), rel=1e-9)
    assert "on another session's air" in v.answer
