"""Held-out gap helpers: residuals scaled by the noise model, the gap, per-channel RMS.

The *gap* of a set of flights is the mean squared residual per sample and channel, each
channel divided by its noise scale (1 = noise level). A reading's *reduction* is
``(gap_nominal - gap_reading) / gap_nominal`` on the held-out flights
(:mod:`quadsim.gap.heldout_verdict`). Plain functions over lists of (N, C) arrays; no I/O.
"""

from __future__ import annotations

import numpy as np

from ..vehicle.params import VehicleParams
from .fitting import residuals
from .residual import CHANNELS

__all__: list[str] = []


def _scaled(flights: list, params, effects, sigma, rotor: bool, *, full=False):
    return [residuals(f.states if full else f.fit, params, effects, rotor_channel=rotor) / sigma
            for f in flights]


def _gap(scaled: list[np.ndarray]) -> float:
    """Mean squared scaled residual per sample and channel (1 = noise level)."""
    return float(np.mean(np.concatenate(scaled) ** 2))


def _channel_rms(scaled: list[np.ndarray], sigma: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.concatenate(scaled) ** 2, axis=0)) * sigma


def _channels(rotor: bool, params: VehicleParams) -> list[str]:
    names = list(CHANNELS)
    if rotor:
        names += [f"rotor_{i + 1}" for i in range(params.rotor_count)]
    return names
