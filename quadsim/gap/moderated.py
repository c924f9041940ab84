"""Per-channel spreads of the references' lack of fit, moderated towards their common one.

The lack-of-fit test (:func:`quadsim.gap.judge.lack_of_fit`) compares a flight's log mean
square per channel with the references'. Their scatter differs by channel (several-fold
between the quiet and the noisy channels). One spread pooled over the channels then
over-tests the noisy channels and under-tests the quiet ones; a spread per channel alone
rests on n - 1 degrees of freedom (7 for 8 references). The moderated spread (Smyth 2004,
"Linear models and empirical Bayes methods for assessing differential expression", SAGMB 3:
the limma method) is in between, by the channels' own evidence:

the per-channel variances s_c^2 (d = n - 1 degrees of freedom each) are taken as draws from
a scaled inverse chi-square prior (nu0 degrees of freedom about s0^2). With
``e_c = log s_c^2 - digamma(d/2) + log(d/2)``, the prior's size follows from the scatter
of e over the channels: ``trigamma(nu0 / 2) = var(e) - trigamma(d/2)`` (no prior scatter
left: nu0 infinite, every channel at the pooled spread), and
``log s0^2 = mean(e) + digamma(nu0/2) - log(nu0/2)``. Each channel's moderated variance is
``(nu0 s0^2 + d s_c^2) / (nu0 + d)`` with ``nu0 + d`` degrees of freedom, never more than
the pooled test's C d.

A channel's spread is what the references show *within* their envelope; how a quiet
channel grows beyond them they do not show, so a flight outside the envelope is tested
with the larger of the moderated and the pooled spread
(:func:`quadsim.gap.envelope.local_reference`).

Example::

    >>> spread, dof, pooled = moderated_spread(log_ms)    # log_ms (n flights, C channels)
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq
from scipy.special import digamma, polygamma

__all__ = ["moderated_spread"]


def _trigamma(x):
    return polygamma(1, x)


def moderated_spread(log_ms: np.ndarray) -> tuple[np.ndarray, int, tuple[float, int]]:
    """(spread per channel (C,), its degrees of freedom, (pooled spread, its degrees of
    freedom)) of ``log_ms`` (n flights, C channels) about each channel's mean, moderated
    towards the channels' common spread (module doc)."""
    log_ms = np.asarray(log_ms, dtype=float)
    n, channels = log_ms.shape
    d = n - 1
    pooled_dof = max(1, channels * d)
    pooled = float(np.sum((log_ms - log_ms.mean(axis=0)) ** 2) / pooled_dof)
    common = (float(np.sqrt(pooled)), pooled_dof)
    if d < 1 or channels < 3:
        return np.full(channels, np.sqrt(pooled)), pooled_dof, common
    var = np.maximum(log_ms.var(axis=0, ddof=1), 1e-12 * max(pooled, 1e-300))
    e = np.log(var) - digamma(d / 2) + np.log(d / 2)
    excess = float(np.var(e, ddof=1) - _trigamma(d / 2))
    if excess <= 0:
        return np.full(channels, np.sqrt(pooled)), pooled_dof, common
    # trigamma is decreasing on (0, inf): one root, bracketed from 1e-6 to where it is tiny
    nu0 = 2.0 * brentq(lambda x: _trigamma(x) - excess, 1e-6, 1e7)
    s0 = float(np.exp(np.mean(e) + digamma(nu0 / 2) - np.log(nu0 / 2)))
    moderated = (nu0 * s0 + d * var) / (nu0 + d)
    return np.sqrt(moderated), int(min(pooled_dof, round(nu0 + d))), common
