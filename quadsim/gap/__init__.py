"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, and how
far it shrinks once that effect is added.

Method (equation error, then prediction error)
----------------------------------------------
1. Every log is resampled and smoothed with one zero-phase Savitzky–Golay filter
   (:mod:`quadsim.gap.residual`); Newton–Euler turns the measured motion into the wrench that
   acted, and the model (parameter set + candidate effects, through the effect hooks the
   engines use) predicts it from the measured rotor speeds. Their difference, per channel
   Fx Fy Fz Mx My Mz (+ one rotor-speed channel per rotor when commands are logged: the
   speed predicted 0.12 s ahead from the command, which is where motor lag shows), divided
   by each channel's noise scale, is the *gap* (1 = sensor noise).
2. Flights are split by flight (never by sample): ``--holdout`` or every third flight.
3. Verdict by evidence (:mod:`.diagnose`, :mod:`.judge`): the parameter set is the
   reference model; the noise model per channel is the scatter of the residual's fast part
   (minus its 0.5 s moving average: what the gap does not contain). Every explanation of how
   the flights differ (each library effect, ``nominal_refit`` = b and d re-identified, or no
   difference) is fitted on the training flights (:mod:`.evidence`: likelihood over all
   channels, priors with sources, Laplace evidence with its Occam factor), then predicts the
   held-out flights; :func:`.judge.posterior` gives a probability per reading. A second
   effect is added when the lead leaves a systematic remainder or does not carry over, and
   the pair earns it.
4. The verdict: the most probable reading with its magnitude (determined parameters only),
   ``no_significant_gap``, or ``unexplained`` (lack of fit: a held-out flight beyond what the
   reading leaves on the training flights, or a systematic remainder with no effect to
   explain it; an implausible magnitude; parameters that differ between regimes,
   :mod:`.judge`).
5. Where: held-out gap by channel, by regime (hover, climb, descent, fast forward,
   aggressive rotation, near ground, low battery), by frequency band, and as k-step
   prediction error of position and attitude (0.05-1 s, multiple shooting with the analytic
   engine) before and after the verdict (:mod:`.judge`).

``diagnose_per_flight`` (:mod:`.diagnose`) judges each flight alone against nominal
reference flights, by evidence: :mod:`.calibrate` absorbs what every reference flight shares
(b, d, motor map and its gain, motor lag, rotor drag, vertical drag, inertia, rate damping,
the rotor delay) into a reference model with a per-channel noise model; :mod:`.reference`
places the flight against the references' envelope (speed, body rate, thrust variation),
states when it lies outside and by how much, and there widens the reference model by the
trend the references show; :mod:`.evidence` fits every explanation of
how a flight differs (:mod:`.explanations`: an effect, a shared parameter at a value of its
own, a logged signal's delay, or none, each with its prior) and weighs it by its Laplace
evidence; :mod:`.judge` gives the posterior per
reading, a lack-of-fit test ("not in the library") and the verdict, :mod:`.words` the
answer. A flight that cannot be judged is ``refused`` with its reason; the others go on.

Both modes share one judgment (:mod:`.judge`: posterior, one lack-of-fit rule whose
baseline -- the reference flights, or the reading's own training flights -- is data, one
outcome rule), one answer writer (:mod:`.words`) and one result type
(:class:`.result.Diagnosis` holding :class:`.result.Verdict`, with ``to_json()``).

Modules, one per stage, imports flowing down (each module's docstring is its manual):
:mod:`.residual` (the residual wrench per sample, the rotor-speed channel, the command ->
speed map, the memo), :mod:`.logcheck` (the vehicle check, command-only logs, the rotor order,
logs without a pose), :mod:`.fitting` (the fit forms beyond the library, plausible magnitudes
and words, least squares of candidate effects), :mod:`.reference` (the reference model as
data: the discrepancy term, moderated spreads, the envelope), :mod:`.calibrate` (calibration
and the references' self-check), :mod:`.explanations` (what a flight is weighed by),
:mod:`.evidence` (each explanation's fit and Laplace evidence; the drag law), :mod:`.words`
(answers), :mod:`.result` (result types), :mod:`.judge` (where and when; the verdict of both
modes), :mod:`.page` (the HTML report, its figures and residual series), :mod:`.report` (JSON
and its schema, summaries, the effect file, the rerun recording), :mod:`.diagnose` (both modes'
entry points), :mod:`.cache` (the CLI's cache of the references' stage). Generated test flights:
``benchmarks.synthetic`` in the repository (not in the wheel).

Example::

    >>> from quadsim.logs.flightlog import load_log
    >>> from quadsim.vehicle.params import load_params
    >>> from quadsim.gap import diagnose
    >>> result = diagnose([load_log(p) for p in paths], load_params("crazyflie21"))
    >>> result.verdict.name, result.verdict.reduction       # or result["verdict"]["effect"]

CLI: ``python -m quadsim.gap --help``. Result schema: :data:`GAP_SCHEMA`
(``quadsim.gap/3``, :mod:`quadsim.gap.report`), documented in docs/gap.md.
"""

from ..core.errors import refuse_moved
from .diagnose import SCHEMA, diagnose, diagnose_per_flight, prepare
from .report import GAP_SCHEMA, summary, to_json, validate, write_html, write_json, write_rerun
from .result import Diagnosis, Reading, Verdict

__all__ = ["GAP_SCHEMA", "SCHEMA", "Diagnosis", "Reading", "Verdict",
           "diagnose", "diagnose_per_flight", "prepare", "summary",
           "to_json", "validate", "write_html", "write_json", "write_rerun"]

#: public names that left the package, and where they are now (refused with that change)
_MOVED = {"synthetic_flight": "benchmarks.synthetic", "SensorNoise": "benchmarks.synthetic"}


#: modules merged into the stage they belong to (issue 43), old name -> new module
_MERGED = {
    "cable": "fitting",
    "checks": "logcheck",
    "commands": "logcheck",
    "discrepancy": "reference",
    "drag_law": "evidence",
    "envelope": "reference",
    "fitmodels": "fitting",
    "memo": "residual",
    "moderated": "reference",
    "motor_map": "residual",
    "order": "logcheck",
    "per_flight": "diagnose",
    "plots": "page",
    "posefree": "logcheck",
    "priors": "fitting",
    "problem": "evidence",
    "recording": "report",
    "rotor_channel": "residual",
    "segments": "residual",
    "selfcheck": "calibrate",
    "traces": "page",
    "where": "judge",
}

__getattr__ = refuse_moved(__name__, {
    **{name: f"moved to {where} (in the repository, not the wheel): write `from {where} import "
             f"{name}` and run from a checkout" for name, where in _MOVED.items()},
    **{old: f"was merged into quadsim.gap.{new}: write `from quadsim.gap import {new}` or "
            f"`from quadsim.gap.{new} import NAME` (every name kept its name)"
       for old, new in _MERGED.items()}})
