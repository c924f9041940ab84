"""The screen's step held on the inertia's wall (quadsim.gap.evidence.linear_step,
InertiaWall; quadsim.gap.fitting.plane_step): the closed form against independent
constrained least-squares solves, the wall's linear form against the vehicle's own check,
and a flight whose inertia lies on the wall read there without the full fit."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.linalg import null_space
from scipy.optimize import minimize

import quadsim.gap.evidence as evidence
from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import QuadsimWarning
from quadsim.effects import make_effect
from quadsim.gap.calibrate import calibrate
from quadsim.gap.diagnose import prepare
from quadsim.gap.fitting import plane_step
from quadsim.vehicle.params import inertia_problems, load_params

from _helpers import shared_effects


def _quadratic(seed: int, n: int = 4):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(3 * n, n))
    r = np.linalg.qr(a, mode="r")
    return r, rng.normal(size=n), rng.normal(size=n)


@pytest.mark.parametrize("seed", range(5))
def test_the_step_on_the_plane_is_the_constrained_least_squares_minimum(seed):
    """Inside the box: the closed form against the minimum over the plane's null space
    (x = x_p + N y, y by ordinary least squares), to round-off."""
    r, qb, c = _quadratic(seed)
    h = 0.3
    big = (np.full(4, -1e6), np.full(4, 1e6))
    x = plane_step(r, qb, c, h, bounds=big)
    xp = c * h / float(c @ c)
    n = null_space(c[None, :])
    y = np.linalg.lstsq(r @ n, -(qb + r @ xp), rcond=None)[0]
    expect = xp + n @ y
    assert float(c @ x) == pytest.approx(h, abs=1e-12)
    np.testing.assert_allclose(x, expect, atol=1e-10)


def test_the_step_on_the_plane_within_a_box_is_slsqps():
    """With the box: where the plane's minimum lies inside, it is SLSQP's minimum over the
    box and the plane (its tolerance); where it leaves the box, no step (the caller keeps
    its own)."""
    r, qb, c = _quadratic(1)
    h = 0.2
    free = plane_step(r, qb, c, h, bounds=(np.full(4, -1e6), np.full(4, 1e6)))
    wide = (-np.abs(free) - 0.1, np.abs(free) + 0.1)
    x = plane_step(r, qb, c, h, bounds=wide)

    def cost(v):
        return float(np.sum((qb + r @ v) ** 2))

    ref = minimize(cost, np.zeros(4), jac=lambda v: 2 * r.T @ (qb + r @ v), method="SLSQP",
                   bounds=list(zip(*wide)),
                   constraints=[{"type": "eq", "fun": lambda v: float(c @ v) - h}],
                   options={"ftol": 1e-14, "maxiter": 500})
    assert ref.success
    assert cost(x) == pytest.approx(ref.fun, rel=1e-6, abs=1e-9)
    np.testing.assert_allclose(x, ref.x, atol=1e-5)
    tight = (-0.5 * np.abs(free), 0.5 * np.abs(free) + 1e-9)
    assert plane_step(r, qb, c, h, bounds=tight) is None
    assert plane_step(r, qb, np.zeros(4), h, bounds=wide) is None


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def reference(cf):
    logs = [synthetic_flight(cf, shared_effects(), duration=4.0, seed=s, speed=0.8 + 0.2 * s)
            for s in range(3)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return calibrate(prepare(logs, cf), cf)


#: a flight whose inertia lies on the wall: Ixx + Iyy = 0.85 (2 x 2.05e-5) = 3.485e-5 kg m^2
#: against Izz = 1.14 x 3.05e-5 = 3.477e-5 kg m^2 (crazyflie21)
ON_WALL = {"xx": -0.15, "yy": -0.15, "zz": 0.14}


@pytest.fixture(scope="module")
def on_wall(cf):
    log = synthetic_flight(cf, shared_effects() + [make_effect("inertia_error", **ON_WALL)],
                           duration=4.0, seed=82)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return prepare([log], cf)[0].fit


def _inertia_problem(reference, states):
    expl = next(e for e in evidence.explanations_for(reference, states)
                if e.name == "inertia_error")
    names = list(reference.candidate.parameter_names)
    jac = evidence.jacobian(states, reference, list(range(len(names))),
                            reference.candidate.effects)
    inputs = evidence.FitInputs(states, reference, jac, reference.s_ref, {})
    return inputs, expl, inputs.problem(expl)


def test_the_walls_linear_form_is_the_vehicles_own_check(cf, reference, on_wall):
    """g = I_a + I_b - I_c of the moments the effects give (apply_to_params), and a point
    crosses exactly where the vehicle's check (inertia_problems) refuses its inertia."""
    _, expl, prob = _inertia_problem(reference, on_wall)
    names = list(expl.parameter_names)
    start = prob.start(0.0)
    wall = evidence.inertia_wall(prob, start)
    assert wall is not None
    rng = np.random.default_rng(3)
    crossed = 0
    for _ in range(40):
        x = np.zeros(len(start))
        for k, n in enumerate(names):
            if n in evidence.INERTIA_KEYS:       # inside the values' bounds (-90 .. +200 %)
                x[k] = rng.uniform(prob.z_lo[k], min(prob.z_hi[k], 1.5)) - start[k]
        theta = prob.mean + prob.sd * (start + x)
        error = [theta[names.index(k)] for k in evidence.INERTIA_KEYS]
        moments = np.diag(np.asarray(cf.inertia, float)) * (1 + np.array(error))
        expect = moments.sum() - 2 * moments            # row c: the others less I_c
        got = wall.g0 + wall.g @ x
        np.testing.assert_allclose(got, expect, atol=1e-12 * moments.max())
        refused = bool(inertia_problems(np.diag(moments)))
        assert wall.crossed(got) == refused
        crossed += refused
    assert 5 < crossed < 35                             # both sides drawn


def test_a_flight_on_the_wall_is_read_there_without_the_full_fit(cf, reference, on_wall,
                                                                   monkeypatch):
    """The inertia reading's steps stay in the physical set: no fall-back to the full fit
    (before: the step crossed the wall and the full fit read it, its finite differences
    across the wall costing ~20 log units of Occam factor on the real references), the
    reading on the wall, and it is the constrained minimum of the same cost found
    independently (SLSQP on the stacked cost, the wall as an inequality, from the prior's
    centre and from the reading: none lower by 0.05, a tenth of a log-evidence unit), and
    the flight's inertia within two posterior spreads of its truth."""
    calls = []
    real_full = evidence.full_fit
    monkeypatch.setattr(evidence, "full_fit", lambda *a, **k: calls.append(a[1].name)
                        or real_full(*a, **k))
    expl_all = evidence.explanations_for(reference, on_wall)
    rows = evidence.evaluate(on_wall, reference, expl_all, 0.0)
    assert "inertia_error" not in calls
    row = next(r for r in rows if r.name == "inertia_error")
    assert not row.screened
    assert row.log_z == max(r.log_z for r in rows)          # the flight's own reading leads
    inputs, expl, prob = _inertia_problem(reference, on_wall)
    names = list(expl.parameter_names)
    z = (np.array([row.values[k] for k in names]) - prob.mean) / prob.sd
    wall = evidence.inertia_wall(prob, z)
    assert wall.on(wall.g0)

    def cost(v):
        vec = prob.stacked(v)
        return float(vec @ vec)

    def solve(z0):
        return minimize(cost, z0, method="SLSQP", bounds=list(zip(prob.z_lo, prob.z_hi)),
                        constraints=[{"type": "ineq", "fun": lambda v: float(np.min(
                            wall.g0 + wall.g @ (v - z))) / wall.scale}],
                        options={"ftol": 1e-12, "maxiter": 500}).fun

    inertia = [k for k, n in enumerate(names) if n in evidence.INERTIA_KEYS]
    centre = np.where(np.isin(np.arange(len(z)), inertia), 0.0, z)
    # measured: 317.75 against SLSQP's 320.32 from the centre, none lower from the reading
    assert cost(z) <= solve(centre) + 0.05
    assert solve(z) >= cost(z) - 0.05
    for key, truth in ON_WALL.items():       # measured within 0.9 posterior spreads
        name = f"inertia_error.{key}"
        assert abs(row.values[name] - truth) < 2.0 * row.post_sd[name]
