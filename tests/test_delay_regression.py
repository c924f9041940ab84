"""The delay estimate's all-lags least squares (quadsim.logs.delays.regression_delay: the
lagged columns' products from one running sum, their products with the unlagged columns
through one FFT, the per-lag solve by the plain inverse where well conditioned) against an
independent per-lag least squares (numpy's SVD-based ``lstsq`` on the design matrix itself,
no normal equations), and the 1 s high-pass's FFT convolution (``savgol(..., fft=True)``)
against scipy's ``savgol_filter``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import savgol_coeffs, savgol_filter

from quadsim.logs.delays import _peak, _pseudo_solve, regression_delay
from quadsim.logs.savgol import savgol


def _per_lag(target, regressors, dt, max_lag_s, fixed=None):
    """R^2 per lag by a least-squares solve of each lag's design matrix (the definition in
    regression_delay's docstring, computed without its shortcuts), then the same peak."""
    y = np.asarray(target, float).reshape(len(target), -1)
    x = np.asarray(regressors, float).reshape(len(regressors), -1)
    n = len(y)
    x = (x - x.mean(0)) / np.maximum(x.std(0), 1e-300)
    k_max = max(1, min(int(round(max_lag_s / dt)), n // 4))
    lags = np.arange(-k_max, k_max + 1)
    a = y[k_max:n - k_max]
    m = len(a)
    extra = [np.ones((m, 1))]
    if fixed is not None:
        f = np.asarray(fixed, float).reshape(n, -1)[k_max:n - k_max]
        extra.append((f - f.mean(0)) / np.maximum(f.std(0), 1e-300))
    extra = np.concatenate(extra, 1)
    total = np.sum((a - a.mean(0)) ** 2)
    r2 = np.empty(len(lags))
    for j in range(len(lags)):
        design = np.concatenate([x[j:j + m], extra], 1)
        coef = np.linalg.lstsq(design, a, rcond=None)[0]
        r2[j] = 1.0 - np.sum((a - design @ coef) ** 2) / total
    return _peak(lags, r2, dt)


def _signals(seed, n=1500, lag=7):
    """A target (N, 2) driven by four smooth regressors seen ``lag`` samples late, a fixed
    column the target also follows, and noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n + 40) * 0.002
    base = np.stack([np.sin(2 * np.pi * f * t + p) for f, p in
                     zip(rng.uniform(0.5, 4.0, 4), rng.uniform(0, 6, 4))], 1)
    base += 0.3 * np.cumsum(rng.standard_normal((n + 40, 4)), 0) / np.sqrt(n)
    regressors = base[20:20 + n]                      # regressors[i] = base[i + 20]
    truth = base[20 - lag:20 - lag + n]               # target sees base lag samples earlier
    fixed = np.cos(2 * np.pi * 0.7 * t[:n])[:, None]
    target = np.stack([truth @ [1.0, -0.5, 0.3, 0.2] + 0.4 * fixed[:, 0],
                       truth @ [0.2, 0.9, -0.4, 0.1]], 1) + 1e-3 * rng.standard_normal((n, 2))
    return target, regressors, fixed


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_all_lags_at_once_is_the_per_lag_least_squares(seed):
    target, regressors, fixed = _signals(seed)
    for f in (None, fixed):
        ours = regression_delay(target, regressors, 0.002, 0.1, f)
        theirs = _per_lag(target, regressors, 0.002, 0.1, f)
        assert ours[2] and theirs[2]
        assert abs(ours[0] - theirs[0]) < 1e-9          # s: far below the 0.1 ms reported
        assert abs(ours[1] - theirs[1]) < 1e-9
    # the regressors lag the target: a negative delay of 7 samples (the sign convention of
    # regressors behind target, quadsim.logs.delays)
    assert abs(regression_delay(target, regressors, 0.002, 0.1, fixed)[0] + 0.014) < 0.001


def test_singular_regressors_give_the_minimum_norm_fit():
    """A constant regressor (zero once standardised) and a duplicated one make every lag's
    Gram matrix singular: pinv's minimum-norm solution, the same R^2 as lstsq's."""
    target, regressors, fixed = _signals(5)
    singular = np.concatenate([regressors, np.full((len(regressors), 1), 3.0),
                               regressors[:, :1]], 1)
    ours = regression_delay(target, singular, 0.002, 0.1, fixed)
    theirs = _per_lag(target, singular, 0.002, 0.1, fixed)
    assert abs(ours[0] - theirs[0]) < 1e-9
    assert abs(ours[1] - theirs[1]) < 1e-9


def test_the_plain_inverse_only_where_pinv_cuts_nothing():
    rng = np.random.default_rng(3)
    a = rng.standard_normal((5, 40, 6))
    gram = np.einsum("kij,kil->kjl", a, a)            # well conditioned: the inverse
    assert np.allclose(_pseudo_solve(gram), np.linalg.pinv(gram), rtol=1e-10, atol=0)
    gram[2, :, 5] = gram[2, 5, :] = 0.0               # one exactly singular: pinv for all
    assert np.array_equal(_pseudo_solve(gram),
                          np.linalg.pinv(gram, rcond=np.finfo(float).eps * 6))
    near = gram.copy()                                # condition ~1e13: pinv, not inv
    near[2, 5, 5] = 1e-12 * near[2, 0, 0]
    assert np.array_equal(_pseudo_solve(near),
                          np.linalg.pinv(near, rcond=np.finfo(float).eps * 6))


@pytest.mark.parametrize("window,order,deriv", [(501, 2, 0), (101, 3, 0), (21, 3, 1),
                                                (9, 3, 2), (5, 2, 0)])
def test_savgol_by_fft_is_scipys(window, order, deriv):
    """The FFT's round-off, bounded by the largest input times the filter's absolute
    coefficient sum (measured 2e-16-1.8e-15 of it on these signals)."""
    rng = np.random.default_rng(window)
    t = np.arange(2000) * 0.002
    x = np.stack([np.sin(3 * t) + 0.1 * rng.standard_normal(2000),
                  5e3 + 2e2 * t ** 2 + rng.standard_normal(2000),
                  np.cumsum(rng.standard_normal(2000))], 1)
    for data in (x, x[:, 1]):
        ours = savgol(data, window, order, deriv=deriv, delta=0.002, fft=True)
        theirs = savgol_filter(data, window, order, deriv=deriv, delta=0.002, axis=0)
        assert ours.shape == theirs.shape
        gain = np.abs(savgol_coeffs(window, order, deriv=deriv, delta=0.002)).sum()
        assert np.all(np.abs(ours - theirs) <= 1e-14 * gain * np.max(np.abs(data), axis=0))
