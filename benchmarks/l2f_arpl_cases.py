"""l2f benchmark cases of a fifth vehicle: l2f's "arpl" quadrotor, each case a single flight
judged per flight against 8 nominal flights of the same vehicle.

Source: :mod:`.l2f_source` with :data:`benchmarks.l2f_source.ARPL` (l2f 2.0.18,
``parameters/dynamics/arpl.h``: a quadrotor of NYU's Agile Robotics and Perception Lab):
0.782 kg, rotors on a 155 x 196 mm rectangle (0.125 m from the centre; the case table's arm is its
shorter half-span, 0.0775 m: CoM offsets 2.3-7.8 mm), J =
diag(1.7665e-3, 1.3766e-3, 2.953e-3) kg m^2, k_Q 0.00596 m, 33 ms rotors, and a thrust curve
that bends down: per rotor -0.530 + 8.971 a - 0.891 a^2 N (c2 < 0), hover at a = 0.281,
where the slope is 0.61x the quadratic model's 2 T / Omega and the curvature is negative
(when it was built, the library's shared curvature stopped at 0; since d636543 it may
bend down: :func:`quadsim.gap.fitting.curve_quadratic_bounds`). Its
rotor state is normalised; this module takes 3000 rad/s at a = 1. quadsim's nominal model
has b from a thrust-stand least-squares fit of b Omega^2 over a = 0.1..0.5, the band it
flies (1.40x low at hover; :func:`benchmarks.l2f_source.stand_b`; over 0.1..1.0 the
vehicle check refused its references, b 2.7x low).
The same PID cascade (its nominal mass, inertia, geometry and thrust curve), path, sensors,
body drag form (C_dA 0.01, 0.01, 0.025 m^2) and the same case table as :mod:`.l2f_cases`
at this vehicle's scale: masses +5..+20 %, a payload 0.04-0.12 kg 15-40 mm off the centre
and 15-45 mm below, CoM 3-10 % of the arm, thrust curve terms +-5..15 % of the hover
thrust, rotors x 1.5-2.5, rate damping 1.5-3 x momentum theory, wind 2-5 m/s, rotor log
10-30 ms late; outside: 1-3 Hz torques, 2-5 Hz vertical forces. Seeds 85 000 + k (cases),
95 000 + 37 k (references), apart from the other vehicles'.

Kept unseen: built on 2026-11-28 with the verdict rules frozen at the commit that shares the
references' thrust-curve curvature (:data:`quadsim.gap.calibrate.POOLED`); its flights
generated and checked for observability only (``--generate-only``), then judged once; the
first number is reported as it came out (README, docs/gap.md). Observability, scoring and
the machinery: as :mod:`.l2f_cases` (:class:`benchmarks.l2f_cases.VehicleCases`).
"""

from __future__ import annotations

from .l2f_cases import ARPL_CASES, OBSERVABLE

__all__ = ["OBSERVABLE", "SOURCE", "case_list", "reference_specs"]

case_list = ARPL_CASES.case_list
reference_specs = ARPL_CASES.reference_specs
SOURCE = ARPL_CASES.source("l2f-arpl")
