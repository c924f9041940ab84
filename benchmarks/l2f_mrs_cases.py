"""l2f benchmark cases of a fourth vehicle: l2f's "mrs" quadrotor, each case a single flight
judged per flight against 8 nominal flights of the same vehicle.

Source: :mod:`.l2f_source` with :data:`benchmarks.l2f_source.MRS` (l2f 2.0.18,
``parameters/dynamics/mrs.h``: a quadrotor of the MRS UAV system, CTU Prague): 1.7 kg on the
flightmare vehicle's rotors, arms and inertia (0.17 m diagonals, J = diag(0.00791, 0.00791,
0.0123) kg m^2, k_Q 0.016 m), 40 ms rotors, its rotor state in rad/s up to 2000: per rotor
-1.769 + 7.672 a + 5.319 a^2 N at a = Omega / 2000, hover at a = 0.558, where the slope is
0.91x the quadratic model's 2 T / Omega (flightmare's, at a = 0.246 on the same curve: 1.2x).
quadsim's nominal model has b from a thrust-stand least-squares fit of b Omega^2 over a =
0.1..1.0 (:func:`benchmarks.l2f_source.stand_b`), as for the fs and flightmare vehicles.
The same PID cascade (its nominal mass, inertia, geometry and thrust curve), path, sensors,
body drag form (C_dA 0.015, 0.015, 0.04 m^2) and the same case table as :mod:`.l2f_cases`
at this vehicle's scale: masses +5..+20 %, a payload 0.085-0.255 kg 20-50 mm off the centre
and 20-60 mm below, CoM 3-10 % of the 0.17 m arm, thrust curve terms +-5..15 % of the hover
thrust, rotors x 1.5-2.5, rate damping 1.5-3 x momentum theory, wind 2-5 m/s, rotor log
10-30 ms late; outside: 1-3 Hz torques, 2-5 Hz vertical forces. Seeds 84 000 + k (cases),
94 000 + 37 k (references), apart from the other vehicles'.

Kept unseen: built on 2026-11-28 with the verdict rules frozen at the commit that shares the
references' thrust-curve slope (:func:`quadsim.gap.calibrate.centred_curve`) and gives a
slower motor its own speed per command; its flights generated and checked for
observability only (``--generate-only``), then judged once; the first number is reported
as it came out (README, docs/gap.md). Observability, scoring and the machinery: as
:mod:`.l2f_cases` (:class:`benchmarks.l2f_cases.VehicleCases`).
"""

from __future__ import annotations

from .l2f_cases import MRS_CASES, OBSERVABLE

__all__ = ["OBSERVABLE", "SOURCE", "case_list", "reference_specs"]

case_list = MRS_CASES.case_list
reference_specs = MRS_CASES.reference_specs
SOURCE = MRS_CASES.source("l2f-mrs")
