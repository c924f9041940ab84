"""l2f benchmark cases of a second vehicle: l2f's "fs" quadrotor, each case a single flight
judged per flight against 8 nominal flights of the same vehicle.

Source: :mod:`.l2f_source` with :data:`benchmarks.l2f_source.FS` (l2f 2.0.18,
``parameters/dynamics/fs.h``): 3.35 kg, rotors on a 0.418 m x 0.481 m rectangle (0.319 m
from the centre), a thrust curve with constant and linear terms per rotor (0.785 + 9.155 a +
18.006 a^2 N at normalised rotor state a: at hover, a = 0.437, the a^2 term carries 42 % of
the thrust), k_Q 0.01492 m, 65.3 ms rotors rising and falling, J = diag(0.0756, 0.0730,
0.1371) kg m^2. quadsim's nominal model of it has b from a thrust-stand least-squares fit of
b Omega^2 over a = 0.1..1.0 (30.1 a^2 N: 30 % low at hover) -- what ``python -m
quadsim.identify`` gives a user with a stand -- so its references share a large thrust-form
error, unlike the X500's purely quadratic rotors. The same PID cascade (its nominal mass,
inertia, geometry and thrust curve), path, sensors, body drag form (C_dA 0.03, 0.03, 0.075
m^2) and the same case table as :mod:`.l2f_cases` at this vehicle's scale: masses +5..+20 %
(0.17-0.67 kg), a payload 0.15-0.5 kg 30-80 mm off the centre and 30-80 mm below, CoM 3-10 %
of the 0.319 m arm, thrust curve terms +-5..15 % of the hover thrust, rotors x 1.5-2.5 (98-163
ms), rate damping 1.5-3 x momentum theory, wind 2-5 m/s, rotor log 10-30 ms late; outside:
1-3 Hz torques, 2-5 Hz vertical forces. Seeds 81 000 + k (cases), 91 000 + 37 k
(references), apart from the X500's.

Kept unseen: built on 2026-11-27 after the inverse-information trend (a70eb6c), its flights
generated and checked for observability only (``--generate-only``), then judged once with
the rules frozen at that commit; the first number is reported as it came out (README,
docs/gap.md). Observability, scoring and the machinery: as :mod:`.l2f_cases`
(:class:`benchmarks.l2f_cases.VehicleCases`), the shared physics with the thrust curve
against the stand fit's b (:meth:`~benchmarks.l2f_cases.VehicleCases.shared_effects`).
"""

from __future__ import annotations

from .l2f_cases import FS_CASES, OBSERVABLE

__all__ = ["OBSERVABLE", "SOURCE", "case_list", "reference_specs"]

case_list = FS_CASES.case_list
reference_specs = FS_CASES.reference_specs
SOURCE = FS_CASES.source("l2f-fs")
