"""quadsim.logs.zerophase.sosfiltfilt0 is scipy's sosfiltfilt(axis=0) bit for bit (the
initial conditions kept per design, issue 43 item 7)."""
import numpy as np
import pytest
from scipy import signal

from quadsim.logs.zerophase import sosfiltfilt0


@pytest.mark.parametrize("design", [
    lambda: signal.butter(4, 0.3, output="sos"),
    lambda: signal.butter(4, (4.0, 16.0), btype="bandpass", fs=100.0, output="sos"),
    lambda: signal.butter(2, 0.05, btype="highpass", output="sos"),
    lambda: signal.cheby1(3, 1.0, 0.2, output="sos")])
@pytest.mark.parametrize("shape", [(500,), (800, 3), (300, 2, 2)])
def test_bit_for_bit_scipys(design, shape):
    sos = design()
    x = np.random.default_rng(len(shape)).standard_normal(shape).cumsum(axis=0)
    ours, theirs = sosfiltfilt0(sos, x), signal.sosfiltfilt(sos, x, axis=0)
    assert ours.shape == theirs.shape
    assert np.array_equal(ours.view(np.int64), np.asarray(theirs).view(np.int64))


def test_too_short_is_refused_as_scipy():
    with pytest.raises(ValueError):
        sosfiltfilt0(signal.butter(4, 0.3, output="sos"), np.zeros(10))
