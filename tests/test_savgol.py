"""quadsim.logs.savgol.savgol against scipy's savgol_filter (axis 0, mode "interp"): the
same numbers to 1e-12 of the signal's scale (1e-11 for a second derivative); the interior
bit for bit."""
import numpy as np
import pytest
from scipy.signal import savgol_filter

from quadsim.logs.savgol import savgol


@pytest.mark.parametrize("window,order,deriv,delta", [
    (5, 3, 0, 1.0), (11, 2, 0, 1.0), (101, 2, 0, 1.0), (21, 3, 1, 0.01), (9, 3, 2, 0.002),
    (3, 1, 0, 1.0), (7, 0, 0, 1.0)])
def test_savgol_is_scipys(window, order, deriv, delta):
    rng = np.random.default_rng(window + order)
    t = np.arange(400) * 0.01
    x = np.stack([np.sin(3 * t) + 0.1 * rng.standard_normal(400),
                  5e3 + 2e2 * t ** 2 + rng.standard_normal(400)], 1)
    for data in (x, x[:, 0]):
        ours = savgol(data, window, order, deriv=deriv, delta=delta)
        theirs = savgol_filter(data, window, order, deriv=deriv, delta=delta, axis=0)
        assert ours.shape == theirs.shape
        half = window // 2
        assert np.array_equal(ours[half:len(data) - half], theirs[half:len(data) - half])
        scale = np.max(np.abs(theirs), axis=0)
        # both fits round differently; a second derivative amplifies it (measured 2e-12)
        assert np.all(np.abs(ours - theirs) <= (1e-12 if deriv < 2 else 1e-11) * scale)


def test_a_polynomial_of_the_order_is_kept_at_the_ends():
    """Where the data are a polynomial of the filter's degree, the ends are the polynomial
    (and its derivative): a closed form, independent of scipy."""
    t = np.arange(50) * 0.1
    x = 2.0 - 3.0 * t + 0.5 * t ** 2
    assert np.allclose(savgol(x, 11, 2), x, rtol=0, atol=1e-12)
    assert np.allclose(savgol(x, 11, 2, deriv=1, delta=0.1), -3.0 + t, rtol=0, atol=1e-10)


def test_a_window_longer_than_the_data_is_refused():
    with pytest.raises(ValueError):
        savgol(np.zeros(4), 5, 2)
