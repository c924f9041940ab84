"""The weighing's fewer-copies paths (issue 43, the inner evidence loop) against the code they
replace, to the bit (each keeps the same floating-point operations in the same order): the
marginal written column-major at once against the stacked, scaled and copied matrix; the
linear step's [A b] written column-major and factored in place against the column stack
copied; the shifted states by a shallow copy against ``dataclasses.replace``; the read
later with its phase rate kept per length against the phase formed anew; the rotor channel
with the closed-form lag's command terms kept per rotor model against
:func:`quadsim.gap.residual.heun_linear`. A generated flight and random matrices."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from scipy.linalg import cho_factor

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import QuadsimWarning
from quadsim.effects import make_effect
from quadsim.gap.diagnose import prepare
from quadsim.gap.evidence import Marginal, _upper_factor
from quadsim.gap.reference import _spectrum, read_later, rotor_spectra, shifted
from quadsim.gap.residual import (
    ROTOR_SUBSTEPS,
    _heun_weights,
    heun_linear,
    rotor_model,
    rotor_residual,
)
from quadsim.vehicle.params import load_params

from _helpers import shared_effects


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def states(cf):
    log = synthetic_flight(cf, shared_effects(), duration=3.0, seed=91, speed=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return prepare([log], cf)[0].fit


def test_the_marginal_written_column_major_is_the_stacked_scaled_copy():
    """Marginal(jac, s, extra) against the matrix the evidence built before:
    ``asfortranarray(hstack([jac, extra]) * concatenate([s, ones]))``, its A = I + jᵀj from
    the row-major product and A's Cholesky factor; the profile of a vector and of columns."""
    rng = np.random.default_rng(7)
    jac, extra = rng.normal(size=(600, 9)), rng.normal(size=(600, 4))
    s = rng.uniform(0.1, 3.0, 9)
    fast = Marginal(jac, s, extra)
    stacked = np.hstack([jac, extra]) * np.concatenate([s, np.ones(4)])
    assert np.array_equal(fast.j, stacked) and fast.j.flags.f_contiguous
    chol = cho_factor(np.eye(13) + stacked.T @ stacked)
    assert np.array_equal(fast.chol[0], chol[0]) and fast.chol[1] == chol[1]
    assert fast.logdet == 2.0 * float(np.sum(np.log(np.diag(chol[0]))))
    for r in (rng.normal(size=600), rng.normal(size=(600, 3))):
        du = -np.linalg.solve(np.eye(13) + stacked.T @ stacked, stacked.T @ r)
        aug, got = fast.profile(r)
        np.testing.assert_allclose(got, du, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(aug, r + stacked @ du, rtol=1e-12, atol=1e-12)
    plain = Marginal(jac, s)                       # no extra columns: jac's alone
    assert np.array_equal(plain.j, jac * s)


def test_the_linear_steps_matrix_factored_in_place_is_the_copied_column_stack():
    """_upper_factor of [A b] written column-major and overwritten, against the copy of
    ``np.column_stack([a, b])`` it factored before: the same R, to the bit."""
    rng = np.random.default_rng(8)
    a, b = rng.normal(size=(700, 4)), rng.normal(size=700)
    want = _upper_factor(np.column_stack([a, b]))
    ab = np.empty((700, 5), order="F")
    ab[:, :4], ab[:, 4] = a, b
    assert np.array_equal(_upper_factor(ab, overwrite=True), want)
    row_major = np.column_stack([a, b])             # not column-major: copied, kept
    kept = row_major.copy()
    assert np.array_equal(_upper_factor(row_major, overwrite=True), want)
    assert np.array_equal(row_major, kept)


def test_the_shifted_states_are_the_replaced_states(states):
    """shifted (a shallow copy with the rotor fields set) against ``dataclasses.replace``
    with the speeds read later by the phase formed anew: every field the same, to the bit."""
    delay = 0.0037
    view = shifted(states, delay, rotor_spectra(states))
    n, t = len(states.t), states.t
    dt = (t[-1] - t[0]) / (n - 1)
    joined = np.hstack([_spectrum(t, states.rotor_speed), _spectrum(t, states.rotor_accel)])
    nu = np.fft.rfftfreq(2 * n)[:, None]
    both = np.fft.irfft(joined * np.exp(2j * np.pi * nu * (delay / dt)), 2 * n, axis=0)[:n]
    k = states.rotor_speed.shape[1]
    want = dataclasses.replace(states, rotor_speed=both[:, :k], rotor_accel=both[:, k:])
    assert type(view) is type(want) and view is not states
    for f in dataclasses.fields(want):
        got, ref = getattr(view, f.name), getattr(want, f.name)
        if isinstance(ref, np.ndarray):
            assert np.array_equal(got, ref), f.name
        else:
            assert got == ref, f.name
    assert states.rotor_speed is not view.rotor_speed       # the original left as it was
    assert np.array_equal(read_later(t, states.rotor_speed, delay), both[:, :k])


def test_the_rotor_channels_kept_lag_terms_are_the_closed_form(cf, states):
    """The rotor channel of a linear lag with its command terms kept per rotor model, read at
    several delays, against heun_linear's sum formed anew (as it was written before the terms
    were kept): the same numbers, to the bit."""
    lag = make_effect("motor_lag", time_constant=0.011)
    memo: dict = {}
    for delay in (0.0, 0.0021, -0.0034):
        view = shifted(states, delay)
        model = rotor_model(view, cf, [lag], memo=memo)
        assert model.tau == pytest.approx(0.011)
        got = rotor_residual(view, cf, [lag], memo=memo)
        steps, n = model.steps, model.n
        gain, weights = _heun_weights(steps, model.dt / ROTOR_SUBSTEPS, model.tau)
        predicted = gain * view.rotor_speed[:n]          # heun_linear as it was written
        for k in range(steps + 1):
            predicted = predicted + weights[k] * model.cmd[k:k + n]
        assert np.array_equal(predicted, heun_linear(view.rotor_speed[:n], model.cmd, steps,
                                                     model.dt / ROTOR_SUBSTEPS, model.tau, n))
        want = np.zeros_like(view.rotor_speed)
        want[steps:] = view.rotor_speed[steps:] - predicted
        assert np.array_equal(got, want)
        assert np.array_equal(rotor_residual(view, cf, [lag]), want)    # no memo
