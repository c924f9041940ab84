"""Does the parameter set describe the logged vehicle at all? Checked before any fit.

A diagnosis that fits effects to flights of a *different* vehicle finds nonsense with
confidence (CHANGELOG: another vehicle's set named an effect at 99.8 %). Two balances that
hold for any vehicle flying on its own rotors catch it first:

* hover/force balance along body z: ``m f_z = b sum_i Omega_i^2`` (f_z the measured
  specific force) gives the thrust factor the data need, by least squares over all samples;
  its ratio to the model's b must lie in [1/:data:`MAX_RATIO`, :data:`MAX_RATIO`]
  (a payload of 60 % of the mass or a 40 % thrust loss still passes, another vehicle not);
* the logged rotor speeds must be reachable: median speed <= :data:`MAX_SPEED_RATIO` x the
  model's ``max_speed``;
* yaw balance ``I_zz dr/dt ~= d sum_i s_i Omega_i^2`` gives the drag factor the data need
  (reported, not enforced: it is noisy on gentle flights).

:func:`vehicle_check` returns the ratios (for the result's ``checks``) and raises
:class:`~quadsim.core.errors.InputError` with the numbers that disagree.

:func:`check_length` refuses a log shorter than :data:`MIN_LOG_S` = 2 s (the edges cut after
smoothing, the noise window and one scoring block need it) or, with ``window_s``, sampled too
coarsely for the differentiator's window (fewer than 5 samples); :func:`quadsim.gap.prepare`
applies the length check to every log given to the library, the CLI both.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import InputError
from ..vehicle.params import VehicleParams
from ..vehicle.rotors import allocation_matrix

__all__ = ["MAX_RATIO", "MAX_SPEED_RATIO", "MIN_LOG_S", "check_length", "vehicle_check"]

#: largest ratio (either way) of the thrust factor the data need to the model's: a payload
#: of 60 % of the mass or a 40 % thrust loss still passes, another vehicle does not
MAX_RATIO = 2.0
#: largest median logged rotor speed over the model's ``max_speed``: a rotor cannot run
#: half again beyond its top speed, a log in other units or of another vehicle does
MAX_SPEED_RATIO = 1.5
#: shortest log the diagnosis can use (s): the 0.2 s edges at both ends, the 0.5 s window
#: of the noise scale and a 1 s scoring block
MIN_LOG_S = 2.0


def check_length(log, window_s: float | None = None, name: str | None = None) -> None:
    """A log long enough for the diagnosis and, with ``window_s`` (s), sampled finely
    enough for it; raises :class:`InputError` naming the file (``name``, default the log's
    path) and ``t``."""
    name = name or str(log.path)
    duration = float(log.t[-1] - log.t[0]) if len(log.t) else 0.0
    if duration < MIN_LOG_S:
        raise InputError(f"{name}: t: {duration:.3g} s of flight; the diagnosis needs "
                         f"at least {MIN_LOG_S:g} s (edges, noise window, a scoring block)")
    step = float(np.median(np.diff(log.t)))
    if window_s is not None and window_s < 5 * step:
        raise InputError(f"--window {window_s:g} s: shorter than 5 samples of {name} "
                         f"(median step {step:.4g} s); the differentiator needs 5 or more")


def vehicle_check(states: list, params: VehicleParams) -> dict:
    """Ratios data/model of b, d and rotor speed over ``states`` (FlightStates; module doc):
    ``{"thrust_factor_data": b the data need (N s^2/rad^2), "thrust_factor_ratio": that over
    the model's b, "drag_factor_ratio": d the yaw balance needs over the model's d,
    "median_speed_ratio": median logged speed over ``max_speed`` (None without one)}``.
    Raises InputError when the parameter set cannot be the logged vehicle's (b ratio
    outside [1/:data:`MAX_RATIO`, :data:`MAX_RATIO`] or speed ratio above
    :data:`MAX_SPEED_RATIO`). States without rotor speeds are skipped ({} when none has
    them)."""
    states = [s for s in states if s.rotor_speed is not None]
    if not states:  # command-only logs: nothing to balance against here
        return {}
    speed = np.concatenate([s.rotor_speed for s in states])
    sf = np.concatenate([s.specific_force for s in states])
    rate_dot = np.concatenate([s.body_accel for s in states])
    omega2 = np.square(speed)
    x = omega2.sum(axis=1)
    b_data = float(params.mass * np.dot(sf[:, 2], x) / max(np.dot(x, x), 1e-300))
    b_ratio = b_data / params.thrust_factor
    yaw_row = allocation_matrix(params)[5] / params.drag_factor  # +-1 per rotor (spin)
    xy = omega2 @ yaw_row
    xy = xy - xy.mean()
    mz = rate_dot[:, 2] * params.inertia[2, 2]
    mz = mz - mz.mean()
    d_ratio = float(np.dot(mz, xy) / max(np.dot(xy, xy), 1e-300)) / params.drag_factor
    speed_ratio = float(np.median(speed) / params.max_speed) if params.max_speed else None
    out = {"thrust_factor_data": b_data, "thrust_factor_ratio": float(b_ratio),
           "drag_factor_ratio": d_ratio, "median_speed_ratio": speed_ratio}
    problems = []
    if not 1 / MAX_RATIO <= b_ratio <= MAX_RATIO:
        problems.append(f"the force balance m*f_z = b*sum(Omega^2) with the model's mass "
                        f"{params.mass:.4g} kg needs b = {b_data:.3g} N s^2/rad^2, "
                        f"{b_ratio:.3g}x the model's {params.thrust_factor:.3g} N s^2/rad^2")
    if speed_ratio is not None and speed_ratio > MAX_SPEED_RATIO:
        problems.append(f"the median logged rotor speed {np.median(speed):.4g} rad/s is "
                        f"{speed_ratio:.3g}x the model's max_speed {params.max_speed:.4g} rad/s")
    if problems:
        raise InputError(f"model {params.name!r} does not describe the logged vehicle: "
                         + "; ".join(problems) + f" (yaw balance: d {d_ratio:.3g}x the "
                         "model's); give the parameter set of the vehicle that flew")
    return out
