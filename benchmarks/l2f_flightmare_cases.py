"""l2f benchmark cases of a third vehicle: l2f's "flightmare" quadrotor, each case a single
flight judged per flight against 8 nominal flights of the same vehicle.

Source: :mod:`.l2f_source` with :data:`benchmarks.l2f_source.FLIGHTMARE` (l2f 2.0.18,
``parameters/dynamics/flightmare.h``: the quadrotor of UZH's Flightmare simulator): 0.73 kg,
rotors at 0.17 m on the diagonals, a thrust curve with a negative constant and a linear
term per rotor (-1.769 + 11.508 a + 11.968 a^2 N at normalised rotor state a: at hover, a =
0.246, the slope is 1.2x the quadratic model's 2 T / Omega, where the fs vehicle's was
0.66x), k_Q 0.016 m, 20 ms rotors, J = diag(0.00791, 0.00791, 0.0123) kg m^2. quadsim's
nominal model has b from a thrust-stand least-squares fit of b Omega^2 over a = 0.1..1.0
(:func:`benchmarks.l2f_source.stand_b`), as for the fs vehicle. The same PID cascade (its
nominal mass, inertia, geometry and thrust curve), path, sensors, body drag form (C_dA
0.01, 0.01, 0.025 m^2) and the same case table as :mod:`.l2f_cases` at this vehicle's
scale: masses +5..+20 %, a payload 0.04-0.11 kg 15-40 mm off the centre and 15-45 mm
below, CoM 3-10 % of the 0.17 m arm, thrust curve terms +-5..15 % of the hover thrust,
rotors x 1.5-2.5, rate damping 1.5-3 x momentum theory, wind 2-5 m/s, rotor log 10-30 ms
late; outside: 1-3 Hz torques, 2-5 Hz vertical forces. Seeds 82 000 + k (cases), 92 000 +
37 k (references), apart from the other vehicles'.

Kept unseen: built on 2026-11-28 with the verdict rules frozen at the commit that chose the
air drag's law per flight (:mod:`quadsim.gap.evidence`); its flights generated and checked
for observability only (``--generate-only``), then judged once; the first number is
reported as it came out (README, docs/gap.md). Observability, scoring and the machinery: as
:mod:`.l2f_cases` (:class:`benchmarks.l2f_cases.VehicleCases`).
"""

from __future__ import annotations

from .l2f_cases import FLIGHTMARE_CASES, OBSERVABLE

__all__ = ["OBSERVABLE", "SOURCE", "case_list", "reference_specs"]

case_list = FLIGHTMARE_CASES.case_list
reference_specs = FLIGHTMARE_CASES.reference_specs
SOURCE = FLIGHTMARE_CASES.source("l2f-flightmare")
