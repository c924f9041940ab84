"""l2f benchmark cases of a sixth vehicle: l2f's "soft_rigid" quadrotor, each case a single
flight judged per flight against 8 nominal flights of the same vehicle.

Source: :mod:`.l2f_source` with :data:`benchmarks.l2f_source.SOFT` (l2f 2.0.18,
``parameters/dynamics/soft_rigid.h``): 0.804 kg on long arms (rotors on a 284 x 338 mm
rectangle; the case table's arm is its shorter half-span, 0.142 m), J = diag(6.584e-3,
4.957e-3, 1.057e-2) kg m^2, k_Q 0.0176 m, 46 ms rotors, and per rotor -0.334 + 6.091 a +
0.782 a^2 N: hover at a = 0.362, where the slope is 0.61x the quadratic model's 2 T / Omega
and c2 is 0.05 of the b that carries the hover. Its rotor state is normalised; this module
takes 2500 rad/s at a = 1. quadsim's nominal model has b from a thrust-stand least-squares
fit of b Omega^2 over a = 0.1..0.6, the band it flies (1.31x low at hover;
:func:`benchmarks.l2f_source.stand_b`). The same PID cascade, path, sensors, body drag
form (C_dA 0.01, 0.01, 0.025 m^2) and the same case table as :mod:`.l2f_cases` at this
vehicle's scale: masses +5..+20 %, a payload 0.04-0.12 kg 15-40 mm off the centre and 15-45
mm below, CoM 3-10 % of the arm, thrust curve terms +-5..15 % of the hover thrust, rotors x
1.5-2.5, rate damping 1.5-3 x momentum theory, wind 2-5 m/s, rotor log 10-30 ms late;
outside: 1-3 Hz torques, 2-5 Hz vertical forces. Seeds 86 000 + k (cases), 96 000 + 37 k
(references), apart from the other vehicles'.

Kept unseen: built on 2026-11-28 with the verdict rules frozen at the commit that lets the
shared curvature bend down (:func:`quadsim.gap.fitting.curve_quadratic_bounds`); its flights
generated and checked for observability only (``--generate-only``), then judged once; the
first number is reported as it came out (README, docs/gap.md). Observability, scoring and
the machinery: as :mod:`.l2f_cases` (:class:`benchmarks.l2f_cases.VehicleCases`).
"""

from __future__ import annotations

from .l2f_cases import OBSERVABLE, SOFT_CASES

__all__ = ["OBSERVABLE", "SOURCE", "case_list", "reference_specs"]

case_list = SOFT_CASES.case_list
reference_specs = SOFT_CASES.reference_specs
SOURCE = SOFT_CASES.source("l2f-soft")
