"""The calibrated sense of "normal" (issue 47): the discrepancy term, the self-check and
practical significance, and the Laplace evidence against an exact marginal likelihood."""

from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.synthetic import flyable_flight
from quadsim.effects import make_effect
from quadsim.gap import diagnose_per_flight
from quadsim.gap.calibrate import PRACTICAL_Z, SelfCheck, Spread, negligible
from quadsim.gap.evidence import Marginal, laplace
from quadsim.gap.judge import FEW_WORDS, UNCHECKED_WORDS, posterior
from quadsim.gap.reference import (
    centre_term,
    channel_features,
    columns,
    features,
    fit_discrepancy,
)
from quadsim.vehicle.params import load_params


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def _states(n, seed):
    """Flight states with random motion (only the fields the features read)."""
    rng = np.random.default_rng(seed)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return SimpleNamespace(t=np.arange(n) * 0.01, quat=quat,
                           velocity=rng.normal(0, 1.0, (n, 3)),
                           body_rate=rng.normal(0, 1.0, (n, 3)),
                           body_accel=rng.normal(0, 5.0, (n, 3)))


def test_discrepancy_centre_and_spread_are_the_flights_coefficients_mean_and_scatter():
    """Residual = features @ beta_j exactly on each of 6 flights: the centre is the mean of
    the beta_j, the covariance their sample covariance x (1 + 1/n) plus the ridge."""
    rng = np.random.default_rng(0)
    states = [_states(400, s) for s in range(6)]
    betas = rng.normal(0, 1.0, (6, 4))            # Fx's four features, per flight
    resid = []
    for s, b in zip(states, betas):
        r = np.zeros((400, 6))
        names = channel_features(0)
        f = features(s)
        r[:, 0] = np.column_stack([f[n] for n in names]) @ b
        resid.append(r)
    d = fit_discrepancy(resid, states)
    assert np.allclose(d.centre[0], betas.mean(axis=0), atol=1e-9)
    cov = np.cov(betas, rowvar=False) * (1 + 1 / 6)
    cov += 0.1 * np.diag(np.diag(cov))
    assert np.allclose(d.factor[0] @ d.factor[0].T, cov, rtol=1e-9, atol=1e-12)
    assert d.explained[0] > 0 and d.explained[1] == 0.0
    # the centre term is the features times the centre; the columns scale by the factor
    c = centre_term(states[0], d, 6)
    f = np.column_stack([v for v in (features(states[0])[n] for n in channel_features(0))])
    assert np.allclose(c[:, 0], f @ d.centre[0]) and np.allclose(c[:, 1:], 0.0)
    cols = columns(states[0], d, np.ones(6) * 4.0)
    assert cols.shape == (400 * 6, d.size)
    assert np.allclose(cols.reshape(400, 6, -1)[:, 0, :4], 2.0 * f @ d.factor[0])
    # leave one out: the other five flights' mean
    assert np.allclose(d.without(2).centre[0], np.delete(betas, 2, 0).mean(axis=0))
    # a channel's F coefficients need F + 1 flights: four force features, five flights
    assert d.channels == (0, 1, 2) and d.without(2).channels == (0, 1, 2)
    assert d.without(2).factor[0].shape == (4, 4)
    assert fit_discrepancy(resid[:4], states[:4]) is None


def test_laplace_evidence_is_the_exact_marginal_likelihood_of_a_linear_gaussian_reading():
    """r = r0 + A theta + J u + e, theta ~ N(mu, sd^2), u ~ N(0, s^2), e ~ N(0, I): the
    exact log Bayes factor of the reading against "no difference" is
    log N(r0 + A mu; 0, I + A sd^2 A' + J s^2 J') - log N(r0; 0, I + J s^2 J')."""
    rng = np.random.default_rng(3)
    n, p, k = 60, 2, 3
    a, jac = rng.normal(0, 0.4, (n, p)), rng.normal(0, 0.3, (n, k))
    mu, sd, s = np.array([0.5, -0.2]), np.array([1.5, 0.7]), np.array([0.8, 1.2, 0.5])
    r0 = a @ np.array([1.1, 0.4]) + rng.normal(0, 1.0, n)     # truth theta = (1.1, 0.4)
    marg = Marginal(jac, s)

    def log_z(expl_mean, expl_sd, amat):
        prob = SimpleNamespace(
            states=None, marg=marg, s_all=s, keep=list(range(k)),
            reference=SimpleNamespace(candidate=SimpleNamespace(parameter_names=["u1", "u2", "u3"]),
                                      sigma=np.ones(1), tau=np.ones(1), rotor=False),
            expl=SimpleNamespace(mean=tuple(expl_mean), sd=tuple(expl_sd), name="linear",
                                 log_prior=0.0, shift=None,
                                 parameter_names=[f"x.p{i}" for i in range(len(expl_mean))]))
        m = len(expl_mean)
        # the stacked residual is linear in z: its least-squares minimum is the MAP
        big = np.vstack([marg.profile(amat * expl_sd)[0], marg.profile(amat * expl_sd)[1],
                         np.eye(m)]) if m else np.zeros((n + k, 0))
        base = np.concatenate([*marg.profile(r0 + amat @ expl_mean), np.zeros(m)]) \
            if m else np.concatenate(marg.profile(r0))
        z = np.linalg.lstsq(big, -base, rcond=None)[0] if m else np.zeros(0)
        vec = base + big @ z
        return laplace(prob, z, vec, big.T @ big, 0).log_z

    def exact(cov, mean):
        _, logdet = np.linalg.slogdet(cov)
        x = r0 + mean
        return -0.5 * x @ np.linalg.solve(cov, x) - 0.5 * logdet

    null_cov = np.eye(n) + jac @ np.diag(s ** 2) @ jac.T
    effect_cov = null_cov + a @ np.diag(sd ** 2) @ a.T
    want = exact(effect_cov, a @ mu) - exact(null_cov, np.zeros(n))
    got = log_z(mu, sd, a) - log_z((), (), np.zeros((n, 0)))
    assert got == pytest.approx(want, abs=1e-8)


def _evidence(name, values, post, determined=True):
    return SimpleNamespace(name=name, explanation=SimpleNamespace(variant="", parts=()),
                           values=dict(values), post_sd=dict(post),
                           determined={k: determined for k in values}, log_z=0.0)


def test_a_detectable_but_negligible_difference_is_no_difference():
    """A thrust reading of -1.0 +- 0.2 % is 5 posterior spreads from zero (detectable) but
    inside the references' own 2 x 0.8 % band: no difference; -4 % is beyond it."""
    check = SelfCheck(("a", "b"), (), (), {("thrust_factor", ""): {
        "thrust_factor.change": Spread(0.0, 0.008, 20)}})
    small = _evidence("thrust_factor", {"thrust_factor.change": -0.010},
                      {"thrust_factor.change": 0.002})
    large = _evidence("thrust_factor", {"thrust_factor.change": -0.040},
                      {"thrust_factor.change": 0.002})
    assert negligible(small, check) and not negligible(large, check)
    # the boundary: |v - mean| - 1.96 sd_post = PRACTICAL_Z sd_ref
    edge = PRACTICAL_Z * 0.008 + 1.96 * 0.002
    assert negligible(_evidence("thrust_factor", {"thrust_factor.change": edge - 1e-6},
                                {"thrust_factor.change": 0.002}), check)
    assert not negligible(_evidence("thrust_factor", {"thrust_factor.change": edge + 1e-6},
                                    {"thrust_factor.change": 0.002}), check)
    # a reading the references never showed, or no self-check: the statistical rule alone
    assert not negligible(_evidence("mass_offset", {"mass_offset.mass": 1e-3},
                                    {"mass_offset.mass": 1e-4}), check)
    assert not negligible(small, None)
    # in the posterior its weight is "no difference"'s
    null = _evidence("no_difference", {}, {})
    null.log_z, small.log_z = -10.0, 0.0
    ranked = posterior([null, small], lambda ev: negligible(ev, check))
    assert ranked[0][0] == "no_difference" and ranked[0][1] == pytest.approx(1.0)
    assert posterior([null, small])[0][0] == "thrust_factor"


def _logs(cf, effects, seeds, duration=4.0):
    """Exact generated flights, one per seed, at 1.5 m/s or, where the rotors cannot fly
    that path, slower (:func:`benchmarks.synthetic.flyable_flight`)."""
    return [flyable_flight(cf, effects, seed=s, duration=duration, speed=1.5) for s in seeds]


EFFECTS = ["mass_offset", "com_offset", "thrust_mismatch", "body_drag"]


def test_a_trait_every_reference_shares_is_normal_and_a_change_on_top_is_named(cf):
    """Every reference and tested flight carries a quadratic body drag (C_d A 40 cm^2) the
    reference model holds only as a linear rotor drag: the flight with nothing else is
    no_significant_gap, the one with +4 g on top is named mass_offset at about +4 g."""
    drag = [make_effect("body_drag", cd_area=0.004)]
    reference = _logs(cf, drag, (40, 41, 42, 43, 44))
    tested = [*_logs(cf, drag, (45,)),
              *_logs(cf, drag + [make_effect("mass_offset", mass=0.004)], (46,))]
    result = diagnose_per_flight(tested, reference, cf, effects=EFFECTS)
    flights = result["flights"]
    assert flights[0]["outcome"] == "no_significant_gap", flights[0]["answer"]
    assert flights[1]["verdict"] == "mass_offset", flights[1]["answer"]
    assert flights[1]["params"]["mass_offset.mass"] == pytest.approx(0.004, abs=1e-3)
    check = result["reference_model"]["self_check"]
    assert check["clean"] and check["false_alarms"] == []


def test_the_self_check_reports_the_reference_that_differs(cf):
    """Four plain references and one carrying +5 g: judged against the others (leave one
    out), that one is a false alarm of the self-check, named by its file with its reading;
    the set is not clean, and every answer against it says so."""
    plain = _logs(cf, [], (50, 51, 52, 53))
    odd = _logs(cf, [make_effect("mass_offset", mass=0.005)], (54,))
    result = diagnose_per_flight(_logs(cf, [], (55,)), plain + odd, cf, effects=EFFECTS)
    check = result["reference_model"]["self_check"]
    alarms = {a["flight"]: a["verdict"] for a in check["false_alarms"]}
    assert len(check["flights"]) == 5
    # the heavy one is reported with its reading (a plain one flown at the others' edge
    # may be reported as well: five references know little of their own envelope)
    assert alarms[check["flights"][4]] == "mass_offset"
    assert not check["clean"]
    assert "disagree" in result["flights"][0]["answer"]


def test_a_damped_swing_decays_as_a_damped_pendulum():
    """A cable of 0.5 m leaning 0.05 rad, its attachment still, swing damping c = 0.5 1/s:
    the small-angle pendulum theta'' + c theta' + (g / L) theta = 0, whose swing decays as
    exp(-c t / 2) -- a peak 8 s on at about exp(-2) of the first; undamped it keeps it."""
    from quadsim.gap import fitting as cable

    t = np.arange(0.0, 10.0, 0.002)
    accel = np.zeros((len(t), 3))
    start = cable.start_state((0.05, 0.0), (0.0, 0.0))
    period = 2 * np.pi * np.sqrt(0.5 / 9.81)
    window = (t >= 8.0) & (t < 8.0 + period)
    first = t < period
    for damping in (0.5, 0.0):
        q, _ = cable.swing(t, accel, 0.5, 9.81, start, damping=damping)
        late = np.flatnonzero(window)[np.argmax(np.abs(q[window, 0]))]
        early = np.argmax(np.abs(q[first, 0]))
        amplitude = abs(q[late, 0]) / abs(q[early, 0])
        assert amplitude == pytest.approx(np.exp(-damping * (t[late] - t[early]) / 2),
                                          rel=0.02)


def test_with_fewer_than_five_references_a_name_is_never_confident(cf):
    """Two references cannot be judged against each other (no self-check, no scale of what
    they show flight to flight), and three are too few for the discrepancy term (a force
    channel's 4 features need 5 flights): +6 g is still read as a mass of about +6 g, but
    tentative, and the answer says why in each case; against five that judge themselves
    clean the same flight is named confidently."""
    tested = _logs(cf, [make_effect("mass_offset", mass=0.006)], (56,))
    two = diagnose_per_flight(tested, _logs(cf, [], (50, 51)), cf,
                              effects=["mass_offset", "com_offset"])
    flight = two["flights"][0]
    assert two["reference_model"]["self_check"] is None
    assert flight["verdict"] == "mass_offset", flight["answer"]
    assert flight["params"]["mass_offset.mass"] == pytest.approx(0.006, abs=1.5e-3)
    assert flight["tentative"] is True
    assert UNCHECKED_WORDS in flight["answer"]
    three = diagnose_per_flight(tested, _logs(cf, [], (50, 51, 52)), cf,
                                effects=["mass_offset", "com_offset"])
    flight = three["flights"][0]
    assert three["reference_model"]["self_check"] is not None
    assert three["reference_model"]["discrepancy"] is None
    assert flight["verdict"] == "mass_offset" and flight["tentative"] is True, flight["answer"]
    assert FEW_WORDS.format(n=3) in flight["answer"]
    five = diagnose_per_flight(tested, _logs(cf, [], (40, 41, 42, 43, 44)), cf,
                               effects=["mass_offset", "com_offset"])
    flight = five["flights"][0]
    assert five["reference_model"]["self_check"]["clean"] is True
    assert five["reference_model"]["discrepancy"] is not None
    assert flight["verdict"] == "mass_offset" and flight["tentative"] is False, flight["answer"]
    assert flight["params"]["mass_offset.mass"] == pytest.approx(0.006, abs=1.5e-3)
    assert UNCHECKED_WORDS not in flight["answer"] and "too few" not in flight["answer"]


def test_unvouched_says_why_references_cannot_vouch():
    """The one rule of both modes (``judge.unvouched``): no self-check -> the unchecked
    sentence; a self-check but no discrepancy term on the force and moment channels (none,
    or the rotor channels' alone) -> "Only n reference flights: too few";
    a self-check that is not clean -> its own sentence; clean with a discrepancy term -> ""."""
    from types import SimpleNamespace

    from quadsim.gap.calibrate import SelfCheck
    from quadsim.gap.judge import unvouched

    names = tuple(f"r{k}.csv" for k in range(6))
    clean = SelfCheck(names, ("no_significant_gap",) * 6, (), {})
    alarmed = SelfCheck(names, ("mass_offset",) * 2 + ("no_significant_gap",) * 4,
                        (("r0.csv", "mass_offset", ("Fz",)), ("r1.csv", "mass_offset", ("Fz",))),
                        {})
    with_term = SimpleNamespace(discrepancy=SimpleNamespace(covers_motion=True))
    without = SimpleNamespace(discrepancy=None)
    rotors_only = SimpleNamespace(discrepancy=SimpleNamespace(covers_motion=False))
    assert unvouched(None, with_term) == UNCHECKED_WORDS
    assert unvouched(clean, without) == FEW_WORDS.format(n=6)
    assert unvouched(clean, rotors_only) == FEW_WORDS.format(n=6)
    assert unvouched(clean, with_term) == ""
    assert not alarmed.clean and unvouched(alarmed, with_term) == alarmed.text()
    assert "disagree with each other on Fz" in unvouched(alarmed, with_term)


def test_a_reference_unlike_the_others_is_left_out_and_said(cf):
    """Ten references, one of them carrying +6 g (a payload flight given as a reference by
    mistake): judged against the other nine it is named confidently, so it is left out, the
    other nine calibrated and checked again (``calibrate.odd_references``), the result and
    the notes say so, and a +6 g flight is read at its own size against the nine (kept, the
    heavy one widens the references' own spread of a mass reading until +6 g is "no
    difference"); nine references have no room for such a step (1 of 9 is more than 10 %:
    not clean, said in every answer)."""
    heavy = [make_effect("mass_offset", mass=0.006)]
    plain = _logs(cf, [], (60, 61, 62, 63, 64, 65, 66, 67, 68))
    odd = _logs(cf, heavy, (69,))
    tested = _logs(cf, heavy, (70,))
    effects = ["mass_offset", "com_offset"]
    result = diagnose_per_flight(tested, plain + odd, cf, effects=effects)
    model = result["reference_model"]
    assert [(e["flight"], e["verdict"]) for e in model["left_out"]] == \
        [("log9", "mass_offset")], model["left_out"]
    assert len(result["reference"]) == 9 and model["self_check"]["clean"] is True
    assert any(n.startswith("left out of the references: ") for n in result["notes"])
    flight = result["flights"][0]
    assert flight["verdict"] == "mass_offset", flight["answer"]
    assert flight["params"]["mass_offset.mass"] == pytest.approx(0.006, abs=1.5e-3)
    # nine references, one of them heavy: not clean, so nothing is left out (that would make
    # verdicts confident that the disagreement keeps from being so); the answer says so
    nine = diagnose_per_flight(tested, plain[:8] + odd, cf, effects=effects)
    assert nine["reference_model"]["left_out"] == []
    assert nine["reference_model"]["self_check"]["clean"] is False
    assert "Your references disagree with each other" in nine["flights"][0]["answer"]
    assert nine["flights"][0]["outcome"] == "no_significant_gap"      # the +6 g lost in it


def test_odd_references_only_from_a_clean_set_and_only_confident_alarms():
    """``calibrate.odd_references``: the confident false alarms of a clean self-check (at most
    10 % false alarms); a tentative alarm stays; a set that is not clean keeps all."""
    from quadsim.gap.calibrate import odd_references

    names = tuple(f"f{k}" for k in range(20))

    def check(alarms, confident):
        return SelfCheck(names, (), tuple((n, "mass_offset", ("Fz",)) for n in alarms), {},
                         confident=tuple(confident))

    assert odd_references(None) == ()
    assert odd_references(check(["f3"], ["f3"])) == ("f3",)
    assert odd_references(check(["f3", "f7"], ["f7"])) == ("f7",)
    assert odd_references(check(["f3"], [])) == ()                  # tentative: kept
    assert odd_references(check(["f1", "f2", "f3"], ["f1"])) == ()  # 3 of 20: not clean
    nine = SelfCheck(names[:9], (), (("f1", "mass_offset", ()),), {}, confident=("f1",))
    assert not nine.clean and odd_references(nine) == ()


def test_rotor_channels_take_the_command_level_from_the_references_mean():
    """A map whose slope is off by beta at the references' level: each rotor's residual is
    beta_k (u_k - u_bar_k) with u_k the command's 0.5 s moving mean. Where the reference
    model's map is a gain through the origin (``levels``), the term covers the rotor
    channels with one feature each, its offset the references' mean level (closed form: the
    mean of the moving means), its centre beta; a flight flown at another level has exactly
    beta (u - u_bar) taken off its rotor channels. Without ``levels`` (the map a line the
    references determine), or without commands, no rotor channel is covered."""
    from quadsim.gap.reference import command_level

    rng = np.random.default_rng(4)
    betas = np.array([-160.0, -150.0, -170.0, -165.0])      # rad/s per unit command
    states, resid = [], []
    for seed in range(5):
        s = _states(300, 10 + seed)
        # a level that wanders slowly (manoeuvres), around 0.42 per rotor
        slow = np.cumsum(rng.normal(0, 0.002, (300, 4)), axis=0)
        s.command = 0.42 + slow - slow.mean(axis=0) + rng.normal(0, 0.001, 4)
        states.append(s)
    level = [command_level(s) for s in states]
    u_bar = np.concatenate(level).mean(axis=0)
    for u in level:
        r = np.zeros((300, 10))
        r[:, 6:] = (u - u_bar) * betas
        resid.append(r)
    assert fit_discrepancy(resid, states).channels == (0, 1, 2)      # no map through 0
    assert fit_discrepancy(resid, states, levels=(True, False, True)).channels == (
        0, 1, 2, 6, 8)
    d = fit_discrepancy(resid, states, levels=(True,) * 4)
    assert d.channels == (0, 1, 2, 6, 7, 8, 9)
    assert [d.names[k] for k in range(3, 7)] == [("u_1",), ("u_2",), ("u_3",), ("u_4",)]
    for k in range(4):
        assert d.offsets[3 + k] == pytest.approx([u_bar[k]], rel=1e-12)
        assert d.centre[3 + k] == pytest.approx([betas[k]], rel=1e-9)
    assert np.allclose(d.offsets[0], 0.0)
    # a flight flown 0.08 higher: the centre term is beta (u - u_bar) on each rotor
    heavy = _states(300, 99)
    heavy.command = np.full((300, 4), 0.50)
    c = centre_term(heavy, d, 10)
    assert np.allclose(c[:, 6:], (0.50 - u_bar) * betas, rtol=1e-9)
    # the moving mean over MAP_WINDOW_S (0.5 s = 50 samples at 100 Hz), edges padded
    step = _states(300, 5)
    step.command = np.zeros((300, 4))
    step.command[150:] = 1.0
    lv = command_level(step)
    assert lv[0, 0] == 0.0 and lv[-1, 0] == 1.0 and lv[150, 0] == pytest.approx(0.5, abs=0.011)
    # without commands the rotor channels are not covered (the features need them)
    for s in states:
        s.command = None
    assert fit_discrepancy(resid, states, levels=(True,) * 4).channels == (0, 1, 2)


def test_a_rotor_levels_spread_is_a_random_effect_not_the_noise_of_each_estimate():
    """Eight references sharing one map slope (-160 rad/s per unit command), each rotor
    residual with 2 rad/s of white noise on a level that barely moves: their per-flight
    slopes scatter by their own noise. The predictive variance is
    max(0, var(beta_j) - mean se_j^2) + var(beta_j) / n (plus the ridge), se_j^2 the
    least-squares variance s^2 tau / sum(x^2); below the raw scatter x (1 + 1/n) that a
    force channel's coefficients keep, by the estimates' own noise."""
    from quadsim.gap.fitting import correlation_time
    from quadsim.gap.reference import command_level

    rng = np.random.default_rng(8)
    states, resid = [], []
    for seed in range(8):
        s = _states(400, 30 + seed)
        slow = np.cumsum(rng.normal(0, 0.0005, (400, 4)), axis=0)
        s.command = 0.42 + slow - slow.mean(axis=0)
        states.append(s)
    u_bar = np.concatenate([command_level(s) for s in states]).mean(axis=0)
    for s in states:
        r = np.zeros((400, 10))
        r[:, 6:] = -160.0 * (command_level(s) - u_bar) + rng.normal(0, 2.0, (400, 4))
        resid.append(r)
    d = fit_discrepancy(resid, states, levels=(True,) * 4)
    k = d.channels.index(6)
    x = [command_level(s)[:, 0] - u_bar[0] for s in states]
    beta = np.array([xi @ r[:, 6] / (xi @ xi) for xi, r in zip(x, resid)])
    assert d.coefs[k][:, 0] == pytest.approx(beta, rel=1e-9)
    se2 = []
    for xi, r, b in zip(x, resid, beta):
        e = r[:, 6] - b * xi
        se2.append(e @ e / (len(e) - 1) * correlation_time(e) / (xi @ xi))
    var = np.var(beta, ddof=1)
    want = (max(0.0, var - np.mean(se2)) + var / 8) * (1 + 0.1)
    got = float(d.factor[k][0, 0] ** 2)
    assert got == pytest.approx(want, rel=1e-6)
    # below the raw scatter by the estimates' own noise at least (mean se^2 > 0)
    assert got <= (var * (1 + 1 / 8) - min(var, np.mean(se2))) * 1.1 + 1e-9
    # leave one out: the other seven's, by the same rule
    d7 = d.without(3)
    var7 = np.var(np.delete(beta, 3), ddof=1)
    want7 = (max(0.0, var7 - np.mean(np.delete(se2, 3))) + var7 / 7) * 1.1
    assert float(d7.factor[k][0, 0] ** 2) == pytest.approx(want7, rel=1e-6)
