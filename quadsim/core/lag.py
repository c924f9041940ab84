"""The first-order lag through which a rotor follows its command, as a filter on sampled data:
one source for the map fits that read a command -> speed map through the rotors' lag
(:func:`quadsim.identify.motor_fits.fit_motor_map`, ``identify --logs``; and
:func:`quadsim.gap.residual.fit_motor_map`, the gap's reference map).

Example::

    >>> import numpy as np
    >>> from quadsim.core.lag import first_order_lag
    >>> first_order_lag(np.r_[0.0, np.ones(99)][:, None], 0.05, 0.002)[-1, 0]   # ~0.98
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter


def first_order_lag(x: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """``x`` (N, ...) through a first-order lag ``tau dy/dt = x - y`` along axis 0, sample
    step ``dt`` (s), ``tau`` (s): backward Euler, ``y_k = y_(k-1) + alpha (x_k - y_(k-1))``
    with ``alpha = dt / (tau + dt)``, started at rest at the first value (``y_(-1) = x_0``).
    ``x`` itself (not a copy) for ``tau <= 0``. Backward Euler rather than the exact
    exp(-dt / tau): its time constant is off by dt / 2 (1 ms at 500 Hz), below the lag
    grids' steps (2.5-5 ms), and ``identify --logs``' committed numbers were fitted with it."""
    if tau <= 0:
        return x
    x = np.asarray(x, float)
    alpha = dt / (tau + dt)
    zi = (1 - alpha) * x[:1]
    out, _ = lfilter([alpha], [1, -(1 - alpha)], x, axis=0, zi=zi)
    return out
