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
   Each library effect (:data:`quadsim.effects.EFFECTS`; see :data:`.fitting.FIT_SPEC` for
   the parameters fitted) is fitted on the training flights by bounded
   ``scipy.optimize.least_squares``; 95 % CIs come from the Jacobian, widened by the
   residuals' correlation time. ``wind`` is fitted together with the rotor-drag coefficient
   (wind alone exerts no force).
3. Each fit is scored by its held-out gap (:mod:`.scoring`). The baseline ``nominal_refit``
   refits b and d. An effect explains a clear share when it cuts the held-out gap by >= 5 %,
   passes a block t test, has a parameter identified (CI < half its plausible range) and
   significantly away from "off", and is not worse than the baseline. Among effects within
   2 % of the best, the most plausible magnitude (:mod:`.priors`) is named and every
   plausible tied one is stated as another *reading* with its magnitude and what would
   separate them (:mod:`.collinear`). Greedy selection then adds a second effect if it earns
   a further clear gain and every part stands (:mod:`.combine`).
4. The verdict (:mod:`.verdict`): the named effect, ``no_significant_gap`` (held-out residual
   at a floor taken from data on every channel) or ``unexplained``; a named effect must have
   one value in every regime (:mod:`.consistency`).
5. Where: held-out gap by channel, by regime (hover, climb, descent, fast forward,
   aggressive rotation, near ground, low battery), by frequency band, and as k-step
   prediction error of position and attitude (0.05-1 s, multiple shooting with the analytic
   engine) before and after the verdict (:mod:`.where`).

``diagnose_per_flight`` (:mod:`.per_flight`) judges each flight alone against nominal
reference flights, by evidence: :mod:`.calibrate` absorbs what every reference flight shares
(b, d, motor map, motor lag, rotor drag, inertia, rate damping, the rotor delay) into a
reference model with a per-channel noise model; :mod:`.evidence` fits every explanation of
how a flight differs (an effect, a shared parameter at a value of its own, a logged signal's
delay, or none) and weighs it by its Laplace evidence; :mod:`.judge` gives the posterior per
reading, a lack-of-fit test ("not in the library") and the answer. A flight that cannot be
judged is ``refused`` with its reason; the others go on.

Modules, in pipeline order: :mod:`.diagnose` (prepare logs, split, rank, decide),
:mod:`.motor_map` (static command -> speed map from data), :mod:`.fitting` (candidates and
least squares), :mod:`.scoring`, :mod:`.collinear` + :mod:`.priors`, :mod:`.combine`,
:mod:`.verdict`, :mod:`.consistency`, :mod:`.per_flight` (:mod:`.calibrate`,
:mod:`.evidence`, :mod:`.judge`, :mod:`.report_flights`), :mod:`.where`, :mod:`.checks`
(vehicle check before fitting), :mod:`.commands` (command-only logs), :mod:`.report` and
:mod:`.schema` (output), :mod:`.synthetic` (generated test flights).

Example::

    >>> from quadsim.logs.flightlog import load_log
    >>> from quadsim.vehicle.params import load_params
    >>> from quadsim.gap import diagnose
    >>> result = diagnose([load_log(p) for p in paths], load_params("crazyflie21"))
    >>> result["verdict"]["effect"], result["verdict"]["reduction"]

CLI: ``python -m quadsim.gap --help``. Result schema: :mod:`quadsim.gap.schema`
(``quadsim.gap/3``), documented in docs/gap.md.
"""

from .diagnose import SCHEMA, diagnose, prepare
from .per_flight import diagnose_per_flight
from .report import summary, to_json, write_html, write_json, write_rerun
from .schema import GAP_SCHEMA, validate
from .synthetic import SensorNoise, synthetic_flight

__all__ = ["SCHEMA", "GAP_SCHEMA", "diagnose", "diagnose_per_flight", "prepare", "summary",
           "to_json", "write_html", "write_json", "write_rerun", "validate", "SensorNoise",
           "synthetic_flight"]
