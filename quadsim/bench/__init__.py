"""Independent benchmark of the gap diagnosis: flights this project's diagnosis did not make.

The self-generated blind benchmark (``scripts/gap_benchmark.py``) flies each hidden effect
through the same hooks the diagnosis fits, on inverse-dynamics logs with perfect sensor
timing. This subpackage provides sources that break that circle:

* :mod:`.rotorpy_source` -- RotorPy (``pip install 'quadsim[independent]'``): its own SE(3)
  controller, RK45 integrator, motor model, aerodynamics, IMU and motion-capture models;
  effects injected as RotorPy parameters (mass, rotor positions about the CoM, inertia, one
  rotor's k_eta and k_m, tau_m, drag coefficients, wind profiles, flapping, translational
  lift), the log converted to quadsim's :class:`~quadsim.logs.flightlog.FlightLog` (xyzw -> wxyz);
* :mod:`.pipeline` -- quadsim's closed loop through a realistic sensor pipeline
  (finite-difference accelerometer from mocap, filtered and delayed rotor speeds, mocap
  latency, noise, bias, quantisation);
* :mod:`.draws` -- realistic random magnitudes per vehicle; :mod:`.outside` -- effects
  outside the library; :mod:`.cases` -- the case list and the judging in held-out and
  per-flight mode; :mod:`.score` -- reading a verdict and scoring it.

Run: ``python scripts/gap_benchmark.py --independent --jobs 2 --out indep.json``; results
and their reading: docs/gap.md, "Independent benchmark".
"""
