"""Savitzky–Golay smoothing and differentiation along the first axis, as
``scipy.signal.savgol_filter(x, window, polyorder, deriv=, delta=, axis=0)`` with its default
``mode="interp"``, with the ends' polynomial fits as two fixed matrices.

In the interior (``window // 2`` samples in from each end) the output is scipy's own: the
same ``scipy.ndimage.convolve1d`` with ``scipy.signal.savgol_coeffs``. At each end scipy fits
a polynomial of degree ``polyorder`` to the first (last) ``window`` samples by least squares
and evaluates it (or its ``deriv``-th derivative over ``delta ** deriv``) at the first (last)
``window // 2`` positions, one ``polyfit`` per end and call. That map from the ``window``
samples to the ``window // 2`` values is linear and depends only on (window, polyorder,
deriv, delta): here it is built once per such tuple,

    E = D pinv(V),   V[i, k] = u_i^k,   D[j, k] = d^deriv/du^deriv (u^k) at u_j, / delta^deriv

with ``u`` the positions 0..window-1 centred and scaled to [-1, 1] (the same polynomials as
scipy's unscaled positions, better conditioned), and applied as one matrix product per end.
The same numbers as scipy's to round-off (``tests/test_savgol.py``: 1e-12 of the signal's
scale); the ends cost a small fraction of scipy's per-call fits (issue 43 item 7).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft


@lru_cache(maxsize=64)
def _edge_maps(window: int, polyorder: int, deriv: int, delta: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """(left, right), each (window // 2, window): the ends' values from the first and the
    last ``window`` samples (module doc); read-only."""
    half = window // 2
    centre, scale = 0.5 * (window - 1), max(0.5 * (window - 1), 1.0)
    u = (np.arange(window) - centre) / scale
    powers = np.arange(polyorder + 1)
    vander = u[:, None] ** powers[None, :]
    # d^deriv/du^deriv u^k = k!/(k-deriv)! u^(k-deriv); d/dposition = (1/scale) d/du
    factor = np.array([float(np.prod(np.arange(k - deriv + 1, k + 1))) if k >= deriv else 0.0
                       for k in powers])
    exps = np.maximum(powers - deriv, 0)
    evaluate = factor[None, :] * u[:, None] ** exps[None, :] / (scale * delta) ** deriv
    fit = np.linalg.pinv(vander)                       # (polyorder + 1, window)
    full = evaluate @ fit                              # (window, window)
    left, right = full[:half].copy(), full[window - half:].copy()
    left.flags.writeable = right.flags.writeable = False
    return left, right


@lru_cache(maxsize=64)
def _coeffs(window: int, polyorder: int, deriv: int, delta: float) -> np.ndarray:
    from scipy.signal import savgol_coeffs

    out = np.asarray(savgol_coeffs(window, polyorder, deriv=deriv, delta=delta), dtype=float)
    out.flags.writeable = False
    return out


def savgol(x: np.ndarray, window: int, polyorder: int, *, deriv: int = 0,
           delta: float = 1.0, fft: bool = False) -> np.ndarray:
    """``x`` (N,) or (N, ...) smoothed (``deriv`` 0) or differentiated (``deriv`` >= 1, per
    unit of ``delta``) along axis 0 by a Savitzky–Golay filter of odd length ``window`` and
    degree ``polyorder`` < ``window``; scipy's ``savgol_filter(..., axis=0)`` with
    ``mode="interp"`` to round-off (module doc). ``fft``: the interior convolved through one
    FFT of length >= N + window - 1 (no wrap-around) instead of ``convolve1d``'s direct sum:
    the same to round-off (not bit for bit: ~1e-15 of the largest input times the filter's
    absolute coefficient sum, ``tests/test_delay_regression.py``), and cheaper for long
    windows (a 1 s high-pass over ~500 samples: ``quadsim.logs.delays``). Raises
    ValueError where ``window`` exceeds N (as scipy)."""
    from scipy.ndimage import convolve1d

    x = np.asarray(x)
    if x.dtype != np.float64 and x.dtype != np.float32:
        x = x.astype(np.float64)
    window, polyorder, deriv = int(window), int(polyorder), int(deriv)
    if window > x.shape[0]:
        raise ValueError("If mode is 'interp', window_length must be less than or equal to "
                         "the size of x.")
    if window % 2 == 0 or polyorder >= window:
        from scipy.signal import savgol_filter

        return savgol_filter(x, window, polyorder, deriv=deriv, delta=delta, axis=0)
    coeffs = _coeffs(window, polyorder, deriv, float(delta))
    if fft and x.dtype == np.float64:
        # full convolution c (N + window - 1); convolve1d's output is c[half:half + N]
        length = next_fast_len(x.shape[0] + window - 1, real=True)
        spectrum = rfft(coeffs, length).reshape((-1,) + (1,) * (x.ndim - 1))
        y = irfft(rfft(x, length, axis=0) * spectrum, length, axis=0)
        y = np.ascontiguousarray(y[window // 2:window // 2 + x.shape[0]])
    else:
        y = convolve1d(x, coeffs, axis=0, mode="constant")
    half = window // 2
    if half == 0:
        return y
    left, right = _edge_maps(window, polyorder, deriv, float(delta))
    flat = x.reshape(x.shape[0], -1)
    out = y.reshape(y.shape[0], -1)
    out[:half] = left @ flat[:window]
    out[x.shape[0] - half:] = right @ flat[x.shape[0] - window:]
    return y
