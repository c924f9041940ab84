"""Per-flight observability: does a flight's true difference from its references show in it?

In per-flight mode a flight is judged against nominal reference flights of its own source.
Its hidden effect can be named only when it leaves a trace in *that* flight, above what the
references themselves scatter. The measure (shared by every per-flight benchmark source:
:mod:`.crazyflow_cases`, :mod:`.cases`):

1. The references' shared physics that quadsim's nominal model lacks (Crazyflow's rotor
   dynamics and body drag, RotorPy's 5 ms motors; nothing for quadsim's own closed loop) as
   library effects at their true values, ``shared``.
2. The motor map fitted on the references (:func:`quadsim.gap.fitting.fit_motor_map`) and
   the noise scale sigma of their residuals under ``shared`` (forces, torques, rotor
   channel; :func:`quadsim.gap.fitting.noise_scale`), as the diagnosis does.
3. A flight's gap under a model: ``G(log, effects) = mean((r / sigma)^2)`` over its samples
   and channels (r: :func:`quadsim.gap.fitting.residuals`, dimensionless).
4. Its true model (:class:`TrueModel`): the shared physics with the true difference in
   quadsim's terms (an effect of the same name replaces the shared one: a slower motor
   replaces the nominal motor lag); for a truth that is a change of the log itself (rotor
   speeds logged late) the log as the true model sees it.

Reported per flight (:class:`Observed`): ``reduction = 1 - G(true) / G(log, shared)`` (0 for
a flight with no library truth: no effect, or one outside the library), and
``gap = G(log, shared) / mean_ref G(ref, shared)``, the flight's gap relative to the
references' own (about 1 when nothing differs; far above 1 an effect, or a flight flown
differently, leaves a gap). A case is observable when ``reduction >= OBSERVABLE``.

Example::

    >>> shared = [make_effect("motor_lag", time_constant=0.005)]
    >>> truth = TrueModel(true_model(shared, [make_effect("mass_offset", mass=0.004)]))
    >>> [(o.reduction, o.gap)] = per_flight_observability([log], refs, params, shared, [truth])
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import VehicleParams

__all__ = ["MIN_GAIN", "OBSERVABLE", "Observed", "TrueModel", "per_flight_observability",
           "true_model"]

#: a case is observable when its true difference cuts the flight's residual by this (5 %)
OBSERVABLE = 0.05
#: held-out mode's observability threshold (:mod:`benchmarks.gap_benchmark`): a hidden
#: effect whose true values cut the held-out gap by less than this fraction is listed apart
#: as unobservable (formerly ``quadsim.gap.diagnose.MIN_GAIN``; the verdict never used it)
MIN_GAIN = 0.05


@dataclass(frozen=True)
class TrueModel:
    """A flight's true model in quadsim's terms: the full effect list (shared physics and the
    true difference, :func:`true_model`) and, for a truth that changes the log (a late rotor
    log), the log as that model sees it (None: the flight as logged)."""

    effects: tuple
    log: FlightLog | None = None


class Observed(NamedTuple):
    """Per flight: the true model's cut of the normalised residual (dimensionless, <= 1) and
    the flight's residual under the shared physics relative to the references' own."""

    reduction: float
    gap: float


def true_model(shared, difference) -> tuple:
    """The shared effects, each replaced by a ``difference`` effect of the same name, then the
    rest of ``difference``."""
    names = {e.name for e in difference}
    return tuple(e for e in shared if e.name not in names) + tuple(difference)


def per_flight_observability(logs: list[FlightLog], references: list[FlightLog],
                             params: VehicleParams, shared,
                             truths: list[TrueModel | None]) -> list[Observed]:
    """:class:`Observed` of each of ``logs`` against ``references`` (module docstring);
    ``truths[i]`` is flight i's true model, None when it has no library form."""
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import fit_motor_map, noise_floor, noise_scale, residuals

    shared = list(shared)
    refs = [f.fit for f in prepare(list(references), params)]
    fitted = fit_motor_map(refs, params)
    nominal = [residuals(f, fitted, shared, rotor_channel=True) for f in refs]
    sigma = noise_scale(np.concatenate(nominal), float(refs[0].t[1] - refs[0].t[0]),
                        floor=noise_floor(fitted, True))

    def gap(log, effects):
        states = prepare([log], params)[0].fit
        return float(np.mean((residuals(states, fitted, list(effects), rotor_channel=True)
                              / sigma) ** 2))

    out = []
    for log, truth in zip(logs, truths):
        before = gap(log, shared)
        if truth is None:
            out.append((0.0, before))
            continue
        after = gap(log if truth.log is None else truth.log, truth.effects)
        out.append((float((before - after) / before), before))
    level = float(np.mean([gap(log, shared) for log in references]))
    return [Observed(r, g / level) for r, g in out]
