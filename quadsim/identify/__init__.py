"""Identification of rotor factors, motor map and inertia from bench data, with an audit.

Replaces the 2015 report's hand calculations (sections 3.5, 4.2.3, 4.3) with fits that
carry 95 % intervals and residuals, and lists, with numbers, where the report went wrong.

Pieces (one module each):

* :mod:`.fits` -- least-squares rotor curves (``quadratic`` b Omega^2, ``quadratic+linear``,
  ``quadratic+offset``, ``power``), held-out scoring, thrust-stand b/d and d/b, the hover
  figure of merit FM = b^1.5 / (d sqrt(2 rho pi R^2)).
* :mod:`.inertia` -- bifilar inertia (corrected T^2 formula) with physical checks; the
  lumped model of eq. 3.18/3.19.
* :mod:`.testbed` -- :func:`identify_testbed`: everything above on the packaged tables.
* :mod:`.audit` -- :func:`audit_report`: the report's errors, each with its numbers.
* :mod:`.paramsets` -- renders ``models/physical.toml`` and ``models/computational.toml``.

Command line: ``python -m quadsim.identify`` (human tables; ``--json`` for scripts).

Example::

    >>> from quadsim.identify import identify_testbed
    >>> ident = identify_testbed()
    >>> ident.thrust_factor, ident.drag_factor, ident.figure_of_merit   # SI, SI, -

Units: SI inside (speeds rad/s, thrust N, torque N m); RPM and grams are converted by
:mod:`quadsim.identify.benchdata` when the tables are read.
"""

from .audit import Finding, audit_report
from .fits import (
                   MODELS,
                   Fit,
                   HeldOutScore,
                   Ratio,
                   StandFit,
                   figure_of_merit,
                   fit_curve,
                   fit_ratio,
                   fit_thrust_stand,
                   held_out_scores,
)
from .inertia import BifilarResult, analyse_bifilar, inertia_bound_problems, lumped_inertia
from .testbed import (
                   FM_PLAUSIBLE,
                   CurveEffect,
                   MotorMapFit,
                   TestbedIdentification,
                   identification_to_json,
                   identify_testbed,
)

__all__ = [
                   "FM_PLAUSIBLE",
                   "MODELS",
                   "BifilarResult",
                   "CurveEffect",
                   "Finding",
                   "Fit",
                   "HeldOutScore",
                   "MotorMapFit",
                   "Ratio",
                   "StandFit",
                   "TestbedIdentification",
                   "analyse_bifilar",
                   "audit_report",
                   "figure_of_merit",
                   "fit_curve",
                   "fit_ratio",
                   "fit_thrust_stand",
                   "held_out_scores",
                   "identification_to_json",
                   "identify_testbed",
                   "inertia_bound_problems",
                   "lumped_inertia",
]
