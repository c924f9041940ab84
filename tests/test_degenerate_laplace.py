"""A reading's Laplace spreads are never narrower than its data determine (issue 47):
the posterior covariance keeps every direction of the precision (quadsim.gap.evidence.
posterior_cov), a fit's Jacobian takes no difference across the wall of values that make no
vehicle (wall_jacobian), and on a generated flight a payload off the centre fitted at ~0 g
leaves its position undetermined -- exactly the prior where the mass is 0 (the position then
acts on nothing) -- also where the fit sits next to the inertia's triangle inequality."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import quadsim.gap.evidence as evidence
from benchmarks.synthetic import flyable_flight, synthetic_flight
from quadsim.core.errors import ModelError, QuadsimWarning
from quadsim.gap.calibrate import calibrate
from quadsim.gap.diagnose import prepare
from quadsim.vehicle.params import load_params

from _helpers import shared_effects


def test_the_posterior_covariance_keeps_every_direction():
    """H = diag(1e20) (+) [[2, 1], [1, 2]] (exact in floats): H^-1 = diag(1e-20) (+)
    [[2, -1], [-1, 2]] / 3, where a pseudo-inverse (cut-off 1e-15 of the largest singular
    value) drops the 2 x 2 block: both its parameters "determined" to 0. An eigenvalue below
    the prior's 1 (round-off) is floored there; an ordinary H (condition 1e6) is inverted to
    round-off."""
    h = np.zeros((3, 3))
    h[0, 0], h[1:, 1:] = 1e20, [[2.0, 1.0], [1.0, 2.0]]
    expect = np.zeros((3, 3))
    expect[0, 0], expect[1:, 1:] = 1e-20, np.array([[2.0, -1.0], [-1.0, 2.0]]) / 3.0
    np.testing.assert_allclose(evidence.posterior_cov(h), expect, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(np.linalg.pinv(h)[1:, 1:], 0.0)      # what it replaced
    np.testing.assert_allclose(evidence.posterior_cov(np.diag([0.5, 2.0])),
                               np.diag([1.0, 0.5]), atol=1e-15)
    q, _ = np.linalg.qr(np.random.default_rng(4).normal(size=(4, 4)))
    lam = np.array([1e6, 30.0, 2.0, 1.0])
    np.testing.assert_allclose(evidence.posterior_cov(q @ np.diag(lam) @ q.T),
                               q @ np.diag(1.0 / lam) @ q.T, rtol=1e-8, atol=1e-12)


class _Linear:
    """A problem whose stacked vector is (A z - b, z) inside a set and a constant 1e3 beyond
    it (as quadsim.gap.evidence.Problem.stacked meets a ModelError): z_0 <= c, and z_1 within
    ``slab`` of 0.3."""

    def __init__(self, c: float, slab: float = np.inf):
        rng = np.random.default_rng(7)
        self.a, self.b = rng.normal(size=(6, 3)), rng.normal(size=6)
        self.c, self.slab = c, slab
        self.z_lo, self.z_hi = np.full(3, -5.0), np.full(3, 5.0)
        self.walls = 0

    def stacked(self, z):
        if z[0] > self.c or abs(z[1] - 0.3) > self.slab:
            self.walls += 1
            return np.full(9, 1e3)
        return np.concatenate([self.a @ z - self.b, z])


def test_the_wall_jacobian_turns_back_at_the_wall():
    """Linear residual: every column the exact (A; I) column from the side the wall allows
    (forward where the forward step would cross it, backward otherwise), the wall reported;
    a parameter whose steps meet the wall both ways keeps the prior's row only; a point
    beyond the wall gives no Jacobian."""
    step = evidence.FULL_FIT_STEP
    prob = _Linear(c=0.2 + 0.5 * step)
    z = np.array([0.2, 0.3, -1.5])
    vec, jac, near = evidence.wall_jacobian(prob, z, step)
    expect = np.vstack([prob.a, np.eye(3)])
    np.testing.assert_allclose(vec, prob.stacked(z), atol=0)
    np.testing.assert_allclose(jac, expect, atol=1e-9)
    assert near
    _, jac, near = evidence.wall_jacobian(_Linear(c=1.0), z, step)
    np.testing.assert_allclose(jac, expect, atol=1e-9)
    assert not near
    thin = _Linear(c=1.0, slab=0.5 * step * 1.0)
    _, jac, near = evidence.wall_jacobian(thin, z, step)
    np.testing.assert_allclose(jac[:, [0, 2]], expect[:, [0, 2]], atol=1e-9)
    np.testing.assert_array_equal(jac[:, 1], np.eye(9)[:, 7])
    assert near
    assert evidence.wall_jacobian(_Linear(c=0.1), z, step) == (None, None, False)


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def setting(cf):
    """References of 3 generated flights and a 4th flight with no payload (crazyflie21)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        logs = [synthetic_flight(cf, shared_effects(), duration=4.0, seed=s,
                                 speed=0.8 + 0.2 * s) for s in range(3)]
        reference = calibrate(prepare(logs, cf), cf)
        flight = prepare([synthetic_flight(cf, shared_effects(), duration=4.0, seed=21)],
                         cf)[0].fit
    names = list(reference.candidate.parameter_names)
    jac = evidence.jacobian(flight, reference, list(range(len(names))),
                            reference.candidate.effects)
    return evidence.FitInputs(flight, reference, jac, reference.s_ref, {})


def _payloads(inputs):
    rows = [e for e in evidence.explanations_for(inputs.reference, inputs.states)
            if e.name == "mass_offset"]
    centred = next(e for e in rows if not e.variant)
    off = next(e for e in rows if e.variant)
    return centred, off


def _laplace(prob, z):
    vec, jac, near = evidence.wall_jacobian(prob, z, evidence.FULL_FIT_STEP)
    return evidence.laplace(prob, z, vec, jac.T @ jac, int(near)), near


def test_a_payload_at_zero_grams_leaves_its_place_undetermined(setting):
    """Closed form at mass 0: the position moves nothing (the x, y columns are 0), so x and
    y keep their prior spread exactly; at the centre the mass has its centred reading's
    spread at the same point. The full fit of the flight with no payload: mass within 2
    posterior spreads of 0 (THROUGH_SDS), so x and y are not identified: their prior spread
    exactly (before: the Laplace spread of a bilinear surface at the fitted -0.03 g, y at
    0.44 of its prior's, "determined"); every spread finite, the mass's at least 1e-3 of
    its prior's."""
    centred, off = _payloads(setting)
    p_off, p_c = setting.problem(off), setting.problem(centred)
    delay = 0.3
    for x, y in ((0.4, -0.6), (0.0, 0.0)):
        ev, near = _laplace(p_off, np.array([0.0, x, y, delay]))
        assert not near
        for k in ("mass_offset.x", "mass_offset.y"):
            assert ev.post_sd[k] == pytest.approx(ev.prior_sd[k], rel=1e-12)
            assert not ev.determined[k]
    # at the centre the payload's mass column is the centred reading's
    ev_c, _ = _laplace(p_c, np.array([0.0, delay]))
    assert ev.post_sd["mass_offset.mass"] == pytest.approx(ev_c.post_sd["mass_offset.mass"],
                                                           rel=1e-9)
    fit = evidence.full_fit(setting, off, 0.0)
    m, s_m = fit.values["mass_offset.mass"], fit.post_sd["mass_offset.mass"]
    assert abs(m) < evidence.THROUGH_SDS * s_m
    assert 1e-3 * fit.prior_sd["mass_offset.mass"] < s_m < fit.prior_sd["mass_offset.mass"]
    for k in ("mass_offset.x", "mass_offset.y"):
        assert fit.post_sd[k] == fit.prior_sd[k]
        assert not fit.determined[k]
    assert all(np.isfinite(v) for v in fit.post_sd.values())


def test_next_to_the_inertias_wall_the_spreads_are_the_datas(setting):
    """A payload at (+16, -21) mm lighter than modelled: along its mass the inertia of the
    crazyflie21 (nearly flat: I_x + I_y ~ I_z) meets the triangle inequality (at -13.9 g
    here, found by bisection; at -0.17 g on the real references' calibrated model); at half
    a finite-difference step inside it a step down in mass crosses it. The solver's
    difference across it (its relative step of a negative value goes down) gives a spread
    below 1e-6 of the prior's (the references' issue 47: 2e-12 kg, 2e-22 m); the wall's
    Jacobian gives the data's: every spread that of a point 3 steps inside (no step
    crossing) to 2 %, and the wall counted as a bound."""
    _, off = _payloads(setting)
    prob = setting.problem(off)
    step = evidence.FULL_FIT_STEP
    z = np.array([0.0, 16e-3, -21e-3, 0.3]) / np.r_[prob.sd[:3], 1.0]

    def crosses(m):
        point = z.copy()
        point[0] = m
        try:
            prob.residual(point)
        except ModelError:
            return True
        return False

    inside, beyond = 0.0, prob.z_lo[0] + 1e-9
    assert not crosses(inside) and crosses(beyond)
    for _ in range(40):                        # the wall along the mass, by bisection
        mid = 0.5 * (inside + beyond)
        inside, beyond = (inside, mid) if crosses(mid) else (mid, beyond)
    near_wall = z.copy()
    near_wall[0] = inside + 0.5 * step
    far = z.copy()
    far[0] = inside + 3 * step
    ev, near = _laplace(prob, near_wall)
    ev_far, near_far = _laplace(prob, far)
    assert near and not near_far
    h = step * max(1.0, abs(near_wall[0]))
    across = near_wall.copy()
    across[0] -= h
    assert crosses(across[0])
    for k in ev.post_sd:
        assert ev.post_sd[k] == pytest.approx(ev_far.post_sd[k], rel=0.02)
    # the solver's way: the mass column by the step down, across the wall
    vec = prob.stacked(near_wall)
    _, jac, _ = evidence.wall_jacobian(prob, near_wall, step)
    jac[:, 0] = (prob.stacked(across) - vec) / -h
    old = evidence.laplace(prob, near_wall, vec, jac.T @ jac, 0)
    assert old.post_sd["mass_offset.mass"] < 1e-6 * old.prior_sd["mass_offset.mass"]


def test_a_stacked_cable_fit_next_to_a_wall_keeps_the_datas_spreads(cf, monkeypatch):
    """The stacked fit with each later flight's own start swing (quadsim.gap.diagnose.
    fit_own_starts, a solver of its own) next to a wall of values that make no vehicle: two
    exact training flights with a 15 g payload on a 0.5 m cable against 3 plain references,
    fitted once freely, then again with a ModelError for every mass above the free fit's
    MAP + half a finite-difference step (a stand-in for the inertia's triangle
    inequality). The solver's last Jacobian steps the mass forward across that wall (a
    column ~1e3 / step): before, the mass's spread came out 4.6e-11 kg (the free fit's
    8.8e-6 kg) and log Z 12 below. Taken again with no difference across the wall
    (evidence.fitted_jacobian), every spread is the free fit's to 2 % (measured 0.994-1.002)
    and log Z the free fit's less log 2 (the wall counted as a bound) to 0.2."""
    import importlib

    import quadsim.gap.explanations as ex
    from quadsim.gap.fitting import CableSwing

    dg = importlib.import_module("quadsim.gap.diagnose")   # (the package's diagnose: a function)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        refs = [flyable_flight(cf, [], seed=s, duration=4.0, speed=1.5) for s in (40, 41, 42)]
        plain = calibrate(prepare(refs, cf), cf)
        starts = ({"lean_x": 0.25, "rate_y": 0.5}, {"lean_y": -0.25, "rate_x": -0.5}, {})
        logs = [flyable_flight(cf, [CableSwing(mass=0.015, length=0.5, swing_damping=0.5,
                                               **s)], seed=80 + k, duration=4.0, speed=1.5)
                for k, s in enumerate(starts)]
        against = dg.against_references(prepare(logs[:2], cf), prepare(logs[2:], cf), plain)
    expl = next(e for e in against.explanations
                if e.name == "cable_payload" and e.variant == "")
    assert expl.parameter_names[0] == "cable_payload.mass"
    reference = against.reference
    jac = evidence.jacobian(against.stacked, reference,
                            list(range(len(reference.candidate.parameter_names))),
                            reference.candidate.effects)
    inputs = evidence.FitInputs(against.stacked, reference, jac, ex.marginal_sd(reference), {})
    at = dg.joins(against.train)
    free = dg.fit_own_starts(inputs, expl, against.start, at=at)
    mass = free.values["cable_payload.mass"]
    z = (mass - expl.mean[0]) / expl.sd[0]
    assert z > 0        # the fit comes from below (z = 0): the wall lies ahead of it
    wall = mass + 0.5 * evidence.FULL_FIT_STEP * max(1.0, z) * expl.sd[0]
    own = ex.own_effects

    def walled(e, theta):
        if e is expl and theta[0] > wall:
            raise ModelError("beyond the stand-in wall")
        return own(e, theta)

    monkeypatch.setattr(ex, "own_effects", walled)
    got = dg.fit_own_starts(inputs, expl, against.start, at=at)
    assert got.values["cable_payload.mass"] <= wall
    for k in free.post_sd:
        assert got.post_sd[k] == pytest.approx(free.post_sd[k], rel=0.02), k
    assert got.log_z == pytest.approx(free.log_z - np.log(2.0), abs=0.2)


@pytest.mark.parametrize("compact", [False, True])
def test_a_candidate_fit_next_to_a_wall_keeps_the_datas_errors(monkeypatch, compact):
    """quadsim.gap.fitting.fit_candidate (the calibration's and the judge's solver, the
    same 1e3 wall, standard errors from the pseudo-inverse of JᵀJ) next to a wall: an
    inertia error (+10 %, -5 %, 0 on xx, yy, zz) on a generated crazyflie21 flight fitted
    once freely, then again with a ModelError for every xx above the free fit's value +
    half a finite-difference step (a stand-in for the triangle inequality). The solver's
    last Jacobian steps xx across it (a column ~1e3 / step): before, xx's standard error
    came out 1.4e-8 of the free fit's, yy's and zz's 2e-17 (the pseudo-inverse's cut-off
    drops every other direction) and no parameter identified. Taken again with no
    difference across the wall (lsq.wall_jacobian, prior=False): every standard error
    the free fit's to 1 % (measured 5e-5), each identified as freely; the same through the
    compact solver (quadsim.gap.lsq)."""
    from quadsim.effects import make_effect
    from quadsim.gap import fitting

    params = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        log = synthetic_flight(params, [make_effect("inertia_error", xx=0.1, yy=-0.05)],
                               seed=0, duration=3.0)
        states = [prepare([log], params)[0].fit]
    params = fitting.fit_motor_map(states, params)
    sigma = fitting.noise_scale(
        fitting.residuals(states[0], params, [], rotor_channel=True),
        float(states[0].t[1] - states[0].t[0]), floor=fitting.noise_floor(params, True))
    cand = next(c for c in fitting.candidates_for(params, True) if c.name == "inertia_error")
    free = fitting.fit_candidate(cand, states, params, sigma, rotor_channel=True,
                                 compact=compact)
    typical = fitting.typical_scales(cand, params)
    z = free.theta[0] / typical[0]          # the fit starts at 0 (no error)
    assert z > 0
    wall = free.theta[0] + 0.5 * fitting.FIT_STEP * max(1.0, z) * typical[0]
    effects = fitting.Candidate.effects

    def walled(self, theta):
        if self is cand and theta[0] > wall:
            raise ModelError("beyond the stand-in wall")
        return effects(self, theta)

    monkeypatch.setattr(fitting.Candidate, "effects", walled)
    got = fitting.fit_candidate(cand, states, params, sigma, rotor_channel=True,
                                compact=compact)
    assert got.theta[0] <= wall
    np.testing.assert_allclose(got.stderr, free.stderr, rtol=0.01)
    assert got.identifiable == free.identifiable == [True, True, True]


def test_a_propellers_speed_exponent_is_undetermined_where_its_change_is(setting):
    """thrust_factor's alpha acts only through its change (a command gives (1 + change)^-alpha
    of its speed: no load change, no speed change), declared so (Reading.through). Closed
    form at change = 0: alpha's column is exactly 0 (ThrustFactor.speed_factor is None), so
    alpha keeps its prior spread. At a change of +0.05 % (within THROUGH_SDS posterior
    spreads of 0 on this flight, +-0.045 %; +-0.23 % on flights whose commands were the
    speed over max_speed, where the test took +0.3 %) the Laplace spread of the bilinear
    surface was finite (alpha's 0.99994 of its prior's): now exactly the prior's,
    uncorrelated, not determined. At -5 % (110 spreads from 0; 22 on the max_speed flights)
    alpha keeps the data's Laplace spread (0.19 of its prior's; 0.984 there)."""
    from quadsim.effects import make_effect

    assert make_effect("thrust_factor", change=0.0, alpha=0.3).speed_factor(np.zeros(3)) is None
    expl = next(e for e in evidence.explanations_for(setting.reference, setting.states)
                if e.name == "thrust_factor" and "thrust_factor.alpha" in e.parameter_names)
    assert expl.through == (("thrust_factor.alpha", "thrust_factor.change"),)
    prob = setting.problem(expl)
    names = expl.parameter_names
    c, a = names.index("thrust_factor.change"), names.index("thrust_factor.alpha")
    sd = np.asarray(expl.sd, float)

    def at(change):
        z = np.zeros(len(names))
        z[c] = change / sd[c]
        if expl.shift:
            z[-1] = 0.3
        return z

    _, jac, _ = evidence.wall_jacobian(prob, at(0.0), evidence.FULL_FIT_STEP)
    np.testing.assert_array_equal(jac[:-len(names), a], 0.0)       # no data row moves
    ev, _ = _laplace(prob, at(0.0))
    assert ev.post_sd["thrust_factor.alpha"] == pytest.approx(sd[a], rel=1e-12)
    ev, _ = _laplace(prob, at(0.0005))
    assert abs(ev.values["thrust_factor.change"]) <= (
        evidence.THROUGH_SDS * ev.post_sd["thrust_factor.change"])
    assert ev.post_sd["thrust_factor.alpha"] == sd[a]
    assert not ev.determined["thrust_factor.alpha"]
    row = ev.post_cov[a]
    assert row[a] == sd[a] ** 2 and np.count_nonzero(row) == 1
    ev, _ = _laplace(prob, at(-0.05))
    assert abs(ev.values["thrust_factor.change"]) > (
        evidence.THROUGH_SDS * ev.post_sd["thrust_factor.change"])
    assert ev.post_sd["thrust_factor.alpha"] < 0.9999 * sd[a]
