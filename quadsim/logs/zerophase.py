"""Zero-phase filtering by second-order sections along the first axis:
``scipy.signal.sosfiltfilt(sos, x, axis=0)`` (odd extension of its default length) with the
filter's steady-state initial conditions (``scipy.signal.sosfilt_zi``) computed once per
design instead of at every call.

The steps are scipy's own, in its order: extend ``x`` by ``edge = 3 ntaps`` samples at each
end by odd reflection (``2 x_0 - x_k``), filter forward from ``zi x_ext[0]``, filter the
reversed output from ``zi y[-1]``, reverse and cut the extension; ``ntaps = 2 n_sections + 1``
less the sections' shared zero coefficients. The same numbers bit for bit
(``tests/test_zerophase.py``); ``sosfilt_zi`` solves a small linear system per section and
cost as much as the filtering on a fit view's few thousand samples (issue 43 item 7).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=32)
def _steady_state(sos_bytes: bytes, sections: int) -> np.ndarray:
    """``sosfilt_zi`` of the (sections, 6) float64 design given as its bytes; read-only."""
    from scipy.signal import sosfilt_zi

    zi = sosfilt_zi(np.frombuffer(sos_bytes, dtype=float).reshape(sections, 6))
    zi.flags.writeable = False
    return zi


def sosfiltfilt0(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``scipy.signal.sosfiltfilt(sos, x, axis=0)`` (``padtype="odd"``, default ``padlen``)
    bit for bit, the initial conditions kept per design (module doc). ``sos`` (S, 6);
    ``x`` (N,) or (N, ...); raises ValueError where N <= the padding, as scipy."""
    from scipy.signal import sosfilt

    sos = np.array(np.atleast_2d(sos), dtype=float, copy=True)     # writable: sosfilt's
    if sos.ndim != 2 or sos.shape[1] != 6 or not np.all(sos[:, 3] == 1):
        from scipy.signal import sosfiltfilt

        return sosfiltfilt(sos, x, axis=0)          # scipy words the problem
    x = np.asarray(x)
    sections = sos.shape[0]
    ntaps = 2 * sections + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    edge = 3 * ntaps
    if x.ndim == 0 or x.shape[0] <= edge:
        from scipy.signal import sosfiltfilt

        return sosfiltfilt(sos, x, axis=0)
    ext = np.concatenate((2 * x[:1] - x[edge:0:-1], x, 2 * x[-1:] - x[-2:-(edge + 2):-1]),
                         axis=0)
    zi = _steady_state(sos.tobytes(), sections).reshape([sections, 2] + [1] * (x.ndim - 1))
    y, _ = sosfilt(sos, ext, axis=0, zi=zi * ext[:1])
    y, _ = sosfilt(sos, y[::-1], axis=0, zi=zi * y[-1:])
    return y[::-1][edge:-edge]
