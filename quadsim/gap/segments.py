"""A flight of several airborne stretches (take-offs) as one set of states.

A log with several take-offs keeps every airborne stretch as a segment of one flight
(:func:`quadsim.logs.spans.join_airborne`, :attr:`quadsim.logs.flightlog.FlightLog.segments`).
Each stretch is resampled, smoothed and differentiated alone (:func:`quadsim.gap.residual.
flight_states`; all on one time step), trimmed at its own ends and decimated alone
(:func:`quadsim.gap.diagnose.prepare`), and only then are the states joined: the residual is
per sample, so no sample's residual mixes two stretches; the time axis keeps its jump (a
non-uniform time base is read by interpolation where a delay is applied,
:func:`quadsim.gap.reference.read_later`, within one step of a join).

Example::

    >>> from quadsim.gap.segments import joined_states
    >>> states = joined_states([flight_states(p, dt=0.002) for p in log.parts()])
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .residual import FlightStates

__all__ = ["joined_states"]


def joined_states(parts: list[FlightStates]) -> FlightStates:
    """The states of ``parts`` (in time order, one filter and step) concatenated along the
    sample axis; one part is returned as it is. Raises ValueError for parts with different
    filters or a None channel in some parts only."""
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    for p in parts[1:]:
        if (p.window_s, p.polyorder, p.accel_source) != (first.window_s, first.polyorder,
                                                         first.accel_source):
            raise ValueError("joined_states: the parts were smoothed differently")
    arrays = {}
    for f in dataclasses.fields(FlightStates):
        values = [getattr(p, f.name) for p in parts]
        if not isinstance(values[0], np.ndarray) and values[0] is not None:
            continue
        if any(v is None for v in values):
            if not all(v is None for v in values):
                raise ValueError(f"joined_states: {f.name} in some parts only")
            continue
        arrays[f.name] = np.concatenate(values, axis=0)
    return dataclasses.replace(first, **arrays)
